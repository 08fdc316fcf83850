"""A robot's measured recording, read from a bag: what the model-gap workflow is given (and nothing else).

Two kinds of bag carry the same topics (``io.messages.ROBOT_STATE_TOPICS``):

* a run (the driver's stream, or ``sit2stand excite``): joint states with measured torques as effort, the ground
  reaction under each foot (world axes, torque about the sole), the COP, the base pose, and the commands the robot
  was sent (``/robot/joint_command``, trajectory_msgs/JointTrajectory) when the bag has them;
* static postures (``sit2stand collect-postures``): one averaged sample per held posture.

Samples of one state are joined by their header stamp. A run is smoothed and differentiated with the same
Savitzky-Golay filter for the motion (``dynamics.smooth_motion``) and for the measured torques and wrenches, so that
both sides of the dynamics equation have one bandwidth; a posture bag is static (zero velocity and acceleration).

Also the excitation run of the simulated robot (:func:`excite`) that the workflow is tested on.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..dynamics import savgol_series, smooth_motion
from ..io import messages as M
from ..io.bag import BagError, BagReader, BagWriter
from ..io.messages import stamp_ns
from ..io.topics import (
    ROBOT_BASE_POSE_TOPIC,
    ROBOT_COP_TOPIC,
    ROBOT_FT_LEFT_TOPIC,
    ROBOT_FT_RIGHT_TOPIC,
    ROBOT_JOINT_COMMAND_TOPIC,
    ROBOT_JOINT_STATES_TOPIC,
    ft_topic,
)
from ..robot.model import SIDES, PlantConfig
from ..robot.plant import Plant
from ..robot.postures import home_com_bias, plan_postures
from .effects import Effect, alter_model

STATIC_PERIOD_S = 0.2     # samples further apart than this are held postures, not a run


SMOOTHING_WINDOW_S = 0.15
"""Savitzky-Golay window [s] (order 3) of a run's motion, torques and wrenches, and of what is differentiated from
them (the control law's feed-forward, :func:`sit2stand.gap.control.control_law`): one bandwidth for all."""


class RecordingError(BagError):
    """A bag that does not hold a usable robot recording; the message names the bag, topic or field."""


@dataclass
class Commands:
    """The joint references the robot was sent (plant joint order)."""

    t_s: np.ndarray           # (K,) [s], on the recording's time base
    q: np.ndarray             # (K, n) [rad]
    qd: np.ndarray            # (K, n) [rad/s]
    qdd: np.ndarray           # (K, n) [rad/s^2]


@dataclass
class Recording:
    """A robot recording (plant joint order; base pose in MuJoCo order x y z qw qx qy qz)."""

    source: str
    joint_names: list[str]
    t_s: np.ndarray                     # (N,) [s] from the first sample
    q: np.ndarray                       # (N, n) [rad]
    qd: np.ndarray                      # (N, n) [rad/s]
    qdd: np.ndarray                     # (N, n) [rad/s^2]
    tau: np.ndarray                     # (N, n) measured joint torques [N m]
    wrench: dict[str, np.ndarray]       # side -> (N, 6) ground reaction on the foot, world axes, about the sole
    cop: np.ndarray                     # (N, 3) [m], NaN when unloaded
    base_pose: np.ndarray               # (N, 7)
    base_v: np.ndarray                  # (N, 6) Pinocchio free-flyer velocity (body frame)
    base_a: np.ndarray                  # (N, 6) and acceleration
    static: bool                        # held postures (velocities and accelerations are zero)
    commands: Commands | None = None
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.t_s)

    @property
    def feet_force_z_n(self) -> np.ndarray:
        """(N,) total vertical ground reaction on the feet [N]."""
        return sum(self.wrench[s][:, 2] for s in SIDES)

    def subset(self, keep: np.ndarray) -> Recording:
        """The samples where ``keep`` is true (commands unchanged)."""
        return Recording(self.source, self.joint_names, self.t_s[keep], self.q[keep], self.qd[keep], self.qdd[keep],
                         self.tau[keep], {s: w[keep] for s, w in self.wrench.items()}, self.cop[keep],
                         self.base_pose[keep], self.base_v[keep], self.base_a[keep], self.static, self.commands,
                         list(self.notes))


