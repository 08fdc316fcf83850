"""Per-frame inverse kinematics with the COM as a hard constraint and markers as soft tasks (Mistry et al. 2010).

Each frame solves, by damped Gauss-Newton steps on the configuration q (Pinocchio, floating base),

    minimise    sum_k w_k || p_k(q) - t_k ||^2  +  mu || q (-) q_ref ||^2        (markers soft, posture prior)
                + w_L || (L(q) - L_prev) / (m g) ||^2                             (angular momentum rate)
    subject to  c(q)[axes] = c_target[axes]                                      (COM: hard equality)
                X_sole(q) = X_sole_target   for both feet                       (feet fixed: hard, 6-D each)
                q_min <= q <= q_max,  |q_dot| dt <= v_max dt                      (joint and velocity limits)
                q_j stays on its stop while gravity presses it there past its motor   (stops that hold)
                q_j accelerates against gravity within its motor's room               (trunk lift-off)
                z_base(q) >= z_min                                                    (hips clear of the seat)

with one dense QP (:class:`~sit2stand.optim.WarmQp`: an active set started from the last step's working set) per
step in the tangent step dq:
``min 1/2 dq' H dq + g' dq  s.t.  A dq = b,  C dq >= d,  l <= dq <= u`` built from the frame, COM and sole
Jacobians, in place in the QP's arrays. The markers' terms, the soles' rows and the QP run in compiled kernels
(:mod:`sit2stand.native`) where the host has a C compiler, else in NumPy and DAQP, to the same answers.
Iterations are warm-started from the previous frame's solution. If the COM target cannot be met with the feet
fixed and within limits, the COM is made a heavily weighted soft task instead, and the frame is flagged infeasible;
the returned q always respects the joint limits and is finite.

The angular momentum term: the centroidal angular momentum L = A_g(q) q_dot [kg m^2/s] of the frame's motion (from
the previous frame) stays near the previous frame's. Its change dL/dt moves the ZMP by dL/dt / (m g) from where the
COM alone puts it; frame-by-frame IK otherwise lets the trunk and arms trade angle against each other from one frame
to the next, and measured on the shipped natural rise that swung dL_y/dt by +-180 N m around seat-off (the ZMP 12-15
cm off). ``momentum_weight`` weighs it as a ZMP shift [m] against the markers' metres.

Stops that hold: a joint no foot hangs from (the torso's, the head's, the arms') carries only its own subtree, so
the torque it needs to hold still is the gravity torque g_j(q). Where g_j presses the joint onto its stop harder than
``stop_torque_share`` of its effort limit, its motor cannot lift it off: the step may not move it off. Without it the
plan lifted TALOS's leaned trunk off its 45 degree stop (~120 N m needed against 78) and, under joint PD, the trunk
lagged and 2 of 30 population rises tipped forward (docs/method.md).

Trunk lift-off: a trunk joint (the torso pitch) may accelerate against gravity only as fast as its motor's room
above gravity allows, (``lift_torque_share`` x effort limit - |g_j|) / M_jj (M_jj the joint-space inertia's
diagonal), from its speed into the previous frame. Without it the plan lifted the trunk off its stop at up to the
speed limit where the motor has next to nothing above gravity. Only the pitch: bounding the arms too doubled the
population's COM tracking p90, bounding the torso yaw lost a fast rise.

Units SI; frames by Pinocchio frame id; positions in the world frame (REP-103).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import pinocchio as pin

from .. import native
from ..kinematics import PointJacobians, PointSet
from ..optim import WarmQp
from ..robot.profile import profile_of


STOP_TOLERANCE_RAD = 1e-3
"""A joint this close to a limit is on its stop (the steps clip exactly to the limits)."""
FREE = 1e20
"""A bound that does not bind (the QP solvers' infinity)."""
LIFT_TORQUE_SHARE = 1.0
"""The share of its effort limit a trunk joint's plan may spend lifting the trunk against gravity: see
``lift_torque_share``. The whole limit: at 0.9 the plan held the leaned trunk back so long that a real child's fast
rise (CAD parameters) fell backwards, or, with the player's lift-off rule, tracked 5 cm; the player stretches the time
where the motor needs more (``player.LIFT_OFF_SPEED_RAD_S``)."""


def free_subtree_dofs(model: pin.Model, frames: list[int]) -> np.ndarray:
    """Tangent indices of the 1-DoF joints that none of ``frames`` hangs from (with the soles: torso, head, arms):
    each holds only its own subtree, so its static torque is the gravity torque g_j(q), whatever the contacts at the
    frames bear."""
    support = {j for fid in frames for j in model.supports[model.frames[fid].parentJoint]}   # the frames' ancestors
    return np.array([model.joints[j].idx_v for j in range(2, model.njoints)
                     if j not in support and model.joints[j].nv == 1], int)


def trunk_lift_dofs(model: pin.Model, dofs: np.ndarray) -> np.ndarray:
    """Of the 1-DoF joints' tangent indices ``dofs``, those that lift the trunk against gravity: not of an arm, a
    gripper or the head, their axis horizontal in the neutral pose (TALOS: the torso pitch, not its yaw)."""
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    name = {model.joints[j].idx_v: model.names[j] for j in range(2, model.njoints)}
    return np.array([d for d in dofs if not profile_of(model).is_upper_limb(name[d])
                     and abs(data.J[5, d]) < 0.5], int)


@dataclass
class IkResult:
    """One frame's solution and how good it is. The sole and marker errors are computed when first read (a forward
    kinematics pass and the markers' positions, 10 % of a frame's solve, that a live frame does not need)."""

    q: np.ndarray
    feasible: bool             # the COM equality (and the feet) could be met
    com_error_m: float         # |c(q) - c_target| on the constrained axes
    iterations: int
    step_norm: float           # size of the last Gauss-Newton step (small at a local optimum)
    seconds: float
    errors: Callable[[], tuple[float, float]] = field(repr=False)   # -> (sole_error, marker_rms_m) at q

    @cached_property
    def _sole_and_marker_errors(self) -> tuple[float, float]:
        return self.errors()

    @property
    def sole_error(self) -> float:
        """The largest sole pose error (norm of the 6-D log)."""
        return self._sole_and_marker_errors[0]

    @property
    def marker_rms_m(self) -> float:
        """The RMS marker distance [m]."""
        return self._sole_and_marker_errors[1]


@dataclass(frozen=True)
class MarkerTargets:
    """One frame's marker tasks: the robot frames' ids (M,), their targets (M, 3) [m, world] and weights (M,)
    [1/m^2]. Iterates as (frame id, target, weight) triples."""

    frame_ids: np.ndarray
    targets_m: np.ndarray
    weights: np.ndarray

    @classmethod
    def of(cls, markers) -> MarkerTargets:
        """``markers`` as a record: itself, or from (frame id, target [m], weight) triples."""
        if isinstance(markers, MarkerTargets):
            return markers
        fids, targets, weights = zip(*markers) if len(markers) else ((), (), ())
        return cls(np.array(fids, int), np.array(targets, float).reshape(-1, 3), np.array(weights, float))

    def __len__(self) -> int:
        return len(self.frame_ids)

    def __iter__(self):
        return zip(self.frame_ids.tolist(), self.targets_m, self.weights.tolist())


@dataclass(frozen=True)
class JointBox:
    """The joints' limits [rad] (nq - 7), their speed limits [rad/s] (nv - 6) and the most they travel in a frame
    [rad]. A step's bounds on the base's six are free (:data:`FREE`)."""

    q_lo: np.ndarray
    q_hi: np.ndarray
    v_max: np.ndarray
    travel: np.ndarray

    @classmethod
    def of(cls, model: pin.Model, velocity_limit: float | np.ndarray, dt: float) -> JointBox:
        v_max = np.broadcast_to(np.asarray(velocity_limit, float), (model.nv - 6,)).copy()
        return cls(model.lowerPositionLimit[7:].copy(), model.upperPositionLimit[7:].copy(), v_max, v_max * dt)

    def of_frame(self, q_prev: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The joints' box over a frame's steps: their limits and, from the previous frame, their speed limits."""
        if q_prev is None:
            return self.q_lo, self.q_hi
        return np.maximum(self.q_lo, q_prev[7:] - self.travel), np.minimum(self.q_hi, q_prev[7:] + self.travel)


@dataclass
class _Frame:
    """One frame's targets: markers (frame ids, positions [m], weights), the COM [m] on ``axes``, the soles, the
    posture reference, the previous frame and the base holds (x, z [m]; pitch [rad])."""

    fids: np.ndarray
    targets: np.ndarray
    weights: np.ndarray
    com_target: np.ndarray
    axes: np.ndarray
    sole_targets: list[pin.SE3]
    q_ref: np.ndarray
    q_prev: np.ndarray | None
    base_xz: np.ndarray | None
    base_weight: float | None
    base_pitch_min: float | None
    base_z_min: float | None = None              # the held point's lowest world z [m] (hips off the seat)
    lift_speed_prev: np.ndarray | None = None    # the trunk joints' speeds into the previous frame [rad/s]
    joint_targets: list[tuple[int, float, float]] = field(default_factory=list)   # (tangent index, rad, 1/rad^2)
    q_lo: np.ndarray | None = None    # the joints' box over this frame's steps: their limits, and the speed limits
    q_hi: np.ndarray | None = None    # from the previous frame [rad] (nq - 7)
    points: PointSet | None = None    # the markers' frames, laid out for :class:`PointJacobians`

    def __post_init__(self) -> None:
        self.axes = np.asarray(self.axes, int)


class ComIk:
    """QP inverse kinematics with a hard COM constraint (see the module docstring).

    Args:
        model: Pinocchio model (free-flyer root) with the COM parameters to use (identified, or CAD).
        sole_frames: frame ids of the two soles, kept at their target placements.
        velocity_limit: joint speed limit [rad/s] (scalar or per joint, nv - 6).
        dt: frame period [s] (velocity limits become step bounds).
        posture_weight: mu, the pull toward ``q_ref`` (regularisation of what the markers do not fix); scalar or
            per tangent direction (nv; the base's six are ignored).
        damping: Levenberg-Marquardt damping on the step.
        momentum_weight: weight of the angular momentum term (see the module docstring).
        stop_torque_share: a joint no sole hangs from stays on its stop while gravity presses it there with more
            than this share of its effort limit (None: not applied; see the module docstring).
        hold_point_b: the point of the base that ``base_xz`` holds, in the base frame [m] (default its origin).
    """

    def __init__(self, model: pin.Model, sole_frames: list[int], velocity_limit: float | np.ndarray = 5.0,
                 dt: float = 0.01, posture_weight: float | np.ndarray = 1e-3, damping: float = 1e-6,
                 momentum_weight: float = 0.0, stop_torque_share: float | None = None,
                 lift_torque_share: float | None = None, hold_point_b: np.ndarray | None = None) -> None:
        self.model = model
        self.data = model.createData()
        self.soles = list(sole_frames)
        self.nv = model.nv
        self.dt = dt
        self.mu = np.broadcast_to(np.asarray(posture_weight, float), (model.nv,)).copy()
        self.mu[:6] = 0.0
        self.damping = damping
        self._diagonal = self.mu + damping
        self.box = JointBox.of(model, velocity_limit, dt)
        self._qp = WarmQp()
        self.hold_point_b = np.zeros(3) if hold_point_b is None else np.asarray(hold_point_b, float)
        self.points = PointJacobians(model)
        self._native = native.StepTerms.of(model, self.data, self._diagonal, self.mu, self.soles,
                                           self.points.point_set(self.soles), FREE)     # None: the NumPy paths
        self.momentum_weight = momentum_weight
        self._weight_g = float(pin.computeTotalMass(model)) * 9.81
        self._L_prev: np.ndarray | None = None      # the previous frame's angular momentum [kg m^2/s]
        self.stop_dofs = free_subtree_dofs(model, self.soles) if stop_torque_share is not None else np.zeros(0, int)
        self.stop_torque_nm = (stop_torque_share or 0.0) * model.effortLimit[self.stop_dofs]
        self.lift_dofs = trunk_lift_dofs(model, self.stop_dofs)
        self.lift_torque_nm = None if lift_torque_share is None else \
            lift_torque_share * model.effortLimit[self.lift_dofs]
        self._last_solve: tuple[np.ndarray, np.ndarray] | None = None    # (q_prev, solution) of the last frame
        self._lift_inertia: np.ndarray | None = None

    def solve(self, q0: np.ndarray, markers: MarkerTargets | list[tuple[int, np.ndarray, float]],
              com_target: np.ndarray, sole_targets: list[pin.SE3], q_ref: np.ndarray | None = None,
              com_axes: tuple[int, ...] = (0, 1, 2), q_prev: np.ndarray | None = None, max_iterations: int = 10,
              tol: float = 1e-7,
              base_xz: np.ndarray | None = None, base_weight: float | None = None,
              base_pitch_min: float | None = None, base_z_min: float | None = None,
              joint_targets: list[tuple[int, float, float]] | None = None) -> IkResult:
        """Solve one frame from ``q0``. ``markers``: a :class:`MarkerTargets`, or (frame id, target position [m],
        weight) triples.
        ``q_prev``: the previous frame's configuration; the joint speed limits bound the motion from it (none for
        the first frame). ``base_xz``: hold the base's ``hold_point_b`` at this world x and z [m] (the hips on a
        seat): two more equality rows, or, with ``base_weight``, a soft task of that weight. ``base_pitch_min``
        [rad]: the base may not pitch back beyond this (a pelvis on a seat cannot roll back about its hips).
        ``base_z_min`` [m]: the world z of ``hold_point_b`` stays at or above this (hips that left a seat stay off it).
        ``joint_targets``: (tangent index, angle [rad], weight [1/rad^2]) soft tasks on single joints (the human's
        knee flexion)."""
        t0 = time.perf_counter()
        markers = MarkerTargets.of(markers)
        frame = _Frame(markers.frame_ids, markers.targets_m, markers.weights, com_target, com_axes, sole_targets,
                       q0 if q_ref is None else q_ref, q_prev, base_xz, base_weight, base_pitch_min, base_z_min,
                       joint_targets=list(joint_targets or ()))
        frame.points = self.points.point_set(frame.fids)
        frame.lift_speed_prev = self._lift_speed_prev(q_prev)
        frame.q_lo, frame.q_hi = self.box.of_frame(q_prev)
        if self._native is not None:          # the frame's targets, once for all its steps
            self._native.load(frame.points, frame.weights, frame.targets, sole_targets, frame.q_ref, com_target,
                              frame.axes, frame.q_lo, frame.q_hi)
        self._lift_inertia = None        # the trunk's inertia about its joints, once per frame (see _bound_lift)
        q = q0.copy()
        feasible = True
        step = np.inf
        it = 0
        while it < max_iterations:
            it += 1
            dq, com_held = self._step(q, frame)
            feasible = feasible and com_held
            q = self._integrate(q, dq, frame)
            step = _norm(dq)
            if step < tol:
                break
        if self.lift_torque_nm is not None:       # the trunk's speed into the next frame (see _lift_speed_prev)
            self._last_solve = None if q_prev is None else (q_prev.copy(), q.copy())
        if self.momentum_weight > 0:
            self._L_prev = None if q_prev is None else \
                pin.computeCentroidalMap(self.model, self.data, q)[3:] @ pin.difference(self.model, q_prev, q) / self.dt
        return self._result(q, frame, feasible, it, step, t0)

    def _step(self, q: np.ndarray, f: _Frame) -> tuple[np.ndarray, bool]:
        """One Gauss-Newton step dq (tangent) from q (zero if no QP could be solved); whether the COM equality
        was kept. The QP is filled in place (:meth:`~sit2stand.optim.WarmQp.problem`)."""
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, q)          # with the joints' placements (the markers need no more)
        Jc = pin.jacobianCenterOfMass(model, data, False)
        n_feet = 6 * len(self.soles) + 2 * (f.base_xz is not None and f.base_weight is None)
        qp = self._qp.problem(self.nv, n_feet + len(f.axes), 0 if f.base_z_min is None else 1)
        if self._native is not None:
            if not self._native(q, qp, n_feet):
                self._sole_rows(f, qp.A, qp.b)
            self._soft_rules(q, f, qp.H, qp.g)
            self._base_rows(q, f, qp, n_feet)
            self._bound_rules(q, f, qp.lo, qp.hi)
            if len(self.stop_dofs):    # the kernel clamped the box, the stop and lift rules may move it
                _clamp_to_zero(qp.lo, qp.hi)
        else:
            e_com = (f.com_target - data.com[0]).take(f.axes)          # before the momentum term's pass
            self._soft_tasks(q, f, qp.H, qp.g)
            self._hard_rows(q, f, qp, Jc.take(f.axes, 0), e_com)
            self._bounds(q, f, qp.lo, qp.hi)
        self._base_height_row(q, f, qp)
        dq = self._qp.solve_problem(qp)
        if dq is not None:
            return dq, True
        # COM infeasible with the feet fixed and the limits: COM as a heavily weighted soft task
        H, g, A_feet, b_feet, lo, hi = qp.H, qp.g, qp.A[:n_feet], qp.b[:n_feet], qp.lo, qp.hi
        Jc, e_com = qp.A[n_feet:], qp.b[n_feet:]
        C, d = (qp.C, qp.d) if len(qp.d) else (None, None)
        Hs = H + 1e4 * Jc.T @ Jc
        gs = g - 1e4 * Jc.T @ e_com
        dq = self._qp.solve(Hs, gs, A_feet, b_feet, lo, hi, C, d)
        if dq is None:     # not even the feet: everything soft; the box and the floor are always feasible (0 is
            #                inside the joints' box, and the floor's row has the unbounded base translation)
            Hs += 1e6 * A_feet.T @ A_feet
            gs -= 1e6 * A_feet.T @ b_feet
            dq = self._qp.solve(Hs, gs, np.zeros((0, self.nv)), np.zeros(0), lo, hi, C, d)
        return (np.zeros(self.nv) if dq is None else dq), False

    def _soft_tasks(self, q: np.ndarray, f: _Frame, H: np.ndarray, g: np.ndarray) -> None:
        """Hessian H and gradient g (filled in place) of the markers, sum w ||J dq + e||^2 [m^2], the posture
        prior and the frame's other soft terms, at q."""
        self._marker_terms(f, H, g)
        g += self.mu * pin.difference(self.model, f.q_ref, q)      # mu is 0 on the base
        self._soft_rules(q, f, H, g)

    def _soft_rules(self, q: np.ndarray, f: _Frame, H: np.ndarray, g: np.ndarray) -> None:
        """The joint targets' and the angular momentum's terms, added to H and g."""
        for i, angle, w in f.joint_targets:          # q's index of a 1-DoF joint is its tangent index + 1
            H[i, i] += w
            g[i] += w * (q[i + 1] - angle)
        if self.momentum_weight > 0 and f.q_prev is not None and self._L_prev is not None:
            # L(dq) = A (v0 + dq / dt), v0 the motion from the previous frame to q; its change as a ZMP shift [m]
            A = pin.computeCentroidalMap(self.model, self.data, q)[3:] / self.dt
            v0 = pin.difference(self.model, f.q_prev, q)
            e = (A @ v0 - self._L_prev) / (self.dt * self._weight_g)
            As = A / (self.dt * self._weight_g)
            H += self.momentum_weight * As.T @ As
            g += self.momentum_weight * As.T @ e

    def _marker_terms(self, f: _Frame, H: np.ndarray, g: np.ndarray) -> None:
        """H = the markers' J' W J plus the damping and posture diagonal and g = their J' W (p - t), in place, at
        the data's joint Jacobians."""
        nv, layout, root_weights = self.nv, f.points, np.repeat(np.sqrt(f.weights), 3)
        P, Jw = self.points(self.data, layout, root_weights)
        Jw = Jw.reshape(-1, nv)
        np.matmul(Jw.T, Jw, out=H)
        H.flat[::nv + 1] += self._diagonal
        np.matmul(Jw.T, root_weights * (P - f.targets).ravel(), out=g)

    def _hard_rows(self, q: np.ndarray, f: _Frame, qp, Jc: np.ndarray, e_com: np.ndarray) -> None:
        """The equality rows A dq = b of ``qp``, in place: the feet (J_sole dq = -log(X_target^-1 X)), a held base
        x, z, then the COM's (``Jc``, ``e_com``); a soft base hold (``base_weight``) goes into its H and g
        instead."""
        n = len(qp.b) - len(e_com)
        self._sole_rows(f, qp.A, qp.b)
        self._base_rows(q, f, qp, n)
        qp.A[n:], qp.b[n:] = Jc, e_com

    def _sole_rows(self, f: _Frame, A: np.ndarray, b: np.ndarray) -> None:
        """The feet's rows J_sole dq = -log(X_target^-1 X), in place in the first rows of A and b."""
        for k, (fid, target) in enumerate(zip(self.soles, f.sole_targets)):
            b[6 * k:6 * k + 6] = -pin.log6(target.actInv(pin.updateFramePlacement(self.model, self.data, fid))).vector
            A[6 * k:6 * k + 6] = pin.getFrameJacobian(self.model, self.data, fid, pin.LOCAL)

    def _base_rows(self, q: np.ndarray, f: _Frame, qp, n: int) -> None:
        """A held base point's x, z (``hold_point_b``): rows n - 2 and n - 1 of ``qp``'s equalities after the
        feet's, or, with ``base_weight``, a soft task in its H and g (the point's world velocity: R (v - p x w))."""
        if f.base_xz is None:
            return
        n_soles, R, rb = 6 * len(self.soles), self.data.oMi[1].rotation, np.zeros((2, self.nv))
        rb[:, :3], rb[:, 3:6] = R[[0, 2]], -(R @ pin.skew(self.hold_point_b))[[0, 2]]
        eb = (np.asarray(f.base_xz, float) - q[:3] - R @ self.hold_point_b)[[0, 2]]
        if n > n_soles:
            qp.A[n_soles:n], qp.b[n_soles:n] = rb, eb
        else:
            qp.H += f.base_weight * rb.T @ rb
            qp.g -= f.base_weight * rb.T @ eb

    def _base_height_row(self, q: np.ndarray, f: _Frame, qp) -> None:
        """The inequality C dq >= d of ``qp`` (in place) keeping the world z of ``hold_point_b`` (not the base's origin,
        which a pelvis pitched about its hips lowers) above ``base_z_min``; its world velocity is R (v - p x w)."""
        if f.base_z_min is not None:
            R = self.data.oMi[1].rotation
            qp.C[0, :3], qp.C[0, 3:6] = R[2], -(R @ pin.skew(self.hold_point_b))[2]
            qp.d[0] = f.base_z_min - (q[2] + R[2] @ self.hold_point_b)

    def _bounds(self, q: np.ndarray, f: _Frame, lo: np.ndarray, hi: np.ndarray) -> None:
        """Step bounds (in place) from the joint limits, the speed limits from the previous frame and the frame's
        rules (:meth:`_bound_rules`); the base free."""
        lo[:6], hi[:6] = -FREE, FREE
        np.subtract(f.q_lo, q[7:], out=lo[6:])
        np.subtract(f.q_hi, q[7:], out=hi[6:])
        self._bound_rules(q, f, lo, hi)
        _clamp_to_zero(lo, hi)

    def _bound_rules(self, q: np.ndarray, f: _Frame, lo: np.ndarray, hi: np.ndarray) -> None:
        """The base pitch's bound [rad] and the joints' stop and lift rules, on step bounds (in place); the caller
        clamps the joints' part to zero after (:func:`_clamp_to_zero`; clamped before too, the same answer)."""
        if f.base_pitch_min is not None:
            R = self.data.oMi[1].rotation
            lo[4] = min(0.0, f.base_pitch_min - np.arctan2(R[0, 2], R[2, 2]))
        if len(self.stop_dofs):
            self._hold_on_stops(q, f, lo, hi)

    def _hold_on_stops(self, q: np.ndarray, f: _Frame, lo: np.ndarray, hi: np.ndarray) -> None:
        """Step bounds (in place) keeping on its stop each joint that gravity presses there past
        ``stop_torque_nm`` (g_j is the torque the joint must give to hold still: below -cap at the upper stop, the
        motor cannot lift the joint off it), and the trunk's lift bound. Gravity's pass leaves the data's
        placements at q."""
        gravity = pin.computeGeneralizedGravity(self.model, self.data, q)
        tau, j = gravity[self.stop_dofs], self.stop_dofs - 6
        on_hi = (q[7:][j] >= self.box.q_hi[j] - STOP_TOLERANCE_RAD) & (tau < -self.stop_torque_nm)
        on_lo = (q[7:][j] <= self.box.q_lo[j] + STOP_TOLERANCE_RAD) & (tau > self.stop_torque_nm)
        lo[self.stop_dofs[on_hi]] = np.maximum(lo[self.stop_dofs[on_hi]], 0.0)
        hi[self.stop_dofs[on_lo]] = np.minimum(hi[self.stop_dofs[on_lo]], 0.0)
        if f.lift_speed_prev is not None:
            self._bound_lift(q, f, gravity[self.lift_dofs], lo, hi)

    def _lift_speed_prev(self, q_prev: np.ndarray | None) -> np.ndarray | None:
        """The trunk joints' speeds into ``q_prev`` [rad/s]: from the last solve's start when ``q_prev`` is its
        solution, else at rest; None without ``q_prev`` or the lift bound."""
        if self.lift_torque_nm is None or q_prev is None:
            return None
        last = self._last_solve
        if last is None or not np.array_equal(last[1], q_prev):
            return np.zeros(len(self.lift_dofs))
        j = self.lift_dofs - 6
        return (q_prev[7:][j] - last[0][7:][j]) / self.dt

    def _bound_lift(self, q: np.ndarray, f: _Frame, tau: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        """Step bounds (in place) keeping each trunk joint's acceleration against gravity (the sign of its gravity
        torque ``tau``) within its motor's room above gravity, ``lift_torque_nm`` - |tau|, over the trunk's inertia
        about the joint's axis (the joint-space inertia's diagonal; the parent's motion left out). A joint moving
        with gravity may turn at once (the stop, or the motor's whole limit, catches it)."""
        j = self.lift_dofs - 6
        if self._lift_inertia is None:      # one frame's steps move the trunk by a fraction of a degree
            pin.crba(self.model, self.data, q)
            self._lift_inertia = self.data.M[self.lift_dofs, self.lift_dofs].copy()
        inertia = self._lift_inertia
        up = np.sign(tau)
        accel = np.maximum(self.lift_torque_nm - np.abs(tau), 0.0) / inertia
        speed = np.maximum(up * f.lift_speed_prev, 0.0) + accel * self.dt
        reach = speed * self.dt - up * (q[7:][j] - f.q_prev[7:][j])      # how much further against gravity [rad]
        pos, neg = self.lift_dofs[up > 0], self.lift_dofs[up < 0]
        hi[pos] = np.minimum(hi[pos], reach[up > 0])
        lo[neg] = np.maximum(lo[neg], -reach[up < 0])

    def _integrate(self, q: np.ndarray, dq: np.ndarray, f: _Frame) -> np.ndarray:
        """q (+) dq, clipped exactly to the frame's joint box (limits and speed limits), whatever the QP's
        tolerance."""
        q = pin.integrate(self.model, q, dq)
        q[7:] = np.minimum(np.maximum(q[7:], f.q_lo), f.q_hi)
        return q

    def _result(self, q: np.ndarray, f: _Frame, feasible: bool, it: int, step: float,
                t0: float) -> IkResult:
        """The solution with its COM, sole and marker errors; FloatingPointError if q is not finite."""
        model, data = self.model, self.data
        if not np.isfinite(q).all():
            raise FloatingPointError("IK produced a non-finite configuration")
        com = pin.centerOfMass(model, data, q, False)       # with the joints' placements: no frame pass needed
        com_err = _norm((com - f.com_target).take(f.axes))
        return IkResult(q, feasible and com_err < 1e-3, com_err, it, step, time.perf_counter() - t0,
                        lambda: self._errors_at(q, f))

    def _errors_at(self, q: np.ndarray, f: _Frame) -> tuple[float, float]:
        """The largest sole pose error and the markers' RMS distance [m] at ``q``, on a data of their own (the
        solver's has moved on by the time they are read)."""
        model = self.model
        data = model.createData()
        pin.forwardKinematics(model, data, q)
        marker_rms = 0.0
        if len(f.fids):
            e = (self.points.positions(data, f.points) - f.targets).ravel()
            marker_rms = math.sqrt(e @ e / len(f.fids))
        sole_err = max(_norm(pin.log6(t.actInv(pin.updateFramePlacement(model, data, fid))).vector)
                       for fid, t in zip(self.soles, f.sole_targets))
        return sole_err, marker_rms

    def last_dual_residual(self) -> float:
        """The last step's QP stationarity residual max |H dq + g + multipliers' forces| (inf if it had no
        solution): a check of the solve, computed when asked."""
        return self._qp.dual_residual()


def _clamp_to_zero(lo: np.ndarray, hi: np.ndarray) -> None:
    """Joints' step bounds with zero inside (in place): a configuration just past a limit may always move back."""
    np.minimum(lo[6:], 0.0, out=lo[6:])
    np.maximum(hi[6:], 0.0, out=hi[6:])


def _norm(v: np.ndarray) -> float:
    """The Euclidean norm of a short vector (a third of ``np.linalg.norm``'s cost)."""
    return math.sqrt(v @ v)
