"""sit2stand's compiled kernels (``ik_kernels.c``, plain C99): the per-frame IK's step terms and its QP.

Built on first use with the host's C compiler (``$CC``, else ``cc``) into the cache folder (:mod:`sit2stand.cache`),
named after a hash of the source, the flags, the compiler and the machine, and loaded with ctypes; ``make setup``
builds it once. Where no compiler works, or ``SIT2STAND_NATIVE=0``, :func:`kernels` is None and the callers keep
their NumPy path, which the tests hold the kernels to (``tests/test_native.py``).

The calls pass small ints and one prepared pointer block per set of arrays (an array of the arrays' addresses,
kept with them): a ctypes call converts each declared argument in Python, ~0.2 us apiece, which at the kernels'
size would cost as much as their work.

Why compiled: at the IK's size (38 unknowns, 31 markers, 15 equalities) a Gauss-Newton step is ~40 small NumPy and
Pinocchio calls, and their per-call cost, not the arithmetic, set its time; the QP's setup in DAQP refactorises the
whole problem from Python on every step.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import logging
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..cache import cache_folder

SOURCE = Path(__file__).with_name("ik_kernels.c")
FLAGS = ("-O3", "-std=c99", "-fopenmp-simd", "-shared", "-fPIC")
"""``-fopenmp-simd``: the dot products' ``omp simd`` reductions run in SIMD lanes (no OpenMP runtime). No
``-march=native``: the cache may be shared by hosts of different CPUs; the source has its entry points compiled
for x86-64-v3 beside the baseline instead, picked per CPU when loaded."""
DISABLE = "SIT2STAND_NATIVE"
"""Set to 0 to run the NumPy paths only."""

_log = logging.getLogger(__name__)
RESULT_TYPES = {"marker_terms": None, "sole_rows": ctypes.c_int, "box_qp": ctypes.c_int, "step_terms": ctypes.c_int}
"""The kernels and their return types; arguments go undeclared (ints, and ctypes pointers made once)."""


def compiler() -> str | None:
    """The C compiler's path, or None."""
    return shutil.which(os.environ.get("CC") or "cc")


def library_path(cc: str) -> Path:
    """Where the kernels built by ``cc`` from today's source are kept."""
    key = hashlib.sha1(SOURCE.read_bytes() + repr((FLAGS, cc, platform.machine())).encode()).hexdigest()[:16]
    return cache_folder("native") / f"ik_kernels-{key}.so"


def build(cc: str, out: Path) -> None:
    """Compile the kernels to ``out`` (a temporary file renamed into place: builds in parallel processes do not
    see each other's half-written library). CalledProcessError with the compiler's message if it fails."""
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(dir=out.parent, suffix=".so", delete=False) as f:
        tmp = Path(f.name)
    try:
        subprocess.run([cc, *FLAGS, "-o", str(tmp), str(SOURCE), "-lm"], check=True, capture_output=True,
                       text=True)
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)


@functools.lru_cache(maxsize=1)
def kernels() -> ctypes.CDLL | None:
    """The loaded kernels (built if need be), or None: disabled, no compiler, or a build that failed (logged)."""
    if os.environ.get(DISABLE, "1") == "0":
        return None
    cc = compiler()
    if cc is None:
        _log.info("no C compiler (%s): the IK runs its NumPy path", os.environ.get("CC") or "cc")
        return None
    out = library_path(cc)
    try:
        if not out.is_file():
            build(cc, out)
        try:
            lib = ctypes.CDLL(str(out))
        except OSError:              # a damaged file in the cache: built again
            build(cc, out)
            lib = ctypes.CDLL(str(out))
    except (OSError, subprocess.CalledProcessError) as e:
        _log.warning("building %s failed, the IK runs its NumPy path: %s", SOURCE.name,
                     getattr(e, "stderr", None) or e)
        return None
    for name, result in RESULT_TYPES.items():
        getattr(lib, name).restype = result
    return lib


class PointerBlock:
    """The addresses of some arrays, as one array the kernels index (``void *const *``), with the arrays held so
    that the addresses stay theirs. ``pointer`` is the argument to pass."""

    def __init__(self, *arrays) -> None:
        self.arrays = arrays
        self._addresses = np.array([a if isinstance(a, int) else a.ctypes.data for a in arrays], np.uint64)
        self.pointer = ctypes.c_void_p(self._addresses.ctypes.data)


SE3_DOUBLES = 12
"""A placement in Pinocchio's ``data.oMi``: its rotation (column-major), then its translation."""