def _by_stamp(msgs: list[tuple[int, object]]) -> dict[int, object]:
    """Messages by their header stamp [ns]."""
    return {stamp_ns(m.header): m for _, m in msgs}


def _nearest(target: np.ndarray, stamps: np.ndarray, tol: int) -> np.ndarray:
    """Index into sorted ``stamps`` of the nearest to each ``target`` (-1 where none is within ``tol`` ns)."""
    k = np.clip(np.searchsorted(stamps, target), 1, max(len(stamps) - 1, 1))
    lo, hi = stamps[k - 1], stamps[np.minimum(k, len(stamps) - 1)]
    pick = np.where(np.abs(target - lo) <= np.abs(hi - target), k - 1, np.minimum(k, len(stamps) - 1))
    return np.where(np.abs(stamps[pick] - target) <= tol, pick, -1)


def _join(js: dict, ft: dict, base: dict, cop: dict):
    """Samples of one state: the same stamp on every topic (the driver stamps a sample once), else the nearest stamp
    within half a joint-state period (bags from drivers that stamped each message on its own)."""
    exact = sorted(set(js) & set(ft["left"]) & set(ft["right"]) & set(base))
    if len(exact) >= 0.9 * len(js):
        return exact, ft, base, cop
    t = np.array(sorted(js), np.int64)
    tol = int(0.5 * np.median(np.diff(t))) if len(t) > 1 else 0
    keep = np.ones(len(t), bool)
    remapped = []
    for series in (ft["left"], ft["right"], base, cop):
        if not series:
            remapped.append({})
            continue
        st = np.array(sorted(series), np.int64)
        idx = _nearest(t, st, tol)
        if series is not cop:
            keep &= idx >= 0
        remapped.append({int(t[i]): series[int(st[j])] for i, j in enumerate(idx) if j >= 0})
    stamps = [int(x) for x in t[keep]]
    return stamps, {"left": remapped[0], "right": remapped[1]}, remapped[2], remapped[3]


@dataclass
class _Samples:
    """The joined samples of a recording, before smoothing (plant joint order; SI units)."""

    q: np.ndarray                       # (N, n) [rad]
    qd: np.ndarray                      # (N, n) [rad/s], zero where not recorded
    tau: np.ndarray                     # (N, n) [N m]
    wrench: dict[str, np.ndarray]       # side -> (N, 6) [N, N m]
    base_pose: np.ndarray               # (N, 7) x y z qw qx qy qz
    cop: np.ndarray                     # (N, 3) [m], NaN where not recorded


def read_recording(path: str | Path, model, rate_hz: float = 100.0, window_s: float = SMOOTHING_WINDOW_S
                   ) -> Recording:
    """Read a robot bag (see the module docstring) at most ``rate_hz``; ``model`` is the Pinocchio robot model used to
    differentiate the base motion. Raises :class:`RecordingError` naming the bag and topic on missing or bad data."""
    path = Path(path)
    js, ft, base, cop, cmd_msgs = _read_topics(path)
    stamps, ft, base, cop = _join(js, ft, base, cop)
    if len(stamps) < 5:
        raise RecordingError(f"{path}: only {len(stamps)} samples have joint states, both feet's wrenches and a base "
                             "pose with the same stamp (need 5)")
    names = list(js[stamps[0]].name)
    stamps, t, static = _time_base(stamps, rate_hz)
    s = _sample_arrays(path, names, stamps, js, ft, base, cop)
    ok = _finite_samples(path, s)
    notes = []
    if not ok.all():
        notes.append(f"{int((~ok).sum())} samples with NaN dropped")
    rec = Recording(str(path), names, t[ok], s.q[ok], s.qd[ok], np.zeros_like(s.q[ok]), s.tau[ok],
                    {side: w[ok] for side, w in s.wrench.items()}, s.cop[ok], s.base_pose[ok],
                    np.zeros((ok.sum(), 6)), np.zeros((ok.sum(), 6)), static, notes=notes)
    if not static:
        _smooth(rec, model, window_s)
    if cmd_msgs:
        rec.commands = _commands(cmd_msgs, names, stamps[0], path)
    if len(names) != model.nv - 6:
        raise RecordingError(f"{path}: /robot/joint_states has {len(names)} joints, the model {model.nv - 6}")
    return rec


