"""The nominal model evaluated along a measured recording: residuals per channel, and each candidate effect's signature.

For a floating-base robot whose only contacts are measured (the feet's F/T sensors), the equations of motion hold
row by row along the measured state (q, v, a):

    e(t) = S^T tau_meas + sum_feet J_foot^T w_foot - RNEA_model(q, v, a)        (nv rows)

e is zero, up to noise, when the model is right. Its rows are the **channels**: the six base rows (the whole body's
external wrench: expressed here in world axes about the midpoint of the soles, as force [N] and moment [N m]) and one
row per actuated joint [N m]. While the robot sits, the seat pushes on the pelvis and thighs unmeasured: the base
rows and the hip rows (yaw, roll, pitch: ``SEATED_HIP_ROLES``) are then excluded; the knees, ankles, torso, arms and
head still hold. A joint at its position limit is held by its hard stop, whose torque the joint's sensor does not
measure: its row is excluded there.

Every candidate physical effect enters e linearly, to first order, through a **signature** (columns d e / d theta):

* extra point mass on a body (theta = m, m c_x, m c_y, m c_z in the body frame [kg, kg m]): the body's mass and
  first-moment columns of ``pin.computeJointTorqueRegressor`` (its rotational inertia m |c|^2 is neglected);
* joint viscous friction [N m s/rad]: q'_j on row j; Coulomb friction [N m]: sat(q'_j / v0) on row j
  (:func:`coulomb_signature`);
* joint spring (stiffness k [N m/rad], preload -k q_rest [N m]): q_j and 1 on row j (the actuator holds the spring);
* rotor inertia (armature beyond the model's) [kg m^2]: q''_j on row j;
* joint-torque sensor bias [N m]: 1 on row j; gain error (measured / true - 1): the model torque on row j;
* joint encoder offset (reading - true angle) [rad]: d e / d q_j, by finite differences of the whole evaluation;
* force/torque sensor bias per foot (sensor axes, [N], [N m]): J_sole^T of the bias carried to the ground reaction.

Actuator delay does not show in e (the measured torque is the applied one, whenever it was commanded): it shows in
the controller channels, ``ctrl/<joint>`` = measured torque - the control law re-evaluated from the recorded commands
(:mod:`sit2stand.gap.control`), added when the bag has the commands; the torque sensor's bias and gain show there
too, masses and friction do not. A gear's play (backlash, half-width b [rad]) shows there alone, as the dead zone it
cuts from the motor's drive: -kp_j sat(drive_j / (kp_j b0_j)) on ``ctrl/<joint>`` (:func:`fit_backlash_widths`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..robot.model import SIDES
from ..robot.profile import profile_of
from ..vectors import xyzw_from_wxyz
from .control import ControlLaw
from .effects import EFFECT_KINDS
from .recording import Recording, _joint_index

CONTROLLER_PREFIX = "ctrl/"    # the controller channels: measured torque - our control law (no physics in them)
BASE_CHANNELS = ["base/force_x", "base/force_y", "base/force_z", "base/moment_x", "base/moment_y", "base/moment_z"]
SEATED_HIP_ROLES = ("hip_yaw", "hip_roll", "hip_pitch")   # the seat pushes on the thighs: their rows are out
COULOMB_V0_RADPS = 0.03       # Coulomb friction's transition speed where none was fitted (fit_coulomb_widths)
COULOMB_V0_GRID_RADPS = (0.001, 0.002, 0.005, 0.01, 0.02, 0.03)
BACKLASH_GRID_RAD = (0.0005, 0.001, 0.002, 0.003, 0.005, 0.008, 0.012, 0.02)   # half-widths of a gear's play tried
FD_STEP_RAD = 1e-5
LIMIT_MARGIN_RAD = 0.01


@dataclass
class Evaluation:
    """The nominal model along a recording (N samples, C = 6 + n channels)."""

    channels: list[str]
    e: np.ndarray                 # (N, C) measured - model
    valid: np.ndarray             # (N, C) rows the measured contacts fully determine
    tau_model: np.ndarray         # (N, n) joint torques the model predicts from the measured motion and wrenches
    mass_cols: np.ndarray         # (N, C, nb, 4) extra-mass signature per body (Pinocchio joint 1..nb)
    offset_cols: np.ndarray       # (N, C, n) encoder-offset signature per joint
    ft_cols: dict[str, np.ndarray]   # side -> (N, C, 6) F/T-bias signature
    body_names: list[str]         # link name of each Pinocchio body (joint 1..nb)
    centre_m: np.ndarray          # (N, 3) the point the base moments are taken about (mid-soles)
    sole_m: dict[str, np.ndarray]  # side -> (N, 3) sole point [m] (measured base pose and joints)
    ctrl_law: np.ndarray | None = None     # (N, n) the control law's torque (gap.control), when commands were recorded
    ctrl_delay: np.ndarray | None = None   # (N, n) its actuator-delay signature
    coulomb_v0: np.ndarray | None = None   # (n,) each joint's Coulomb transition speed [rad/s] (fit_coulomb_widths)
    ctrl_drive: np.ndarray | None = None   # (N, n) the law without the joint's damping (gap.control.ControlLaw)
    ctrl_kp: np.ndarray | None = None      # (n,) the joint PD's stiffness [N m/rad]
    backlash_b0: np.ndarray | None = None  # (n,) each joint's play half-width its signature uses [rad]

    @property
    def n_joints(self) -> int:
        """Number of actuated joints n."""
        return self.tau_model.shape[1]

    def add_control(self, law: ControlLaw, tau_meas: np.ndarray, joint_names: list[str]) -> None:
        """Append the controller channels ``ctrl/<joint>``: measured torque - control law (see gap.control)."""
        N, n = law.torque.shape
        ok = law.valid
        self.channels = self.channels + [f"{CONTROLLER_PREFIX}{j}" for j in joint_names]
        self.e = np.hstack([self.e, np.where(ok[:, None], tau_meas - law.torque, 0.0)])
        self.valid = np.hstack([self.valid, np.repeat(ok[:, None], n, axis=1)])
        self.mass_cols = np.concatenate([self.mass_cols, np.zeros((N, n) + self.mass_cols.shape[2:])], axis=1)
        self.offset_cols = np.concatenate([self.offset_cols, np.zeros((N, n, n))], axis=1)
        self.ft_cols = {s: np.concatenate([c, np.zeros((N, n, 6))], axis=1) for s, c in self.ft_cols.items()}
        self.ctrl_law, self.ctrl_delay = law.torque, law.delay
        self.ctrl_drive, self.ctrl_kp = law.drive, law.kp

    @property
    def joint_channels(self) -> slice:
        """The channels after the six base rows (joint torques, then controller channels)."""
        return slice(6, len(self.channels))


def body_link_names(model: pin.Model) -> list[str]:
    """The link (body) name of each Pinocchio joint 1..njoints-1 (the first body frame on it)."""
    out = []
    for jid in range(1, model.njoints):
        names = [f.name for f in model.frames if f.parentJoint == jid and f.type == pin.FrameType.BODY]
        out.append(names[0] if names else model.names[jid])
    return out


def _pin_q(model: pin.Model, rec: Recording, k: int, idx_v: np.ndarray) -> np.ndarray:
    """Pinocchio configuration of sample ``k`` (base quaternion reordered to x, y, z, w)."""
    q = pin.neutral(model)
    b = rec.base_pose[k]
    q[:3] = b[:3]
    q[3:7] = xyzw_from_wxyz(b[3:7])
    q[idx_v + 1] = rec.q[k]
    return q


class _Rows:
    """b(q) - RNEA(q, v, a) for one sample, and the pieces the signatures need."""

    def __init__(self, model: pin.Model) -> None:
        self.model, self.data = model, model.createData()
        self.soles = {s: model.getFrameId(f"sole_{s}") for s in SIDES}

    def residual(self, q, v, a, tau_full, wrench: dict[str, np.ndarray]) -> tuple[np.ndarray, dict]:
        """e = tau + sum_feet J^T w - RNEA(q, v, a) (v order) and the soles' Jacobians (side -> 6 x nv)."""
        m, d = self.model, self.data
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacements(m, d)
        J = {s: pin.getFrameJacobian(m, d, f, pin.LOCAL_WORLD_ALIGNED) for s, f in self.soles.items()}
        b = tau_full.copy()
        for s in SIDES:
            b += J[s].T @ wrench[s]
        return b - pin.rnea(m, d, q, v, a), J


