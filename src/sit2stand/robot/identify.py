"""Identification of the robot's mass / centre-of-mass parameters from static postures (Mistry et al. 2010, Sec. III).

In a static posture the floating-base dynamics reduce to gravity:

    g(q, phi) = Y(q) phi = S^T tau + sum_feet J_c(q)^T lambda

with phi_i = [m_i, m_i c_xi, m_i c_yi, m_i c_zi] per body (``pin.computeJointTorqueRegressor`` at zero velocity and
acceleration gives Y's mass and first-moment columns), tau the measured joint torques and lambda the measured ground
reactions at the soles (world axes, about the sole point). Stacking postures gives a linear problem:

* ``planar5``, the paper's reduced sagittal model: five links (foot, shank, thigh per leg, left = right; pelvis;
  torso with head and arms), 15 parameters (m, m c_x, m c_z), rows of the base's sagittal wrench and of the pitch
  joints (ankle, knee, hip, torso); weighted least squares.
* ``full``: every body's 4 parameters (the feet stay at CAD: their weight is already compensated in the F/T
  processing), all base and joint rows, solved as a QP (proxsuite) with physical consistency: masses between half
  CAD and CAD + 30 kg, each COM within ``com_bound_m`` of CAD's; a weak pull toward CAD resolves what the postures
  cannot see (the identifiable combinations come from the data; their count and the condition number are reported).

Evaluation (held-out postures): RMS of the predicted COM's forward position against the measured COP (forward
COM = COP in a static posture), and the CAD model's RMS on the same postures.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml

from ..errors import Sit2StandError
from ..io.bag import BagError, BagReader
from ..io.topics import (ROBOT_BASE_POSE_TOPIC, ROBOT_COP_TOPIC, ROBOT_FT_LEFT_TOPIC, ROBOT_FT_RIGHT_TOPIC,
                         ROBOT_JOINT_STATES_TOPIC, ft_topic)
from ..optim import constrained_lsq
from ..vectors import xyzw_from_wxyz
from .model import DEFAULT_ROBOT, SIDES, PlantConfig, controller_model
from .profile import profile_of

PLANAR_SEGMENTS = {
    # segment: the joint whose body frame holds its parameters (a leg role, per leg; "root" or "trunk_pitch")
    "foot": "ankle_pitch",
    "shank": "knee",
    "thigh": "hip_pitch",
    "pelvis": "root",
    "torso": "trunk_pitch",
}
"""The paper's five planar segments. Each segment is every body that moves with its joint while the lateral joints
(hip yaw and roll, ankle roll, trunk yaw and roll) stay at zero, as they do in the static postures: a mass anywhere on
the segment then acts on the base's sagittal wrench and on the pitch joints exactly as the same mass on the joint's own
body, so the segment's parameters are those of that body's frame (G1's thigh sums its hip pitch, roll and yaw links:
its hip pitch comes first in the chain, and the thigh's mass sits on the hip yaw link)."""


def planar_segment_joints(model: pin.Model) -> dict[str, list[str]]:
    """Per planar segment, the joint (one, or one per leg) whose body frame holds its parameters."""
    profile = profile_of(model)
    out = {}
    for segment, role in PLANAR_SEGMENTS.items():
        if role == "root":
            out[segment] = [model.names[1]]
        elif role == "trunk_pitch":
            if profile.trunk_pitch:              # without one, the torso is the pelvis's: one rigid body
                out[segment] = [profile.trunk_pitch]
        else:
            out[segment] = [profile.leg(s, role) for s in SIDES]
    return out


PLANAR_PRIOR_WEIGHT = 1e-2
"""The planar model's pull toward CAD's segment parameters (per kg or kg m; the rows weigh ~1 per N or N m): what the
postures cannot tell apart (a mass at the knee, on the thigh or on the shank; the foot's height) stays as CAD has it,
which moves the identifiable combinations by far less than the noise (their normal matrix reaches 1e4-1e5)."""


def cad_planar_parameters(model: pin.Model) -> np.ndarray:
    """(15,) CAD's planar parameters (m, m c_x, m c_z per segment, one leg's): each segment sums the bodies that move
    with its joint while the lateral joints are at zero (a body belongs to its nearest segment joint up the chain),
    in that joint's frame at the neutral posture."""
    segments = planar_segment_joints(model)
    owner = {model.getJointId(j): (seg, k == 0) for seg, joints in segments.items() for k, j in enumerate(joints)}
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    out = {seg: np.zeros(3) for seg in segments}
    for j in range(1, model.njoints):
        a = j
        while a not in owner:
            a = model.parents[a]
        seg, counted = owner[a]
        if not counted:                  # the right leg's bodies: the left's mirror, counted once
            continue
        inertia = model.inertias[j]
        com = data.oMi[a].actInv(data.oMi[j].act(inertia.lever))
        out[seg] += inertia.mass * np.array([1.0, com[0], com[2]])
    return np.concatenate(list(out.values()))


def planar_joint_rows(model: pin.Model) -> list[str]:
    """The joints whose torques the planar model explains: the trunk pitch, then each leg's hip, knee, ankle pitch."""
    profile = profile_of(model)
    trunk = [profile.trunk_pitch] if profile.trunk_pitch else []
    return trunk + [profile.leg(s, r) for s in SIDES for r in ("hip_pitch", "knee", "ankle_pitch")]


class IdentificationError(Sit2StandError, ValueError):
    """Data that cannot identify the model; the message names the rank, the condition number or the file."""


@dataclass
class PostureData:
    """The static postures of a bag (plant joint order; base pose in MuJoCo order x y z qw qx qy qz)."""

    joint_names: list[str]
    q: np.ndarray
    tau: np.ndarray
    wrench: dict[str, np.ndarray]
    cop: np.ndarray
    base_pose: np.ndarray

    def __len__(self) -> int:
        return len(self.q)


def read_postures(path: str | Path) -> PostureData:
    """Load the postures written by ``collect-postures`` (names the bag and the topic on any problem)."""

    with BagReader(path) as bag:
        topics = bag.topics()
        need = [ROBOT_JOINT_STATES_TOPIC, ROBOT_FT_LEFT_TOPIC, ROBOT_FT_RIGHT_TOPIC, ROBOT_COP_TOPIC,
                ROBOT_BASE_POSE_TOPIC]
        missing = [t for t in need if t not in topics]
        if missing:
            raise BagError(f"{path}: not a static-posture bag: no {', '.join(missing)}")
        js = bag.read(ROBOT_JOINT_STATES_TOPIC)
        names = list(js[0][1].name)
        q = np.array([m.position for _, m in js])
        tau = np.array([m.effort for _, m in js])
        wrench = {}
        for side in SIDES:
            msgs = bag.read(ft_topic(side))
            wrench[side] = np.array([[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z, m.wrench.torque.x,
                                      m.wrench.torque.y, m.wrench.torque.z] for _, m in msgs])
        cop = np.array([[m.point.x, m.point.y, m.point.z] for _, m in bag.read(ROBOT_COP_TOPIC)])
        base = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z, m.pose.orientation.w,
                          m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z]
                         for _, m in bag.read(ROBOT_BASE_POSE_TOPIC)])
    return PostureData(names, q, tau, wrench, cop, base)