def _read_topics(path: Path) -> tuple[dict, dict, dict, dict, list]:
    """Joint states, feet wrenches (per side), base poses and COPs by stamp [ns], and the command messages."""
    need = [ROBOT_JOINT_STATES_TOPIC, ROBOT_FT_LEFT_TOPIC, ROBOT_FT_RIGHT_TOPIC, ROBOT_BASE_POSE_TOPIC]
    try:
        reader = BagReader(path)
    except BagError as err:
        raise RecordingError(str(err)) from None
    with reader as bag:
        topics = bag.topics()
        missing = [t for t in need if t not in topics]
        if missing:
            raise RecordingError(f"{path}: not a robot recording: no {', '.join(missing)}")
        js = _by_stamp(bag.read(ROBOT_JOINT_STATES_TOPIC))
        ft = {s: _by_stamp(bag.read(ft_topic(s))) for s in SIDES}
        base = _by_stamp(bag.read(ROBOT_BASE_POSE_TOPIC))
        cop = _by_stamp(bag.read(ROBOT_COP_TOPIC)) if ROBOT_COP_TOPIC in topics else {}
        cmd_msgs = bag.read(ROBOT_JOINT_COMMAND_TOPIC) if ROBOT_JOINT_COMMAND_TOPIC in topics else []
    return js, ft, base, cop, cmd_msgs


def _time_base(stamps: list[int], rate_hz: float) -> tuple[list[int], np.ndarray, bool]:
    """A run's stamps thinned to at most ``rate_hz``, their times [s] from the first, and whether they are postures."""
    t = (np.array(stamps, np.int64) - stamps[0]) * 1e-9
    static = bool(np.median(np.diff(t)) > STATIC_PERIOD_S)
    if not static:     # thin to at most rate_hz
        step = max(1, int(round(1.0 / (rate_hz * float(np.median(np.diff(t)))))))
        stamps = stamps[::step]
        t = t[::step]
    return stamps, t, static


def _sample_arrays(path: Path, names: list[str], stamps: list[int], js: dict, ft: dict, base: dict,
                   cop: dict) -> _Samples:
    """The messages of each stamp as arrays; RecordingError where the efforts are not one per joint."""
    q = np.array([js[s].position for s in stamps], float)
    tau = np.array([js[s].effort for s in stamps], float)
    if tau.shape != q.shape:
        raise RecordingError(f"{path}: /robot/joint_states: effort (measured torque) missing or not one per joint")
    qd = np.array([js[s].velocity if len(js[s].velocity) == len(names) else np.zeros(len(names)) for s in stamps])
    wrench = {side: np.array([[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z, m.wrench.torque.x,
                               m.wrench.torque.y, m.wrench.torque.z] for m in (ft[side][s] for s in stamps)])
              for side in SIDES}
    b = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z, m.pose.orientation.w,
                   m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z]
                  for m in (base[s] for s in stamps)])
    cp = np.array([[cop[s].point.x, cop[s].point.y, cop[s].point.z] if s in cop else [np.nan] * 3 for s in stamps])
    return _Samples(q, qd, tau, wrench, b, cp)


def _finite_samples(path: Path, s: _Samples) -> np.ndarray:
    """(N,) samples finite in every measured quantity; RecordingError naming a quantity with no finite sample."""
    for label, arr in (("/robot/joint_states position", s.q), ("/robot/joint_states effort", s.tau),
                       (ROBOT_BASE_POSE_TOPIC, s.base_pose), *((ft_topic(side), w) for side, w in s.wrench.items())):
        bad = ~np.all(np.isfinite(arr), axis=1)
        if bad.all():
            raise RecordingError(f"{path}: {label}: no finite sample")
    return np.all(np.isfinite(s.q), 1) & np.all(np.isfinite(s.tau), 1) & np.all(np.isfinite(s.base_pose), 1) & \
        np.all(np.isfinite(s.wrench["left"]), 1) & np.all(np.isfinite(s.wrench["right"]), 1)


