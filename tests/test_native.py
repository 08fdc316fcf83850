"""sit2stand.native: the compiled kernels give the NumPy and Pinocchio answers they replace, the QP kernel gives
the general solver's answers or none, and the IK is the same with or without them."""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from sit2stand import native
from sit2stand.human.marker_ik import MarkerIK
from sit2stand.human.offline import read_trial
from sit2stand.human.skeleton import Subject, build_human
from sit2stand.kinematics import PointJacobians
from sit2stand.optim import QpProblem, WarmQp
from sit2stand.retarget.ik import ComIk, MarkerTargets
from sit2stand.retarget.robot import robot_setup

from test_optim import proxsuite_answer, random_qp

DEMO = Path(__file__).resolve().parents[1] / "bags"

pytestmark = pytest.mark.skipif(native.kernels() is None, reason="no C compiler: the kernels are not built")


def filled(H, g, A, b, lo, hi, C, d, into: QpProblem | None = None) -> QpProblem:
    """A QP problem of the shape (``into``, or a new one), filled."""
    p = QpProblem(len(g), len(b), len(d)) if into is None else into
    p.H[:], p.g[:], p.A[:], p.b[:], p.lo[:], p.hi[:], p.C[:], p.d[:] = H, g, A, b, lo, hi, C, d
    return p


def random_q(model, rng):
    q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
    q[3:7] = rng.normal(size=4)
    q[3:7] /= np.linalg.norm(q[3:7])
    return q


@pytest.fixture(scope="module", params=["talos", "g1"])
def robot(request):
    return robot_setup(robot=request.param)


def test_marker_terms_equal_numpys(robot):
    """H = J'WJ + diag and g = J'W(p - t) of random marker subsets at random configurations, as the NumPy path."""
    model = robot.model
    rng = np.random.default_rng(0)
    data = model.createData()
    diagonal = rng.uniform(0, 1e-2, model.nv)
    terms = native.MarkerTerms.of(data, diagonal)
    assert terms is not None, "Pinocchio's placements are laid out as the kernel reads them"
    points = PointJacobians(model)
    for size in (1, 7, 25):
        q = random_q(model, rng)
        pin.computeJointJacobians(model, data, q)
        layout = points.point_set(np.array(sorted(rng.choice(range(1, model.nframes), size, replace=False))))
        w, t = rng.uniform(0.5, 20, size), rng.normal(size=(size, 3))
        P, J = points(data, layout)
        J = J.reshape(-1, model.nv) * np.repeat(np.sqrt(w), 3)[:, None]
        H, g = np.empty((model.nv, model.nv)), np.empty(model.nv)
        terms.load(layout, w, t)
        terms(H, g)
        assert np.abs(H - (J.T @ J + np.diag(diagonal))).max() < 1e-10
        assert np.abs(g - J.T @ (np.repeat(np.sqrt(w), 3) * (P - t).ravel())).max() < 1e-10


def test_sole_rows_equal_pinocchios_frame_jacobian_and_log(robot):
    """The feet's rows: LOCAL frame Jacobians and -log6(target^-1 X), targets near and far (2.5 rad) from the
    soles; a rotation error near pi is handed back to Pinocchio (None)."""
    model = robot.model
    rng = np.random.default_rng(1)
    data = model.createData()
    soles = list(robot.sole_frames)
    rows = native.SoleRows.of(model, data, soles, PointJacobians(model).point_set(soles))
    for scale in (1e-7, 1e-2, 0.5, 2.5):
        q = random_q(model, rng)
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        targets = [data.oMf[f] * pin.exp6(pin.Motion(rng.normal(size=6) * scale / np.sqrt(6))) for f in soles]
        A, b = np.empty((6 * len(soles) + 3, model.nv)), np.empty(6 * len(soles) + 3)
        rows.load(targets)
        assert rows(A, b)
        for k, (f, X) in enumerate(zip(soles, targets)):
            assert np.abs(A[6 * k:6 * k + 6] - pin.getFrameJacobian(model, data, f, pin.LOCAL)).max() < 1e-12
            assert np.abs(b[6 * k:6 * k + 6] + pin.log6(X.actInv(data.oMf[f])).vector).max() < 1e-9
    flipped = [data.oMf[f] * pin.SE3(pin.exp3(np.array([0.0, 0.0, 3.13])), np.zeros(3)) for f in soles]
    rows.load(flipped)
    assert not rows(A, b)