def _pin_q(model: pin.Model, data: PostureData, k: int) -> np.ndarray:
    b = data.base_pose[k]
    q = pin.neutral(model)
    q[:3] = b[:3]
    q[3:7] = xyzw_from_wxyz(b[3:7])
    idx = {n: model.joints[model.getJointId(n)].idx_q for n in data.joint_names}
    for j, name in enumerate(data.joint_names):
        q[idx[name]] = data.q[k, j]
    return q


def static_rows(model: pin.Model, mdata: pin.Data, data: PostureData, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Y (nv, 4 * nbodies) and b (nv) of posture ``k``: Y phi = S^T tau + sum J_c^T lambda."""
    q = _pin_q(model, data, k)
    zero = np.zeros(model.nv)
    Y10 = pin.computeJointTorqueRegressor(model, mdata, q, zero, zero)
    nb = model.njoints - 1
    Y = np.hstack([Y10[:, 10 * i:10 * i + 4] for i in range(nb)])
    tau_full = np.zeros(model.nv)
    for j, name in enumerate(data.joint_names):
        tau_full[model.joints[model.getJointId(name)].idx_v] = data.tau[k, j]
    pin.computeJointJacobians(model, mdata, q)
    pin.updateFramePlacements(model, mdata)
    rhs = tau_full.copy()
    for side in SIDES:
        J = pin.getFrameJacobian(model, mdata, model.getFrameId(f"sole_{side}"), pin.LOCAL_WORLD_ALIGNED)
        rhs += J.T @ data.wrench[side][k]
    return Y, rhs


def cad_parameters(model: pin.Model) -> np.ndarray:
    """phi of the model (4 per body: m, m c_x, m c_y, m c_z in the joint frame)."""
    return np.concatenate([[model.inertias[i].mass, *(model.inertias[i].mass * model.inertias[i].lever)]
                           for i in range(1, model.njoints)])


def with_parameters(model: pin.Model, phi: np.ndarray) -> pin.Model:
    """A copy of ``model`` with masses and COMs from phi (rotational inertias scaled with mass)."""
    out = model.copy()
    for i in range(1, model.njoints):
        m, mc = phi[4 * (i - 1)], phi[4 * (i - 1) + 1:4 * i]
        old = model.inertias[i]
        scale = m / old.mass if old.mass > 0 else 1.0
        out.inertias[i] = pin.Inertia(max(m, 1e-9), mc / m if m > 1e-9 else old.lever, old.inertia * max(scale, 0.0))
    return out


def com_x(model: pin.Model, data: PostureData, k: int) -> float:
    return float(pin.centerOfMass(model, model.createData(), _pin_q(model, data, k))[0])


@dataclass
class IdentificationResult:
    model_name: str
    names: list[str]
    values: np.ndarray
    std_devs: np.ndarray
    train_rms_m: float
    eval_rms_m: float
    cad_train_rms_m: float
    cad_eval_rms_m: float
    condition_number: float
    rank: int
    n_train: int
    n_eval: int
    total_mass_kg: float
    cad_mass_kg: float
    seconds: float
    link_parameters: dict[str, dict] = field(default_factory=dict)   # joint -> {mass, com} for the full model
    eval_predictions: dict[str, list[float]] = field(default_factory=dict)
    robot: str = DEFAULT_ROBOT                                        # the robot profile's name

    def summary(self) -> str:
        return (f"{self.model_name}: held-out COM-vs-COP RMS {self.eval_rms_m * 1e3:.1f} mm (CAD "
                f"{self.cad_eval_rms_m * 1e3:.1f} mm) on {self.n_eval} postures; training {self.train_rms_m * 1e3:.1f} "
                f"mm (CAD {self.cad_train_rms_m * 1e3:.1f}) on {self.n_train}; total mass {self.total_mass_kg:.1f} kg "
                f"(CAD {self.cad_mass_kg:.1f}); rank {self.rank}, condition number {self.condition_number:.3g}; "
                f"{self.seconds * 1e3:.0f} ms")


def split(n: int, eval_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Train / evaluation indices (the paper held out 10 %)."""
    rng = np.random.default_rng(seed)
    order = rng.permutation(n)
    n_eval = max(1, int(round(eval_fraction * n)))
    return np.sort(order[n_eval:]), np.sort(order[:n_eval])


def _check_data(data: PostureData, train: np.ndarray, Y: np.ndarray, min_postures: int = 5) -> tuple[int, float]:
    """Numerical rank and condition number of the column-scaled regressor; refuse data that cannot identify."""
    scale = np.linalg.norm(Y, axis=0)
    keep = scale > 1e-9 * max(scale.max(), 1e-300)
    s = np.linalg.svd(Y[:, keep] / scale[keep], compute_uv=False)
    rank = int(np.sum(s > 1e-8 * s[0]))
    cond = float(s[0] / s[rank - 1]) if rank else float("inf")
    distinct = len({tuple(np.round(data.q[k], 2)) for k in train})
    if distinct < min_postures:
        raise IdentificationError(f"only {distinct} distinct posture(s) in the training set (need {min_postures}): "
                                  f"the stacked regressor has rank {rank} and condition number {cond:.3g}")
    return rank, cond


def identify_full(data: PostureData, eval_fraction: float = 0.1, seed: int = 0, com_bound_m: float = 0.35,
                  max_extra_kg: float = 30.0, prior_weight: float = 1.0, tau_sd_nm: float = 1.0,
                  wrench_sd: float = 2.0, model: pin.Model | None = None) -> IdentificationResult:
    """The full model (see the module docstring); ``model``: the CAD controller model, if already built."""
    t0 = time.perf_counter()
    model = model if model is not None else controller_model()
    mdata = model.createData()
    train, ev = split(len(data), eval_fraction, seed)
    rows = [static_rows(model, mdata, data, k) for k in range(len(data))]
    phi_cad = cad_parameters(model)
    nb = model.njoints - 1
    fixed = np.zeros(4 * nb, bool)
    for side in SIDES:          # the feet: their weight is already taken out of the F/T reading with CAD
        i = model.getJointId(profile_of(model).foot_joint(side)) - 1
        fixed[4 * i:4 * i + 4] = True
    free = ~fixed
    A = np.vstack([rows[k][0] for k in train])
    b = np.concatenate([rows[k][1] for k in train]) - A[:, fixed] @ phi_cad[fixed]
    A = A[:, free]
    rank, cond = _check_data(data, train, A)
    w = np.tile(np.r_[[1 / wrench_sd] * 6, [1 / tau_sd_nm] * (model.nv - 6)], len(train))
    m_cad = phi_cad[0::4]
    lb, ub = np.zeros(4 * nb), np.zeros(4 * nb)
    m_hi = m_cad + max_extra_kg
    lb[0::4], ub[0::4] = 0.5 * m_cad, m_hi
    for a in (1, 2, 3):          # |m c - m c_cad| <= m_max * bound, a linear box around CAD's first moment
        lb[a::4] = phi_cad[a::4] - m_hi * com_bound_m
        ub[a::4] = phi_cad[a::4] + m_hi * com_bound_m
    prior_w = np.full(4 * nb, prior_weight)
    res = constrained_lsq(A, b, weights=w, lb=lb[free], ub=ub[free], prior=phi_cad[free],
                          prior_weights=prior_w[free], eps_abs=1e-6)   # N m-scale residuals: 1e-6 is ample
    phi = phi_cad.copy()
    phi[free] = res.x
    ident = with_parameters(model, phi)
    out = _evaluate("full", data, train, ev, model, ident, t0, rank, cond)
    out.names = [f"{model.names[i + 1]}.{p}" for i in range(nb) for p in ("mass", "mcx", "mcy", "mcz")]
    out.values = phi
    out.std_devs = np.full(len(phi), np.nan)
    out.link_parameters = {model.names[i]: {"mass": float(ident.inertias[i].mass),
                                            "com": ident.inertias[i].lever.tolist()} for i in range(1, model.njoints)}
    return out


def planar_columns(model: pin.Model, Y: np.ndarray) -> np.ndarray:
    """(nv, 15) columns of the planar5 parameters (m, m c_x, m c_z per link; legs left = right; 12 without a trunk
    pitch joint)."""
    cols = []
    for joints in planar_segment_joints(model).values():
        for a in (0, 1, 3):     # m, m c_x, m c_z of the segment's frame body
            cols.append(sum(Y[:, 4 * (model.getJointId(j) - 1) + a] for j in joints))
    return np.stack(cols, axis=1)


def identify_planar5(data: PostureData, eval_fraction: float = 0.1, seed: int = 0, tau_sd_nm: float = 1.0,
                     wrench_sd: float = 2.0, model: pin.Model | None = None) -> IdentificationResult:
    """The paper's reduced sagittal model (see the module docstring); ``model`` as in :func:`identify_full`."""
    t0 = time.perf_counter()
    model = model if model is not None else controller_model()
    mdata = model.createData()
    train, ev = split(len(data), eval_fraction, seed)
    rows = planar_joint_rows(model)
    segments = planar_segment_joints(model)
    row_idx = [0, 2, 4] + [model.joints[model.getJointId(j)].idx_v for j in rows]
    A_list, b_list = [], []
    for k in range(len(data)):
        Y, rhs = static_rows(model, mdata, data, k)
        A_list.append(planar_columns(model, Y)[row_idx])
        b_list.append(rhs[row_idx])
    A = np.vstack([A_list[k] for k in train])
    b = np.concatenate([b_list[k] for k in train])
    rank, cond = _check_data(data, train, A)
    w = np.tile(np.r_[[1 / wrench_sd] * 3, [1 / tau_sd_nm] * len(rows)], len(train))
    res = constrained_lsq(A, b, weights=w, prior=cad_planar_parameters(model),
                          prior_weights=np.full(A.shape[1], PLANAR_PRIOR_WEIGHT))
    theta = res.x
    # covariance of weighted least squares, from the training residual
    Aw = A * w[:, None]
    resid = Aw @ theta - b * w
    dof = max(1, len(b) - A.shape[1])
    cov = np.linalg.pinv(Aw.T @ Aw) * (resid @ resid / dof)

    def predict(k: int) -> float:
        q = _pin_q(model, data, k)
        pin.forwardKinematics(model, mdata, q)
        total_m, moment = 0.0, 0.0
        for i, joints in enumerate(segments.values()):
            m, mcx, mcz = theta[3 * i:3 * i + 3]
            for j in joints:
                M = mdata.oMi[model.getJointId(j)]
                total_m += m
                moment += m * M.translation[0] + (M.rotation @ np.array([mcx, 0.0, mcz]))[0]
        return moment / total_m

    t_train = np.array([predict(k) for k in train])
    t_eval = np.array([predict(k) for k in ev])
    rms = lambda pred, idx: float(np.sqrt(np.mean((pred - data.cop[idx, 0]) ** 2)))  # noqa: E731
    cad_train = np.array([com_x(model, data, k) for k in train])
    cad_eval = np.array([com_x(model, data, k) for k in ev])
    total = sum(theta[3 * i] * len(joints) for i, joints in enumerate(segments.values()))
    names = [f"{segment}.{p}" for segment in segments for p in ("mass", "mcx", "mcz")]
    return IdentificationResult("planar5", names, theta, np.sqrt(np.maximum(np.diag(cov), 0.0)), rms(t_train, train),
                                rms(t_eval, ev), rms(cad_train, train), rms(cad_eval, ev), cond, rank, len(train),
                                len(ev), float(total), float(pin.computeTotalMass(model)), time.perf_counter() - t0,
                                eval_predictions={"cop_x": data.cop[ev, 0].tolist(), "identified_x": t_eval.tolist(),
                                                  "cad_x": cad_eval.tolist()})


def _evaluate(name: str, data: PostureData, train, ev, cad: pin.Model, ident: pin.Model, t0: float, rank: int,
              cond: float) -> IdentificationResult:
    pred = {k: com_x(ident, data, k) for k in range(len(data))}
    cad_pred = {k: com_x(cad, data, k) for k in range(len(data))}
    rms = lambda p, idx: float(np.sqrt(np.mean([(p[k] - data.cop[k, 0]) ** 2 for k in idx])))  # noqa: E731
    return IdentificationResult(name, [], np.zeros(0), np.zeros(0), rms(pred, train), rms(pred, ev),
                                rms(cad_pred, train), rms(cad_pred, ev), cond, rank, len(train), len(ev),
                                float(pin.computeTotalMass(ident)), float(pin.computeTotalMass(cad)),
                                time.perf_counter() - t0,
                                eval_predictions={"cop_x": [float(data.cop[k, 0]) for k in ev],
                                                  "identified_x": [pred[k] for k in ev],
                                                  "cad_x": [cad_pred[k] for k in ev]})


def identify(path: str | Path, model: str = "full", eval_fraction: float = 0.1, seed: int = 0,
             robot: str | None = None) -> IdentificationResult:
    """Identify ``model`` ("planar5" or "full") from the posture bag at ``path`` of ``robot`` (a profile; default
    TALOS)."""
    if model not in ("planar5", "full"):
        raise IdentificationError(f"model must be 'planar5' or 'full', not {model!r}")
    if not 0.0 < eval_fraction < 0.9:
        raise IdentificationError(f"eval_fraction {eval_fraction:g} must be in (0, 0.9)")
    data = read_postures(path)
    if len(data) < 6:
        raise IdentificationError(f"{path}: only {len(data)} postures (need at least 6: 5 to train, 1 to evaluate)")
    cad = controller_model(PlantConfig.load(None, robot))   # built once (~0.3 s): the joint check, the fit
    check_postures(data, cad, path)
    fn = identify_full if model == "full" else identify_planar5
    result = fn(data, eval_fraction=eval_fraction, seed=seed, model=cad)
    result.robot = profile_of(cad).name
    check_result(result, path)
    return result


MASS_RATIO_RANGE = (0.67, 1.5)
"""Plausible identified total mass over CAD's: a robot carries extra parts, not twice or half its CAD mass."""
EVAL_WORSE_THAN_CAD = 1.5
"""The held-out COM error may not exceed CAD's by more than this factor (and 5 mm): a fit that predicts worse than
the CAD model it started from learned the noise, not the robot."""


def check_postures(data: PostureData, model: pin.Model, path: str | Path) -> None:
    """The postures name exactly the model's joints and hold finite numbers.

    Raises:
        IdentificationError: foreign or missing joints (named), or postures with NaN or infinite values (listed).
    """
    joints = [n for n in model.names[2:]]
    foreign = [n for n in data.joint_names if n not in joints]
    if foreign:
        raise IdentificationError(f"{path}: joints the robot model ({model.name}) does not have: "
                                  f"{', '.join(foreign[:6])}{' ...' if len(foreign) > 6 else ''} (postures of "
                                  f"another robot? pass its --robot)")
    missing = [n for n in joints if n not in data.joint_names]
    if missing:
        raise IdentificationError(f"{path}: {len(data.joint_names)} of the robot's {len(joints)} joints; missing "
                                  f"{', '.join(missing[:6])}{' ...' if len(missing) > 6 else ''}")
    arrays = {"joint positions": data.q, "joint torques": data.tau, "COP": data.cop, "base pose": data.base_pose,
              **{f"{side} F/T wrench": w for side, w in data.wrench.items()}}
    for what, values in arrays.items():
        bad = np.flatnonzero(~np.all(np.isfinite(np.asarray(values, float).reshape(len(values), -1)), axis=1))
        if len(bad):
            raise IdentificationError(f"{path}: {what} not finite in posture(s) {', '.join(map(str, bad[:8]))}")


def check_result(result: IdentificationResult, path: str | Path) -> None:
    """The identified parameters are physically plausible and predict better than CAD's.

    Raises:
        IdentificationError: a total mass outside :data:`MASS_RATIO_RANGE` of CAD's (likely scaled forces), or a
            held-out error beyond :data:`EVAL_WORSE_THAN_CAD` times CAD's.
    """
    ratio = result.total_mass_kg / result.cad_mass_kg
    if not MASS_RATIO_RANGE[0] <= ratio <= MASS_RATIO_RANGE[1]:
        raise IdentificationError(f"{path}: identified total mass {result.total_mass_kg:.1f} kg is {ratio:.2f} x "
                                  f"CAD's {result.cad_mass_kg:.1f} kg: check the force units and the F/T scaling")
    if not np.isfinite(result.eval_rms_m) or \
            result.eval_rms_m > max(EVAL_WORSE_THAN_CAD * result.cad_eval_rms_m, result.cad_eval_rms_m + 0.005):
        raise IdentificationError(f"{path}: held-out COM error {result.eval_rms_m * 1e3:.1f} mm against CAD's "
                                  f"{result.cad_eval_rms_m * 1e3:.1f} mm: the postures do not determine the "
                                  f"parameters (too few, too alike, or inconsistent)")


def read_link_parameters(path: str | Path) -> dict:
    """The per-link parameters (``{joint: {mass, com}}``) of a YAML written by :func:`write_yaml`, for
    ``model.apply_link_parameters``.

    Raises:
        IdentificationError: the file is not valid YAML or has no ``links`` (only ``--model full`` writes them).
        OSError: the file cannot be read.
    """
    try:
        doc = yaml.safe_load(Path(path).read_text())
    except yaml.YAMLError as err:
        raise IdentificationError(f"{path}: not valid YAML: {err}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("links"), dict):
        raise IdentificationError(f"{path}: no per-link parameters ('links'); identify with --model full")
    return doc["links"]


def write_yaml(result: IdentificationResult, path: str | Path, source: str = "", robot: str = "") -> None:
    """The parameters for the retargeter and the analysis (``model.apply_link_parameters`` loads ``links``);
    ``robot``: the profile's name, which the file carries (a model of another robot refuses its links)."""
    doc = {"robot": robot, "model": result.model_name, "source": source, "total_mass_kg": result.total_mass_kg,
           "cad_mass_kg": result.cad_mass_kg, "eval_rms_m": result.eval_rms_m, "cad_eval_rms_m": result.cad_eval_rms_m,
           "train_rms_m": result.train_rms_m, "cad_train_rms_m": result.cad_train_rms_m,
           "condition_number": result.condition_number, "rank": result.rank,
           "parameters": {n: float(v) for n, v in zip(result.names, result.values)}}
    if result.link_parameters:
        doc["links"] = result.link_parameters
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(yaml.safe_dump(doc, sort_keys=False))