def smoothing_window(t_s: np.ndarray, window_s: float = SMOOTHING_WINDOW_S) -> int:
    """The Savitzky-Golay window [samples, odd, at least 5] of ``window_s`` on the time base ``t_s``."""
    return max(5, int(round(window_s / float(np.median(np.diff(t_s))))) | 1)


def _smooth(rec: Recording, model, window_s: float) -> None:
    """Savitzky-Golay smoothing and derivatives of the run (in place)."""
    dt = float(np.median(np.diff(rec.t_s)))
    window = smoothing_window(rec.t_s, window_s)
    if len(rec) <= window:
        rec.notes.append(f"run too short to smooth ({len(rec)} samples)")
        return
    idx = _joint_index(model, rec.joint_names)
    qs = np.zeros((len(rec), model.nq))
    qs[:, :3] = rec.base_pose[:, :3]
    qs[:, 3:7] = rec.base_pose[:, [4, 5, 6, 3]]
    qs[:, idx + 1] = rec.q            # joint j's q index is its v index + 1 (one quaternion slot)
    q_s, v, a = smooth_motion(model, qs, dt, window, order=3)
    rec.q = q_s[:, idx + 1]
    rec.qd = v[:, idx]
    rec.qdd = a[:, idx]
    rec.base_v, rec.base_a = v[:, :6], a[:, :6]
    rec.base_pose = np.hstack([q_s[:, :3], q_s[:, [6]], q_s[:, 3:6]])
    rec.tau = savgol_series(rec.tau, window, 3, 0)
    rec.wrench = {s: savgol_series(w, window, 3, 0) for s, w in rec.wrench.items()}


def _joint_index(model, names: list[str]) -> np.ndarray:
    """v index of each named joint in ``model`` (names must all exist)."""
    out = []
    for name in names:
        if not model.existJointName(name):
            raise RecordingError(f"joint {name!r} of the recording is not in the model")
        out.append(model.joints[model.getJointId(name)].idx_v)
    return np.array(out)


def _commands(msgs, names: list[str], t0_ns: int, path: Path) -> Commands | None:
    """The recorded joint commands (held per joint between messages) in ``names`` order; None if there are none."""
    index = {n: i for i, n in enumerate(names)}
    ts, qs, qds, qdds = [], [], [], []
    q = np.full(len(names), np.nan)
    qd, qdd = np.zeros(len(names)), np.zeros(len(names))
    for log_ns, m in msgs:
        if not m.points:
            continue
        p = m.points[0]
        for k, name in enumerate(m.joint_names):
            j = index.get(name)
            if j is None:
                continue
            q[j] = p.positions[k]
            qd[j] = p.velocities[k] if len(p.velocities) > k else 0.0
            qdd[j] = p.accelerations[k] if len(p.accelerations) > k else 0.0
        stamp = stamp_ns(m.header) or log_ns
        ts.append((stamp - t0_ns) * 1e-9)
        qs.append(q.copy())
        qds.append(qd.copy())
        qdds.append(qdd.copy())
    if not ts:
        return None
    return Commands(np.array(ts), np.array(qs), np.array(qds), np.array(qdds))


# --- An excitation run of the simulated robot, recorded as a robot bag: the data the model-gap workflow is tested on.
#
# The robot stands (no chair) and moves smoothly from one statically stable stance to the next (the identification's
# stances: hip, knee, ankle and torso pitch across the stand-up's ranges, both arms at random shoulder and elbow
# angles), with a quintic profile of ``move_s`` and a hold of ``hold_s`` at each stance, under PD + inverse-dynamics
# feed-forward with the controller's (CAD) model. Everything is written as the driver would publish it, at
# ``rate_hz``: ``/robot/joint_states`` (measured torque as effort), ``/robot/ft/*``, ``/robot/cop``,
# ``/robot/base_pose`` and the references sent, ``/robot/joint_command``. The bag's metadata names the plant file's
# ``name`` only: never its ``unmodeled`` section.
#
# Joints that do not move in these runs (hip yaw and roll, ankle roll, torso yaw, head, wrists, grippers, the upper-arm
# rotation) cannot show friction, and masses on links rigidly joined by them cannot be told apart: the workflow names
# such a mass by the group of links.