@pytest.mark.parametrize("seed", range(10))
def test_the_qp_kernel_answers_as_proxsuite_warm_or_not_at_all(seed):
    """Random QPs and their neighbours: every answer the kernel gives is proxsuite's; after the first, the
    neighbours are solved by the kernel from the last working set."""
    rng = np.random.default_rng(seed)
    qp = native.ActiveSetQp(native.kernels())
    problem = random_qp(rng)
    solved, p = 0, None
    for _ in range(5):
        H, g, A, b, lo, hi, C, d = problem
        p = filled(*problem, into=p)
        answer = qp.solve_problem(p)
        if answer is not None:
            x, lam = answer
            solved += 1
            assert np.abs(x - proxsuite_answer(*problem)).max() < 1e-7
            assert np.abs(H @ x + g + lam[:len(x)] + np.vstack((A, C)).T @ lam[len(x):]).max() < 1e-7
        problem = (H, g + rng.normal(size=len(g)) * 0.05, A, b + rng.normal(size=len(b)) * 0.005, lo, hi, C, d)
    assert solved >= 4


def test_the_qp_kernel_gives_no_answer_to_contradicting_equalities():
    rng = np.random.default_rng(1)
    H, g, _, _, lo, hi, _, _ = random_qp(rng, n=6, m=0, rows=0)
    A = np.array([[1.0, 0, 0, 0, 0, 0], [1.0, 0, 0, 0, 0, 0]])
    qp = filled(H, g, A, np.array([0.01, 0.02]), lo, hi, np.zeros((0, 6)), np.zeros(0))
    assert native.ActiveSetQp(native.kernels()).solve_problem(qp) is None


def first_step_qp(solver: ComIk, *args, **kwargs) -> tuple[np.ndarray, ...]:
    """H, g, A, b, lo, hi of the QP of ``solver.solve(*args, **kwargs)``'s first step (copies)."""
    taken = []

    def capture(qp):
        taken.append(tuple(a.copy() for a in (qp.H, qp.g, qp.A, qp.b, qp.lo, qp.hi)))
        return np.zeros(solver.nv)

    solver._qp.solve_problem = capture
    solver.solve(*args, max_iterations=1, **kwargs)
    return taken[0]


def test_a_steps_terms_in_one_call_equal_the_numpy_paths(robot):
    """The QP of one Gauss-Newton step, H, g, A, b, lo and hi, written by ``step_terms`` (markers, feet, posture,
    COM on two axes, the joints' box) as the NumPy path writes them, at random configurations (joints past their
    box among them) and targets."""
    model = robot.model
    rng = np.random.default_rng(3)
    mu = rng.uniform(1e-4, 1e-2, model.nv)
    solvers = [ComIk(model, list(robot.sole_frames), dt=0.01, posture_weight=mu) for _ in range(2)]
    solvers[1]._native = None
    assert solvers[0]._native is not None
    fids = np.array(sorted(rng.choice(range(1, model.nframes), 12, replace=False)))
    for _ in range(3):
        q, q_prev, q_ref = random_q(model, rng), random_q(model, rng), random_q(model, rng)
        markers = MarkerTargets(fids, rng.normal(size=(len(fids), 3)), rng.uniform(1, 20, len(fids)))
        feet = [pin.SE3(pin.exp3(rng.normal(size=3) * 0.3), rng.normal(size=3)) for _ in robot.sole_frames]
        args = (q, markers, rng.normal(size=3), feet)
        kernel, numpy = (first_step_qp(s, *args, q_ref=q_ref, q_prev=q_prev, com_axes=(0, 2)) for s in solvers)
        for name, a, b in zip(("H", "g", "A", "b", "lo", "hi"), kernel, numpy):
            assert np.abs(a - b).max() <= 1e-9 * max(1.0, np.abs(b).max()), name