def placements_address(data: pin.Data) -> int | None:
    """The address of ``data.oMi``'s storage, where the kernels read the joints' placements without a Python call
    per joint; None unless every placement lies where :data:`SE3_DOUBLES` says (then the NumPy path runs)."""
    oMi = data.oMi
    base = oMi[0].rotation.ctypes.data
    for j in range(len(oMi)):
        X = oMi[j]
        if X.rotation.ctypes.data != base + 8 * SE3_DOUBLES * j or X.translation.ctypes.data != \
                base + 8 * (SE3_DOUBLES * j + 9) or not X.rotation.flags.f_contiguous:
            return None
    return base


def _on_data(data: pin.Data) -> tuple[ctypes.CDLL, int] | None:
    """The kernels and the address of ``data``'s placements, or None (no kernels, or another layout)."""
    lib = kernels()
    oMi = None if lib is None else placements_address(data)
    return None if oMi is None else (lib, oMi)


class _Outputs:
    """Pointer blocks of the output arrays a kernel writes into, one per set of arrays (held with it)."""

    def __init__(self) -> None:
        self._blocks: dict[tuple[int, ...], PointerBlock] = {}

    def __call__(self, *arrays: np.ndarray) -> ctypes.c_void_p:
        key = tuple(map(id, arrays))
        block = self._blocks.get(key)
        if block is None:
            block = self._blocks[key] = PointerBlock(*arrays)
        return block.pointer