def quintic(s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk profile on s in [0, 1]: position, first and second derivative (per unit s)."""
    s = np.clip(s, 0.0, 1.0)
    return 10 * s**3 - 15 * s**4 + 6 * s**5, 30 * s**2 - 60 * s**3 + 30 * s**4, 60 * s - 180 * s**2 + 120 * s**3


def excite(cfg: PlantConfig, out: str | Path, seed: int = 0, n_moves: int = 8, move_s: float = 2.5,
           hold_s: float = 0.5, rate_hz: float = 100.0, progress: bool = False,
           alterations: list[Effect] | None = None) -> dict:
    """Run and record an excitation (see the module docstring); returns a summary (duration, fell).
    ``alterations``: effects applied to the compiled plant (``gap.effects.alter_model``: springs, rotor inertia,
    kinematic and contact errors)."""
    plant = Plant(replace(cfg, fall_tilt_rad=np.pi), with_chair=False)
    if alterations:
        alter_model(plant.model, alterations)
        plant.reset()
    bias = home_com_bias(plant)
    stances = plan_postures(plant, n_moves, seed=seed, com_bias_m=bias)
    if len(stances) < n_moves:
        raise RuntimeError(f"only {len(stances)} of {n_moves} stable stances found")
    plant.reset(stances[0])
    plant.command(plant.q_ref, feedforward="inverse_dynamics")
    plant.step(int(round(1.0 / cfg.timestep_s)))          # settle in the first stance
    plant.data.time = 0.0
    dt = cfg.timestep_s
    every = max(1, int(round(1.0 / (rate_hz * dt))))
    refs = [s[plant.qadr] + plant.faults.q_offset for s in stances]
    segment_s = move_s + hold_s
    duration = segment_s * (len(refs) - 1) + hold_s
    steps = int(round(duration / dt))
    t0_ns = 1_000_000_000
    with BagWriter(out, custom_data={"source": "sit2stand excite", "plant": cfg.name, "seed": str(seed),
                                     "joint_names": ",".join(plant.joint_names)}) as bag:
        for topic, msgtype in M.ROBOT_STATE_TOPICS.items():
            bag.add_topic(topic, msgtype)
        bag.add_topic(ROBOT_JOINT_COMMAND_TOPIC, "trajectory_msgs/msg/JointTrajectory")
        for k in range(steps):
            # the joint controller interpolates the reference at every physics step, as a real one does; the
            # bag gets it at rate_hz (a reference held for a whole output period makes the forces jump at each
            # update, and sampling locked to the updates would read a bias)
            t = k * dt
            i = min(int(t // segment_s), len(refs) - 2)
            s, sd, sdd = quintic(np.array((t - i * segment_s) / move_s))
            dq = refs[i + 1] - refs[i]
            q, qd, qdd = refs[i] + s * dq, sd / move_s * dq, sdd / move_s**2 * dq
            plant.command(q, qd, qdd, refresh=False)
            if k % every == 0:
                t_ns = t0_ns + int(round(t * 1e9))
                command = M.joint_trajectory_point(t_ns, plant.joint_names, q, qd, qdd, plant.cfg.profile.root_link)
                bag.write(ROBOT_JOINT_COMMAND_TOPIC, t_ns, command)
                sens = plant.sensors()
                for topic, msg in M.robot_state(t_ns, plant.joint_names, sens.q, sens.qd, sens.tau,
                                                sens.wrench_world, sens.cop_m, sens.base_pose,
                                                plant.cfg.profile.root_link):
                    bag.write(topic, t_ns, msg)
                if progress and k % int(round(2.0 / dt)) == 0:
                    print(f"  excite: {t:.1f}/{duration:.1f} s", file=sys.stderr, flush=True)
            plant.step(1)
            if plant.fallen:
                break
    feet = {s: plant.data.site(f"sole_{s}").xpos.copy() for s in SIDES}
    return {"duration_s": duration, "fell": bool(plant.fallen), "status": plant.status_text,
            "feet_x_m": [float(feet[s][0]) for s in SIDES]}