def test_the_ik_is_the_same_with_or_without_the_kernels(robot):
    """A sequence of frames (markers on links, a COM target and the feet held, a speed-limited box; the stops, the
    trunk's lift, the momentum term, base holds hard and soft, the base's floor and a joint target in turn): the
    same configurations, to round-off, whichever path runs."""
    model = robot.model
    rng = np.random.default_rng(2)
    solvers = [ComIk(model, list(robot.sole_frames), dt=0.01, posture_weight=1e-3, momentum_weight=1e-3,
                     stop_torque_share=1.0, lift_torque_share=1.0) for _ in range(2)]
    solvers[1]._native = solvers[1]._native_soles = solvers[1]._qp._native = None
    assert solvers[0]._native is not None and solvers[0]._qp._native is not None
    q0, feet = robot.q_seated, list(robot.sole_targets)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q0)
    fids = np.array(sorted(rng.choice(range(1, model.nframes), 20, replace=False)))
    base = np.array([data.oMf[int(f)].translation for f in fids])
    com0 = pin.centerOfMass(model, data, q0)
    qs = [q0.copy(), q0.copy()]
    for k in range(20):
        markers = MarkerTargets(fids, base + 0.002 * k * rng.normal(size=base.shape), np.full(len(fids), 10.0))
        com = com0 + np.array([0.001 * k, 0.0, -0.002 * k])
        rules = [{}, {"base_xz": q0[:3]}, {"base_xz": q0[:3], "base_weight": 1e3, "base_pitch_min": -0.2},
                 {"base_z_min": q0[2] - 0.01, "joint_targets": [(model.nv - 1, 0.1, 3.0)]}][k % 4]
        qs = [ik.solve(q, markers, com, feet, q_prev=q, max_iterations=2, **rules).q for ik, q in zip(solvers, qs)]
        assert np.abs(qs[0] - qs[1]).max() < 1e-8


def test_warm_qp_falls_back_to_daqp_where_the_kernel_gives_up():
    """A QP the kernel cannot finish (one iteration allowed): the general solver's answer, and its working set
    seeds the next call, which the kernel then finishes."""
    rng = np.random.default_rng(4)
    solver = WarmQp()
    solver._native.MAX_ITERATIONS = 1
    problem = random_qp(rng)
    x = solver.solve(*problem)
    assert x is not None and np.abs(x - proxsuite_answer(*problem)).max() < 1e-6
    qp = next(iter(solver._problems.values()))
    assert solver._native.solve_problem(qp) is not None, "seeded from DAQP's answer, one iteration finishes it"


def _with_held_constraints_unbounded(problem, x, tol=1e-9):
    """The problem with the bounds and rows that hold at ``x`` made infinite (what a joint reaching its
    mechanical stop does to the whole-body QP's torque rows), and the indices of those bounds and rows."""
    H, g, A, b, lo, hi, C, d = (np.array(a, float) for a in problem)
    at_lo, at_hi = np.abs(x - lo) < tol, np.abs(x - hi) < tol
    rows = np.abs(C @ x - d) < tol
    lo[at_lo], hi[at_hi], d[rows] = -np.inf, np.inf, -np.inf
    return (H, g, A, b, lo, hi, C, d), at_lo | at_hi, rows