def base_to_world(q: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """6x6 map of the base rows (a wrench in the base frame, at the base origin) to world axes about ``centre``."""
    R = pin.Quaternion(q[3:7]).normalized().matrix()
    p = q[:3] - centre
    T = np.zeros((6, 6))
    T[:3, :3] = R
    T[3:, 3:] = R
    T[3:, :3] = pin.skew(p) @ R
    return T


@dataclass
class _Sample:
    """One recorded sample in the model's terms: q, v, a (Pinocchio order), joint torques [N m] (v order), and the
    feet's wrenches (side -> [N, N m])."""

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    tau_full: np.ndarray
    wrench: dict[str, np.ndarray]


def _sample(model: pin.Model, rec: Recording, k: int, idx_v: np.ndarray) -> _Sample:
    """Sample ``k`` of ``rec`` as Pinocchio state, torques and wrenches."""
    q = _pin_q(model, rec, k, idx_v)
    v = np.concatenate([rec.base_v[k], np.zeros(model.nv - 6)])
    a = np.concatenate([rec.base_a[k], np.zeros(model.nv - 6)])
    v[idx_v], a[idx_v] = rec.qd[k], rec.qdd[k]
    tau_full = np.zeros(model.nv)
    tau_full[idx_v] = rec.tau[k]
    return _Sample(q, v, a, tau_full, {s: rec.wrench[s][k] for s in SIDES})


def _to_channels(x: np.ndarray, perm: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Rows of the model's v order (leading axis) -> channel order, base rows to world about the centre (T)."""
    out = x[perm].copy()
    out[:6] = np.tensordot(T, x[:6], axes=(1, 0))
    return out


def evaluate(model: pin.Model, rec: Recording, seated: np.ndarray | None = None,
             offsets: bool = True, signatures: bool = True) -> Evaluation:
    """Evaluate ``model`` along ``rec`` (see the module docstring); ``seated`` (N,) marks samples with the seat
    loaded (base and hip rows invalid); ``offsets`` / ``signatures``: the encoder-offset signatures / all the
    candidates' signatures (left at zero without: the residual alone costs a third of the time)."""
    n = len(rec.joint_names)
    N = len(rec)
    C = 6 + n
    idx_v = _joint_index(model, rec.joint_names)
    perm = np.concatenate([np.arange(6), idx_v])          # channel order: base rows, then the recording's joints
    rows = _Rows(model)
    nb = model.njoints - 1
    e = np.zeros((N, C))
    tau_model = np.zeros((N, n))
    mass_cols = np.zeros((N, C, nb, 4))
    offset_cols = np.zeros((N, C, n))
    ft_cols = {s: np.zeros((N, C, 6)) for s in SIDES}
    centre = np.zeros((N, 3))
    sole = {s: np.zeros((N, 3)) for s in SIDES}
    for k in range(N):
        smp = _sample(model, rec, k, idx_v)
        r, J = rows.residual(smp.q, smp.v, smp.a, smp.tau_full, smp.wrench)
        for s in SIDES:
            sole[s][k] = rows.data.oMf[rows.soles[s]].translation
        centre[k] = 0.5 * (sole["left"][k] + sole["right"][k])
        T = base_to_world(smp.q, centre[k])
        e[k] = _to_channels(r, perm, T)
        tau_model[k] = rec.tau[k] - e[k, 6:]
        if not signatures:
            continue
        Y = pin.computeJointTorqueRegressor(model, rows.data, smp.q, smp.v, smp.a)
        mass_cols[k] = _to_channels(Y.reshape(model.nv, nb, 10)[:, :, :4], perm, T)
        for s in SIDES:
            _ft_bias_columns(rows, s, J[s], perm, T, ft_cols[s][k])
        if offsets:
            _offset_columns(rows, smp, r, idx_v, perm, T, offset_cols[k])
    channels = BASE_CHANNELS + [f"tau/{j}" for j in rec.joint_names]
    return Evaluation(channels, e, _valid_rows(model, rec, idx_v, seated), tau_model, mass_cols, offset_cols, ft_cols,
                      body_link_names(model), centre, sole)


def _ft_bias_columns(rows: _Rows, side: str, J: np.ndarray, perm: np.ndarray, T: np.ndarray, out: np.ndarray) -> None:
    """(C, 6) signature of a bias of the ``side`` F/T sensor (sensor axes, [N], [N m]) at this state, into out."""
    R = rows.data.oMf[rows.soles[side]].rotation
    lever = R @ np.array([0.0, 0.0, profile_of(rows.model).sole.below_foot_m])   # sensor (ankle) - sole, world axes
    # column c: the ground wrench a unit bias beta = e_c of the sensor's reading takes off the sole (world axes)
    d_wrench = np.zeros((6, 6))
    d_wrench[:3, :3] = -R
    d_wrench[3:, :3] = -pin.skew(lever) @ R
    d_wrench[3:, 3:] = -R
    out[:] = _to_channels(J.T @ d_wrench, perm, T)


def _offset_columns(rows: _Rows, smp: _Sample, r: np.ndarray, idx_v: np.ndarray, perm: np.ndarray, T: np.ndarray,
                    out: np.ndarray) -> None:
    """(C, n) encoder-offset signature (d e / d q_j [per rad], finite differences) of the sample, into out."""
    de = np.empty((len(r), len(idx_v)))
    for j in range(len(idx_v)):
        qj = smp.q.copy()
        qj[idx_v[j] + 1] += FD_STEP_RAD
        de[:, j] = rows.residual(qj, smp.v, smp.a, smp.tau_full, smp.wrench)[0] - r
    out[:] = _to_channels(de, perm, T) / FD_STEP_RAD
    rows.residual(smp.q, smp.v, smp.a, smp.tau_full, smp.wrench)     # leave the data at the measured state


def _valid_rows(model: pin.Model, rec: Recording, idx_v: np.ndarray, seated: np.ndarray | None) -> np.ndarray:
    """(N, C) rows the measured contacts determine: not a joint at its limit, not base or hips while seated."""
    valid = np.ones((len(rec), 6 + len(rec.joint_names)), bool)
    at_limit = joints_at_limit(model, rec, idx_v)
    valid[:, 6:] &= ~at_limit              # a hard stop's torque is not in the measured actuator torque
    if seated is not None and seated.any():
        hips = [6 + rec.joint_names.index(j) for j in profile_of(model).leg_joints(SEATED_HIP_ROLES)
                if j in rec.joint_names]
        valid[np.ix_(seated, list(range(6)) + hips)] = False
    return valid


def coulomb_signature(qd: np.ndarray, v0: float = COULOMB_V0_RADPS) -> np.ndarray:
    """Coulomb friction's shape along a joint velocity series: sat(q' / v0). While a joint is held still its
    friction can take any value up to the sliding one (stiction), which no signature of the velocity can follow:
    tried, the sign of the last motion fits worse (measured on the hidden-effect cases)."""
    return np.clip(qd / v0, -1.0, 1.0)


def is_physics_channel(channel: str) -> bool:
    """Whether a residual channel holds the robot's physics (not a controller channel, :data:`CONTROLLER_PREFIX`)."""
    return not channel.startswith(CONTROLLER_PREFIX)


def fit_coulomb_widths(recordings: list[Recording], evaluations: list[Evaluation]) -> None:
    """Each joint's Coulomb transition speed (``Evaluation.coulomb_v0``): the speed of
    ``COULOMB_V0_GRID_RADPS`` whose sat(q' / v0) fits the joint's own torque residual best, over all recordings.
    The sliding friction's sign changes over a speed that depends on the joint (MuJoCo's dry friction, as a real
    gearbox's): measured on the hidden-effect plants, 0.002 rad/s on a slow shoulder (RSS 28 against 2038 at 0.03
    rad/s, where a spring then won) and 0.01-0.02 rad/s on a loaded ankle."""
    n = evaluations[0].n_joints
    v0 = np.full(n, COULOMB_V0_RADPS)
    for j in range(n):
        pairs = [(rec.qd[ev.valid[:, 6 + j], j], ev.e[ev.valid[:, 6 + j], 6 + j])
                 for rec, ev in zip(recordings, evaluations) if not rec.static]
        if not pairs:
            continue
        qd, y = (np.concatenate(x) for x in zip(*pairs))
        rss = [_rss_one(coulomb_signature(qd, v), y) for v in COULOMB_V0_GRID_RADPS]
        v0[j] = COULOMB_V0_GRID_RADPS[int(np.argmin(rss))]
    for ev in evaluations:
        ev.coulomb_v0 = v0


def backlash_signature(drive: np.ndarray, kp: float, b0_rad: float) -> np.ndarray:
    """d r / d b of a gear's play on the controller channel: -kp sat(drive / (kp b0)) [N m/rad] (gap.control)."""
    return -kp * np.clip(drive / (kp * b0_rad), -1.0, 1.0)


def fit_backlash_widths(recordings: list[Recording], evaluations: list[Evaluation]) -> None:
    """Each joint's play half-width for its signature (``Evaluation.backlash_b0``): the width of
    ``BACKLASH_GRID_RAD`` whose signature fits the joint's own controller residual best, over all recordings (the
    dead zone's edges sit at +-kp b: a joint whose drive never changes sign sees a constant, whatever b0)."""
    n = evaluations[0].n_joints
    b0 = np.full(n, BACKLASH_GRID_RAD[0])
    with_law = [ev for ev in evaluations if ev.ctrl_drive is not None and ev.valid[:, 6 + n:].any()]
    for j in range(n if with_law else 0):
        c, kp = 6 + n + j, float(with_law[0].ctrl_kp[j])
        drive, y = (np.concatenate(x) for x in zip(*[(ev.ctrl_drive[ev.valid[:, c], j], ev.e[ev.valid[:, c], c])
                                                      for ev in with_law]))
        rss = [_rss_one(backlash_signature(drive, kp, b), y) for b in BACKLASH_GRID_RAD]
        b0[j] = BACKLASH_GRID_RAD[int(np.argmin(rss))]
    for ev in evaluations:
        ev.backlash_b0 = b0


def _rss_one(x: np.ndarray, y: np.ndarray) -> float:
    """Residual sum of squares of y after its least-squares fit by the one column x."""
    xx = float(x @ x)
    return float(y @ y) - (float(x @ y) ** 2 / xx if xx > 0 else 0.0)


def joints_at_limit(model: pin.Model, rec: Recording, idx_v: np.ndarray, margin_rad: float = LIMIT_MARGIN_RAD
                    ) -> np.ndarray:
    """(N, n) samples in which a joint is within ``margin_rad`` of its position limit (the model's URDF limits)."""
    lo = model.lowerPositionLimit[idx_v + 1]
    hi = model.upperPositionLimit[idx_v + 1]
    return (rec.q <= lo[None, :] + margin_rad) | (rec.q >= hi[None, :] - margin_rad)




def joint_columns(rec: Recording, ev: Evaluation, kind: str, j: int) -> np.ndarray:
    """(N, C, p) signature of a single-joint effect ``kind`` on joint ``j`` (see the module docstring); with
    ``actuator_delay`` (all joints, ``j`` ignored) the delay's signature on the controller channels."""
    N, C = ev.e.shape
    col = np.zeros((N, C, EFFECT_KINDS[kind].parameters))
    row = 6 + j
    ctrl = 6 + ev.n_joints + j if ev.ctrl_law is not None else None
    if kind == "actuator_delay":
        if ev.ctrl_delay is not None:
            col[:, 6 + ev.n_joints:, 0] = ev.ctrl_delay
        return col
    if kind == "viscous_friction":
        col[:, row, 0] = rec.qd[:, j]
    elif kind == "coulomb_friction":
        col[:, row, 0] = coulomb_signature(rec.qd[:, j], COULOMB_V0_RADPS if ev.coulomb_v0 is None
                                           else float(ev.coulomb_v0[j]))
    elif kind == "torque_bias":      # the sensor's bias shows against the dynamics and against the control law
        col[:, row, 0] = 1.0
        if ctrl is not None:
            col[:, ctrl, 0] = 1.0
    elif kind == "torque_gain":
        col[:, row, 0] = ev.tau_model[:, j]
        if ctrl is not None:
            col[:, ctrl, 0] = ev.ctrl_law[:, j]
    elif kind == "joint_offset":
        col[:, :, 0] = ev.offset_cols[:, :, j]
    elif kind == "joint_spring":
        col[:, row, 0] = rec.q[:, j]
        col[:, row, 1] = 1.0
    elif kind == "rotor_inertia":
        col[:, row, 0] = rec.qdd[:, j]
    elif kind == "backlash":
        if ctrl is not None:
            b0 = BACKLASH_GRID_RAD[0] if ev.backlash_b0 is None else float(ev.backlash_b0[j])
            col[:, ctrl, 0] = backlash_signature(ev.ctrl_drive[:, j], float(ev.ctrl_kp[j]), b0)
    else:
        raise InputError(f"unknown joint effect {kind!r}")
    return col