class MarkerTerms:
    """The markers' Hessian J' W J plus a diagonal, and their gradient J' W (p - t) (``marker_terms`` of the
    kernels), on one Pinocchio model and data after ``computeJointJacobians``. The data's Jacobian and placements
    stay where they are for the data's life, so their addresses are taken once. A frame's markers are loaded once
    (:meth:`load`); each Gauss-Newton step then writes the terms into arrays of the caller's (:meth:`__call__`)."""

    def __init__(self, lib: ctypes.CDLL, data: pin.Data, diagonal: np.ndarray, oMi: int) -> None:
        J = data.J
        self._lib, self.nv = lib, J.shape[1]
        self._data = data                         # keeps the Jacobian and the placements alive
        self._strides = (J.strides[0] // 8, J.strides[1] // 8)
        self._fixed = (J.ctypes.data, oMi, np.ascontiguousarray(diagonal, float))
        self._work = np.empty(3 * self.nv)
        self._outputs = _Outputs()
        self._layout = None
        self._grow(0)

    def _grow(self, m: int) -> None:
        self._capacity = m
        self._P, self._w, self._t = np.empty((m, 3)), np.empty(m), np.empty((m, 3))
        J, oMi, diagonal = self._fixed
        self._block = PointerBlock(J, oMi, self._w, self._t, diagonal, self._P, self._work)

    @classmethod
    def of(cls, data: pin.Data, diagonal: np.ndarray) -> MarkerTerms | None:
        """The kernel's terms, or None where there is no kernel or the placements are not laid out as it reads
        them."""
        found = _on_data(data)
        return None if found is None else cls(found[0], data, diagonal, found[1])

    def load(self, layout, weights: np.ndarray, targets: np.ndarray) -> None:
        """A frame's markers: the frames of ``layout`` (a :class:`~sit2stand.kinematics.PointSet`), their weights
        (M,) [1/m^2] and targets (M, 3) [m]."""
        m = layout.size
        if m > self._capacity:
            self._grow(m)
        self._w[:m] = weights
        self._t[:m] = targets
        self._layout = layout

    def __call__(self, H: np.ndarray, g: np.ndarray) -> None:
        """H (nv, nv) and g (nv,), C-contiguous, overwritten with the loaded markers' terms at the data's
        Jacobians."""
        layout = self._layout
        self._lib.marker_terms(self.nv, layout.size, *self._strides, self._block.pointer,
                               layout.kernel_block.pointer, self._outputs(H, g))

    @property
    def positions(self) -> np.ndarray:
        """The loaded markers' world positions (M, 3) [m] from the last call (a view, overwritten by the next)."""
        return self._P[:self._layout.size]


class SoleRows:
    """The feet's equality rows (``sole_rows`` of the kernels): per sole frame, its LOCAL frame Jacobian (6, nv)
    and -log6(target^-1 X), on one Pinocchio model and data after ``computeJointJacobians`` (as
    ``pin.getFrameJacobian(model, data, f, pin.LOCAL)`` and ``pin.log6``). Targets are loaded once a frame
    (:meth:`load`)."""

    def __init__(self, lib: ctypes.CDLL, model: pin.Model, data: pin.Data, frames: list[int], soles, oMi: int
                 ) -> None:
        J = data.J
        self._lib, self.nv, self.count = lib, model.nv, soles.size
        self._data, self._soles = data, soles                   # keep what the pointer block points into
        self._strides = (J.strides[0] // 8, J.strides[1] // 8)
        self._target = np.empty((soles.size, 4, 4))
        self._block = PointerBlock(J.ctypes.data, oMi, soles.joint_id,
                                   np.array([model.frames[f].placement.homogeneous for f in frames]), self._target,
                                   soles.joint_row, soles.dofs, soles.dof_start, soles.dof_count)
        self._outputs = _Outputs()

    @classmethod
    def of(cls, model: pin.Model, data: pin.Data, frames: list[int], soles) -> SoleRows | None:
        """The kernel's rows for the sole ``frames``, laid out as their point set ``soles``
        (:meth:`~sit2stand.kinematics.PointJacobians.point_set`), or None (see :meth:`MarkerTerms.of`)."""
        found = _on_data(data)
        return None if found is None else cls(found[0], model, data, frames, soles, found[1])

    def load(self, targets: list[pin.SE3]) -> None:
        """The soles' target placements, one per frame."""
        self._target[:] = [X.homogeneous for X in targets]

    def __call__(self, A: np.ndarray, b: np.ndarray) -> bool:
        """The rows written into the first 6 * soles rows of A (rows, nv) and entries of b, both C-contiguous;
        False if a rotation error is near pi (ask Pinocchio)."""
        return bool(self._lib.sole_rows(self.nv, self.count, *self._strides, self._block.pointer,
                                        self._outputs(A, b)))


def _held_in_place(a: np.ndarray, b: np.ndarray, shape: tuple[int, ...]) -> bool:
    """Whether two reads of one data member (``a``, ``b``, both alive) are the same storage of ``shape``: a view
    the kernel may keep the address of, not a copy made per read."""
    return a.shape == shape and a.ctypes.data == b.ctypes.data


class StepTerms:
    """A Gauss-Newton step's QP terms in one kernel call (``step_terms``): the markers' terms
    (:class:`MarkerTerms`), the feet's rows (:class:`SoleRows`), the posture prior's gradient, the COM's rows and
    the joints' step box, written into a :class:`~sit2stand.optim.QpProblem`, after ``computeJointJacobians`` and
    ``jacobianCenterOfMass`` on the data (whose ``Jcom`` and ``com[0]`` it reads where they lie). A frame's targets
    are loaded once (:meth:`load`)."""

    def __init__(self, markers: MarkerTerms, soles: SoleRows, model: pin.Model, data: pin.Data,
                 posture_weight: np.ndarray, free: float) -> None:
        self.markers, self.soles = markers, soles
        self._free = ctypes.c_double(free)
        Jcom = data.Jcom
        self._jc_strides = (Jcom.strides[0] // 8, Jcom.strides[1] // 8)
        self._q, self._q_ref, self._c_target = np.empty(model.nq), np.empty(model.nq), np.empty(3)
        self._axes, self._n_axes = np.zeros(3, np.int32), 0
        self._q_lo, self._q_hi = np.empty(model.nv - 6), np.empty(model.nv - 6)
        self._block = PointerBlock(self._q, self._q_ref, np.ascontiguousarray(posture_weight, float),
                                   Jcom.ctypes.data, data.com[0].ctypes.data, self._c_target, self._axes,
                                   self._q_lo, self._q_hi)
        self._outputs = _Outputs()

    @classmethod
    def of(cls, model: pin.Model, data: pin.Data, diagonal: np.ndarray, posture_weight: np.ndarray,
           frames: list[int], soles, free: float) -> StepTerms | None:
        """The kernel's terms (``diagonal``, ``frames`` and ``soles`` as :class:`MarkerTerms` and
        :class:`SoleRows` take them; ``posture_weight`` (nv) 0 on the base; ``free``: the base's step bounds, the
        QP's infinity), or None: no kernel, placements laid out otherwise, a COM and its Jacobian not where the
        data keeps them, or a joint past the base with other than one coordinate."""
        markers, sole_rows = MarkerTerms.of(data, diagonal), SoleRows.of(model, data, frames, soles)
        if markers is None or sole_rows is None or not _held_in_place(data.Jcom, data.Jcom, (3, model.nv)) or \
                not _held_in_place(data.com[0], data.com[0], (3,)) or \
                any(j.nq != 1 or j.nv != 1 for j in model.joints[2:]):
            return None
        return cls(markers, sole_rows, model, data, posture_weight, free)

    def load(self, layout, weights: np.ndarray, targets: np.ndarray, sole_targets: list[pin.SE3],
             q_ref: np.ndarray, com_target: np.ndarray, axes: np.ndarray, q_lo: np.ndarray,
             q_hi: np.ndarray) -> None:
        """A frame's targets: markers (as :meth:`MarkerTerms.load`), the soles' placements, the posture reference
        (nq), the COM target [m] on ``axes``, and the joints' box over its steps [rad] (nq - 7)."""
        self.markers.load(layout, weights, targets)
        self.soles.load(sole_targets)
        self._q_ref[:] = q_ref
        self._c_target[:] = com_target
        self._n_axes = len(axes)
        self._axes[:self._n_axes] = axes
        self._q_lo[:] = q_lo
        self._q_hi[:] = q_hi

    def __call__(self, q: np.ndarray, p, com_row: int) -> bool:
        """``p``'s H, g, A, b, lo and hi at ``q`` (its COM rows from ``com_row``); False if a foot's rotation
        error is near pi (its rows are then the caller's to write, with Pinocchio)."""
        self._q[:] = q
        m, s = self.markers, self.soles
        return bool(m._lib.step_terms(m.nv, m._layout.size, s.count, self._n_axes, com_row, *m._strides,
                                      *self._jc_strides, self._free, m._block.pointer, m._layout.kernel_block.pointer,
                                      s._block.pointer, self._block.pointer,
                                      self._outputs(p.H, p.g, p.A, p.b, p.lo, p.hi)))


class ActiveSetQp:
    """``box_qp`` of the kernels: min 1/2 x'Hx + g'x s.t. A x = b, C x >= d, lo <= x <= hi by a primal-dual active
    set, on a :class:`~sit2stand.optim.QpProblem` (its arrays read where they are), started from the working set
    of the problem's last solve. Its answer is exact where it returns one; None sends the caller to a general
    solver (then :meth:`remember` seeds the next start from that solver's answer)."""

    MAX_ITERATIONS = 12
    TOLERANCE = ctypes.c_double(1e-9)
    """Primal feasibility [units of x] and the multipliers' sign."""

    def __init__(self, lib: ctypes.CDLL) -> None:
        self._lib = lib

    def solve_problem(self, p) -> tuple[np.ndarray, np.ndarray] | None:
        """(x, multipliers in DAQP's convention: H x + g + lam[:n] + [A; C]' lam[n:] = 0), or None. x is a copy;
        the multipliers are the problem's own array, rewritten by its next solve."""
        state = _KernelState.of(p)
        if not self._lib.box_qp(*p.shape, self.MAX_ITERATIONS, self.TOLERANCE, state.block.pointer):
            return None
        return state.x.copy(), state.lam

    def remember(self, p, lam: np.ndarray) -> None:
        """Start the problem's next solve from another solver's answer: the bounds and rows with a nonzero
        multiplier held (DAQP's sign: negative at a lower bound; a NaN holds nothing). The kernel drops what is
        held at an infinite bound when it starts."""
        n, me, _ = p.shape
        state = _KernelState.of(p)
        lam = np.nan_to_num(lam, nan=0.0)
        state.bound[:] = np.sign(lam[:n])
        state.row[:] = lam[n + me:] != 0.0


class _KernelState:
    """One problem's outputs, working set and scratch for ``box_qp``, with the problem's arrays in one pointer
    block."""

    def __init__(self, p) -> None:
        n, me, mi = p.shape
        m = me + mi
        self.x, self.lam = np.zeros(n), np.zeros(n + m)
        self.bound, self.row = np.zeros(n, np.int32), np.zeros(mi, np.int32)
        self.block = PointerBlock(p.H, p.g, p.A, p.b, p.C, p.d, p.lo, p.hi, self.x, self.lam, self.bound, self.row,
                                  np.empty((m, n)), np.empty(5 * n + n * n + m * (n + m + 4) + 16))

    @classmethod
    def of(cls, p) -> _KernelState:
        """The problem's state, made on first use."""
        if p.kernel is None:
            p.kernel = cls(p)
        return p.kernel