@pytest.mark.parametrize("seed", range(5))
def test_a_start_holding_a_bound_or_row_made_infinite_is_solved_not_nan(seed):
    """The next problem frees what the last working set held: the kernel drops those from its start and answers
    as proxsuite (no NaN from a variable held at an infinite bound), also when a general solver's multipliers (one
    NaN) seeded them."""
    rng = np.random.default_rng(seed)
    problem = random_qp(rng, rows=6)
    solver = native.ActiveSetQp(native.kernels())
    p = filled(*problem)
    x = solver.solve_problem(p)
    if x is None:                                  # seeded from the general answer
        solver.remember(p, np.where(np.abs(proxsuite_answer(*problem) - problem[4]) < 1e-9, -1.0, 0.0).tolist()
                        + [0.0] * (len(problem[3]) + len(problem[7])))
        x = solver.solve_problem(p)
    freed, held_bounds, held_rows = _with_held_constraints_unbounded(problem, x[0])
    assert held_bounds.any() or held_rows.any()
    p = filled(*freed, into=p)
    answer = solver.solve_problem(p)
    if answer is not None:
        assert np.isfinite(answer[0]).all()
        assert np.abs(answer[0] - proxsuite_answer(*(np.nan_to_num(a, posinf=1e20, neginf=-1e20) for a in freed)
                                                   )).max() < 1e-6
    lam = np.ones(len(p.g) + len(p.b) + len(p.d))            # a general solver's answer holding them all
    lam[:len(p.g)][held_bounds] = -1.0
    lam[0] = np.nan
    solver.remember(p, lam)
    answer = solver.solve_problem(p)
    assert answer is None or np.isfinite(answer[0]).all()


def test_warm_qp_answers_a_problem_whose_last_active_set_became_infinite():
    """WarmQp's DAQP path (the kernel disabled) on a problem that frees what the last answer held: DAQP's warm
    start from an active set with an infinite bound answers NaN, so it is solved again from the equalities."""
    rng = np.random.default_rng(7)
    problem = random_qp(rng, rows=6)
    solver = WarmQp()
    solver._native = None
    x = solver.solve(*problem)
    freed, held_bounds, held_rows = _with_held_constraints_unbounded(problem, x)
    assert held_bounds.any() or held_rows.any()
    again = solver.solve(*freed)
    assert again is not None and np.isfinite(again).all()
    assert np.abs(again - proxsuite_answer(*(np.nan_to_num(a, posinf=1e20, neginf=-1e20) for a in freed))
                  ).max() < 1e-6


def test_no_compiler_or_disabled_means_no_kernels_and_a_damaged_cache_is_built_again(monkeypatch, tmp_path):
    monkeypatch.setenv("SIT2STAND_CACHE", str(tmp_path))
    try:
        damaged = native.library_path(native.compiler())
        damaged.parent.mkdir(parents=True)
        damaged.write_bytes(b"not a library")
        native.kernels.cache_clear()
        assert native.kernels() is not None and damaged.stat().st_size > 1000
        for env in ({"SIT2STAND_NATIVE": "0"}, {"CC": str(tmp_path / "no-such-cc")}):
            native.kernels.cache_clear()
            with monkeypatch.context() as m:
                for k, v in env.items():
                    m.setenv(k, v)
                assert native.kernels() is None
    finally:
        native.kernels.cache_clear()


def test_the_skeleton_fit_is_the_same_with_or_without_the_kernels():
    """The human skeleton fitted to a shipped demonstration's frames, markers occluded at random: the same poses
    and residuals, to round-off, whichever path computes the markers' terms."""
    trial = read_trial(DEMO / "natural")
    human = build_human(Subject(trial.height_m, trial.mass_kg, trial.sex))
    fits = [MarkerIK(human, trial.marker_names) for _ in range(2)]
    fits[1]._terms = None
    assert fits[0]._terms is not None
    rng, fitted = np.random.default_rng(4), 0
    for k in range(0, len(trial.marker_t_s), 10):
        valid = trial.valid[k] & (rng.random(len(trial.marker_names)) > 0.1)
        a, b = (ik.fit(trial.positions[k], valid) for ik in fits)
        assert a.ok == b.ok and a.iterations == b.iterations and np.abs(a.q - b.q).max() < 1e-9
        if a.ok:       # a pelvis marker occluded leaves the frame unfitted, on both paths
            fitted += 1
            assert abs(a.rms_m - b.rms_m) < 1e-12
    assert fitted >= 20
