"""Analysis of a recorded stand-up run (the ``standup`` graph's bag): did the robot stand, how well its COM followed the
plan, and the paper's figures.

* :func:`analyse` reads ``/robot/joint_states`` + ``/robot/base_pose`` (what a robot measures), ``/robot/planned_com``,
  ``/robot/cop``, ``/human/com`` and the chair plate, and computes the robot's measured COM with the identified
  parameters and with CAD's (forward kinematics of the measured state), seat-off, and the verdict.
* :func:`figure_6`: forward COM of the human, planned robot COM, measured robot COM and robot COP against time,
  seat-off marked (Mistry et al. 2010, Fig. 6).
* :func:`figure_7`: sagittal COM paths, natural against elderly-like, measured robot COM with identified against CAD
  parameters (Fig. 7).
* :func:`render_strip`: frames of the robot standing up, rendered offscreen by MuJoCo (``MUJOCO_GL=egl`` or
  ``osmesa``; Fig. 4/5), the human's skeleton below at the same share of its rise.

Stood up: not fallen (the pelvis never below the plant's fall height), the pelvis 20 cm or more above where it sat,
and above ``stand_fraction`` of the highest it reached for ``hold_s`` seconds on end (the last ones, unless it sat
back down). Sat back down (a demonstration that ends seated): stood up, then the pelvis back within 5 cm of where it
sat. Units SI.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import mujoco
import numpy as np
import pinocchio as pin

from ..io.topics import (CHAIR_PLATE_TOPIC, HUMAN_COM_TOPIC, HUMAN_JOINTS_TOPIC, HUMAN_PELVIS_POSE_TOPIC,
                         ROBOT_BASE_POSE_TOPIC, ROBOT_COM_FEEDBACK_TOPIC, ROBOT_COP_TOPIC, ROBOT_JOINT_STATES_TOPIC,
                         ROBOT_PLANNED_COM_TOPIC, ROBOT_PLANNED_ZMP_TOPIC)
from ..io.bag import BagReader
from ..io.messages import stamp_ns
from ..robot.identify import read_link_parameters
from ..robot.model import DEFAULT_ROBOT, PlantConfig, controller_model, sole_corners_world
from ..human.skeleton import SAGITTAL_FLEXION
from ..robot.plant import Plant
from ..robot.postures import standing_pelvis_height_m
from ..vectors import pitch_deg
from ..robot.profile import SIDES
from .compare import cycle_rows, flexion_deg, posture_rms_deg

STOOD_RISE_M = 0.2
"""A robot that stood up: its pelvis at least this far above where it sat [m]."""
SAT_DOWN_TOLERANCE_M = 0.05
"""A robot that sat back down: its pelvis within this of the seated height [m]."""
KNEE_TOLERANCE_DEG = 15.0
"""A robot that stood up ends with its knees within this of the human's final knee flexion: a squat is not a stand."""


@dataclass
class RunAnalysis:
    """One stand-up run analysed: robot states and COMs, the plan, COP, the human's COM, seat-offs and the verdict."""

    name: str
    t: np.ndarray                   # robot state times [s] from the run's start
    q: np.ndarray                   # (N, nq) measured configurations (Pinocchio)
    com: np.ndarray                 # (N, 3) measured COM, identified parameters
    com_cad: np.ndarray             # (N, 3) measured COM, CAD parameters
    plan_t: np.ndarray
    plan_com: np.ndarray
    cop_t: np.ndarray
    cop: np.ndarray
    human_t: np.ndarray
    human_com: np.ndarray
    human_seat_off_s: float | None
    seat_off_s: float | None
    summary: dict
    plan_zmp_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    plan_zmp: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))    # the plan's ZMP (the commands' own) [m]
    support_x: tuple[float, float] = (np.nan, np.nan)   # the feet's heel and toe lines along x [m]
    robot: str = DEFAULT_ROBOT                          # the robot's profile


@dataclass
class _RunMessages:
    """The messages of a stand-up bag that the analysis reads, as (receive time [ns], message) pairs."""

    joint_states: list
    base_pose: list
    planned_com: list
    planned_zmp: list
    cop: list
    human_com: list
    chair: list
    com_feedback_shift_m: list[float]     # horizontal size of each COM feedback correction
    human_joints: list = field(default_factory=list)   # the fitted skeleton's joint states (the last few)
    human_pelvis: list = field(default_factory=list)   # the fitted skeleton's pelvis poses


def _stamps(msgs) -> np.ndarray:
    """Header stamps [s]: the robot side is stamped by the driver and the retargeter on one clock, the human side
    in the demonstration's own time (the recorder's receive times would mis-pair states that arrive in bursts)."""
    return np.array([stamp_ns(m.header) for _, m in msgs]) * 1e-9


def _xyz(msgs, field: str) -> np.ndarray:
    """(N, 3) [m] of the point or vector ``field`` of each message."""
    return np.array([[getattr(m, field).x, getattr(m, field).y, getattr(m, field).z] for _, m in msgs])


def analyse(run: Path, name: str, params_yaml: Path | None, plant_yaml: Path | None = None,
            hold_s: float = 2.0, stand_fraction: float = 0.9, every: int = 5, robot: str | None = None
            ) -> RunAnalysis:
    """Analyse the stand-up bag ``run`` of ``robot`` (a profile; None: the plant's) (see the module docstring);
    ``every``: use every n-th robot state."""
    cfg = PlantConfig.load(plant_yaml, robot)
    cad = controller_model(cfg)
    ident = controller_model(cfg, read_link_parameters(params_yaml) if params_yaml else None)
    msgs = _read_run(run, every)
    t_js = _stamps(msgs.joint_states)
    q = _measured_configurations(msgs, t_js, cad)
    dc, di = cad.createData(), ident.createData()
    com_cad = np.array([pin.centerOfMass(cad, dc, qk) for qk in q])
    com = np.array([pin.centerOfMass(ident, di, qk) for qk in q])
    t0 = t_js[0]
    plan_t = _stamps(msgs.planned_com) - t0
    plan_com = _xyz(msgs.planned_com, "position")
    human_t = _stamps(msgs.human_com) if msgs.human_com else np.zeros(0)
    human_com = _xyz(msgs.human_com, "position").reshape(-1, 3)
    human_seat_off = _human_seat_off(msgs.chair)
    if len(human_t):
        human_t = human_t - human_t[0]
    t = t_js - t0
    z = q[:, 2]
    rise = np.flatnonzero(z > z[0] + 0.02)
    seat_off = float(t[rise[0]]) if len(rise) else None
    fallen, stood, sat_down = _stood_up(cfg, t, z, hold_s, stand_fraction)
    posture = _end_posture(cfg, cad, q, msgs.human_joints, sat_down)
    posture["posture_rms_deg"] = _posture_rms(cfg, msgs, t_js, com)
    stood = stood and posture.get("standing_knees_match", True)
    shift = msgs.com_feedback_shift_m
    summary = {"stood_up": bool(stood), "sat_down": sat_down, "fallen": fallen, "pelvis_start_m": float(z[0]),
               "pelvis_final_m": float(z[-1]), **posture,
               "robot_seat_off_s": seat_off, "human_seat_off_s": human_seat_off,
               "com_tracking_rms_m": _tracking_rms(t, com, plan_t, plan_com),
               "planned_final_com_z_m": float(plan_com[-1, 2]) if len(plan_com) else None,
               "duration_s": float(t[-1]),
               "com_feedback_max_shift_m": float(max(shift)) if shift else None,
               "cad_vs_identified_com_rms_m": float(np.sqrt(np.mean(np.sum((com - com_cad)[:, [0, 2]] ** 2, axis=1))))}
    if msgs.human_pelvis:       # a row per sit-stand-sit cycle of the human, the robot's beside it
        summary["cycles"] = cycle_rows(_stamps(msgs.human_pelvis),
                                       np.array([m.pose.position.z for _, m in msgs.human_pelvis]), t, z)
    zmp_t = _stamps(msgs.planned_zmp) - t0 if msgs.planned_zmp else np.zeros(0)
    zmp = _xyz(msgs.planned_zmp, "point").reshape(-1, 3)
    return RunAnalysis(name, t, q, com, com_cad, plan_t, plan_com, _stamps(msgs.cop) - t0, _xyz(msgs.cop, "point"),
                       human_t, human_com, human_seat_off, seat_off, summary, zmp_t, zmp, _support_x(ident, q[0]),
                       cfg.profile.name)


def _support_x(model: pin.Model, q: np.ndarray) -> tuple[float, float]:
    """The feet's heel and toe lines along x [m] (the support polygon's extent) at configuration ``q``."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    x = sole_corners_world(model, data)[:, 0]
    return float(x.min()), float(x.max())


def _end_posture(cfg: PlantConfig, model: pin.Model, q: np.ndarray, human_joints: list, sat_down: bool | None
                 ) -> dict:
    """The robot's final knee flexion [deg], pelvis height over its straight-legged stance's and pelvis pitch [deg,
    forward positive: a robot standing with its pelvis tipped back shows here], beside the human's last knee flexion
    (its skeleton's, when the run has ``/human/joint_states``), and whether the knees match within
    ``KNEE_TOLERANCE_DEG``. A run that sat back down is judged standing: the robot where its pelvis was highest, the
    human at its most extended knee."""
    profile = cfg.profile
    knees = [model.joints[model.getJointId(profile.leg(s, "knee"))].idx_q for s in SIDES]
    up = int(np.argmax(q[:, 2])) if sat_down else -1
    out = {"final_knee_flexion_deg_robot": float(np.degrees(np.mean(q[up, knees]))),
           "final_pelvis_height_ratio": float(q[up, 2] / standing_pelvis_height_m(Plant(cfg, with_chair=False))),
           "final_pelvis_pitch_deg": pitch_deg(q[up, 3:7])}
    if human_joints:
        judged = human_joints if sat_down else human_joints[-1:]
        flexion = flexion_deg(list(judged[0][1].name), np.array([m.position for _, m in judged]),
                              {"knee": SAGITTAL_FLEXION["knee"]}).get("knee")
        if flexion is not None:
            human = float(np.min(flexion))
            out["final_knee_flexion_deg_human"] = human
            out["standing_knees_match"] = bool(abs(out["final_knee_flexion_deg_robot"] - human) <= KNEE_TOLERANCE_DEG)
    return out


def _posture_rms(cfg: PlantConfig, msgs: _RunMessages, t_js: np.ndarray, com: np.ndarray) -> dict | None:
    """:func:`posture_rms_deg` of a stand-up run: the human skeleton's flexions (``/human/joint_states``) against the
    robot's (its sensed joints); None without the human's joints or COM."""
    if not msgs.human_joints or not msgs.human_com:
        return None
    js = [m for _, m in msgs.human_joints]
    names = list(js[0].name)
    t_h = _stamps(msgs.human_joints)
    z_h = np.interp(t_h, _stamps(msgs.human_com), _xyz(msgs.human_com, "position")[:, 2])
    human = flexion_deg(names, np.array([m.position for m in js]), SAGITTAL_FLEXION)
    robot_names = list(msgs.joint_states[0][1].name)
    robot = flexion_deg(robot_names, np.array([m.position for _, m in msgs.joint_states]),
                        cfg.profile.sagittal_flexion())
    return posture_rms_deg((t_h, z_h, human), (t_js, com[:, 2], robot))


def _read_run(run: Path, every: int) -> _RunMessages:
    """Read the run's topics (every ``every``-th joint state); ValueError if it is not a stand-up run."""
    with BagReader(run) as bag:
        topics = bag.topics()
        for needed in (ROBOT_JOINT_STATES_TOPIC, ROBOT_BASE_POSE_TOPIC, ROBOT_PLANNED_COM_TOPIC):
            if needed not in topics:
                raise ValueError(f"{run}: no {needed} topic: not a stand-up run")
        return _RunMessages(
            bag.read(ROBOT_JOINT_STATES_TOPIC)[::every], bag.read(ROBOT_BASE_POSE_TOPIC),
            bag.read(ROBOT_PLANNED_COM_TOPIC),
            bag.read(ROBOT_PLANNED_ZMP_TOPIC) if ROBOT_PLANNED_ZMP_TOPIC in topics else [],
            bag.read(ROBOT_COP_TOPIC),
            bag.read(HUMAN_COM_TOPIC) if HUMAN_COM_TOPIC in topics else [],
            bag.read(CHAIR_PLATE_TOPIC) if CHAIR_PLATE_TOPIC in topics else [],
            [np.hypot(m.vector.x, m.vector.y) for _, m in bag.read(ROBOT_COM_FEEDBACK_TOPIC)]
            if ROBOT_COM_FEEDBACK_TOPIC in topics else [],
            bag.read(HUMAN_JOINTS_TOPIC) if HUMAN_JOINTS_TOPIC in topics else [],
            bag.read(HUMAN_PELVIS_POSE_TOPIC) if HUMAN_PELVIS_POSE_TOPIC in topics else [])


def _measured_configurations(msgs: _RunMessages, t_js: np.ndarray, cad: pin.Model) -> np.ndarray:
    """(N, nq) configurations: each joint state with the base pose received at or just after it."""
    js, base = msgs.joint_states, msgs.base_pose
    t_base = _stamps(base)
    bp = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z, m.pose.orientation.x,
                    m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w] for _, m in base])
    names = list(js[0][1].name)
    order = [names.index(n) for n in cad.names[2:]]
    q = np.zeros((len(js), cad.nq))
    for k, (_, m) in enumerate(js):
        i = min(np.searchsorted(t_base, t_js[k]), len(t_base) - 1)
        q[k, :7] = bp[i]
        q[k, 7:] = np.asarray(m.position)[order]
    return q


def _human_seat_off(chair: list) -> float | None:
    """The human's seat-off [s from the chair plate's first sample]: the chair unloaded (< 30 N) after a load > 60 N."""
    if not chair:
        return None
    fz = np.array([m.wrench.force.z for _, m in chair])
    tc = _stamps(chair)
    loaded = np.flatnonzero(fz > 60.0)
    if not len(loaded):
        return None
    off = np.flatnonzero((fz < 30.0) & (np.arange(len(fz)) > loaded[0]))
    return float(tc[off[0]] - tc[0]) if len(off) else None


def _stood_up(cfg: PlantConfig, t: np.ndarray, z: np.ndarray, hold_s: float,
              stand_fraction: float) -> tuple[bool, bool, bool]:
    """(fallen, stood up, sat back down) from the pelvis height z [m] over time t [s] (see the module
    docstring)."""
    fallen = bool(np.any(z < cfg.fall_height_m))
    up = z > stand_fraction * max(z.max(), 1e-9)
    back = z[-1] < z[0] + SAT_DOWN_TOLERANCE_M
    if back:          # the longest stretch standing, anywhere
        starts = np.flatnonzero(np.diff(np.r_[0, up.astype(int)]) == 1)
        ends = np.flatnonzero(np.diff(np.r_[up.astype(int), 0]) == -1)
        held = max((t[e] - t[b] for b, e in zip(starts, ends)), default=0.0) >= hold_s
    else:
        held = bool(np.all(up[t > t[-1] - hold_s]))
    stood = not fallen and held and z.max() > z[0] + STOOD_RISE_M
    return fallen, stood, bool(stood and back)


def _tracking_rms(t: np.ndarray, com: np.ndarray, plan_t: np.ndarray, plan_com: np.ndarray) -> float:
    """RMS horizontal distance [m] of the measured from the planned COM, over the plan within the run; NaN: none."""
    if len(plan_t) <= 1:
        return np.nan
    inside = (plan_t >= t[0]) & (plan_t <= t[-1])
    meas = np.stack([np.interp(plan_t[inside], t, com[:, i]) for i in range(3)], axis=1)
    return float(np.sqrt(np.mean(np.sum((meas[:, :2] - plan_com[inside, :2]) ** 2, axis=1))))


def figure_6(a: RunAnalysis, png: Path) -> None:
    """Forward COM of the human, planned and measured robot COM and robot COP against time, seat-off marked."""
    matplotlib.use("Agg")
    fig, ax = plt.subplots(2, 1, figsize=(9, 7))
    if len(a.human_t):
        ax[0].plot(a.human_t, a.human_com[:, 0], label="human COM (estimated)")
    if a.human_seat_off_s is not None:
        ax[0].axvline(a.human_seat_off_s, color="k", ls=":", lw=1, label="human seat-off (chair plate)")
    ax[0].set_title(f"{a.name}: the human's rise (its own time)")
    ax[0].set_ylabel("forward [m]")
    ax[0].set_xlabel("time [s]")
    ax[0].legend(fontsize=8)
    ax[1].plot(a.plan_t, a.plan_com[:, 0], label="planned robot COM")
    ax[1].plot(a.t, a.com[:, 0], label="measured robot COM (identified parameters)")
    ok = np.isfinite(a.cop[:, 0])
    ax[1].plot(a.cop_t[ok], a.cop[ok, 0], lw=0.6, alpha=0.6, label="robot COP (ankle F/T)")
    if len(a.plan_zmp_t):
        ax[1].plot(a.plan_zmp_t, a.plan_zmp[:, 0], lw=0.6, alpha=0.7, label="planned ZMP")
    for x, edge in zip(a.support_x, ("heel", "toe")):
        if np.isfinite(x):
            ax[1].axhline(x, color="grey", lw=0.8, ls="--", label=f"support polygon: {edge}")
    if a.seat_off_s is not None:
        ax[1].axvline(a.seat_off_s, color="k", ls=":", lw=1, label="robot seat-off (pelvis +2 cm)")
    ax[1].set_ylim(-0.3, 0.2)
    s = a.summary
    verdict = ("stood up" if s["stood_up"] else "did not stand up") + \
        (" and sat back down" if s.get("sat_down") else "")
    ax[1].set_title(f"the robot (retimed): {verdict}, COM tracking RMS {s['com_tracking_rms_m'] * 100:.1f} cm")
    ax[1].set_ylabel("forward [m]")
    ax[1].set_xlabel("time since the robot's first state [s]")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def figure_7(runs: list[RunAnalysis], png: Path) -> None:
    """Sagittal COM paths: natural against elderly-like, the robot's measured COM with identified and CAD
    parameters, and the human's."""
    matplotlib.use("Agg")
    fig, ax = plt.subplots(1, 2, figsize=(11, 5))
    for a, color in zip(runs, ("tab:blue", "tab:red", "tab:green")):
        ax[0].plot(a.com[:, 0], a.com[:, 2], color=color, lw=2, label=f"{a.name}: identified parameters")
        ax[0].plot(a.com_cad[:, 0], a.com_cad[:, 2], color=color, lw=1, ls="--", label=f"{a.name}: CAD parameters")
        if len(a.human_t):
            ax[1].plot(a.human_com[:, 0], a.human_com[:, 2], color=color, lw=2, label=f"{a.name}: human")
    ax[0].set_title("robot COM from its measured states")
    ax[1].set_title("human COM (estimated)")
    for x in ax:
        x.set_xlabel("forward x [m]")
        x.set_ylabel("height z [m]")
        x.grid(alpha=0.3)
        x.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


SEATED_PELVIS_FRAMED_M = 0.627
"""The frames' camera is framed for a robot whose seated pelvis is this high (TALOS) and scaled for others."""


def strip_indices(n: int, frames: int) -> np.ndarray:
    """The ``frames`` evenly spaced states of ``n`` that :func:`render_strip` shows."""
    return np.linspace(0, n - 1, frames).astype(int)


def render_strip(a: RunAnalysis, plant_yaml: Path | None, png: Path, frames: int = 6,
                 human_bones: np.ndarray | None = None, human_chair: tuple | None = None) -> str | None:
    """A strip of offscreen-rendered frames of the run (the states of :func:`strip_indices`); returns None, or why
    nothing was rendered. ``human_bones`` (frames, B, 2, 3) [m]: the human skeleton's bones (from, to) at the
    matched instants (:func:`matched_times`), drawn as a side view under each robot frame, on the human's chair
    ``human_chair`` (centre, half size [m]). MuJoCo picks its GL backend when it is imported, so each backend
    (``MUJOCO_GL`` if set, else egl then osmesa) is tried in a process of its own."""
    with tempfile.TemporaryDirectory() as tmp:
        states = Path(tmp) / "states.npz"
        extra = {} if human_bones is None else {"bones": human_bones}
        if human_chair is not None:
            extra["chair"] = np.array(human_chair, float)
        np.savez(states, q=a.q, t=a.t, name=a.name, robot=a.robot, **extra)
        reason = "no GL backend"
        for gl in ([os.environ["MUJOCO_GL"]] if os.environ.get("MUJOCO_GL") else ["egl", "osmesa"]):
            code = ("import sys; from pathlib import Path; from sit2stand.retarget.report import _render_file; "
                    "_render_file(*sys.argv[1:])")
            proc = subprocess.run([sys.executable, "-c", code, str(states), str(plant_yaml or ""), str(png),
                                   str(frames)], env=dict(os.environ, MUJOCO_GL=gl), capture_output=True, text=True,
                                  timeout=300)
            if proc.returncode == 0:
                return None
            reason = f"MUJOCO_GL={gl}: {(proc.stderr.strip().splitlines() or ['failed'])[-1]}"
    return reason


def _render_file(states: str, plant_yaml: str, png: str, frames: str) -> None:
    """:func:`_render` of the states saved by :func:`render_strip` (command-line arguments as strings)."""
    d = np.load(states)
    _render(d["q"], d["t"], str(d["name"]), Path(plant_yaml) if plant_yaml else None, Path(png), int(frames),
            str(d["robot"]), d["bones"] if "bones" in d else None, d["chair"] if "chair" in d else None)


def _render(qs: np.ndarray, ts: np.ndarray, name: str, plant_yaml: Path | None, png: Path, frames: int,
            robot: str = DEFAULT_ROBOT, bones: np.ndarray | None = None, chair: np.ndarray | None = None) -> None:
    """Render ``frames`` evenly spaced configurations of the run in MuJoCo, side by side, into ``png``; with
    ``bones``, the human's skeleton at the matched instants in a row below."""
    matplotlib.use("Agg")
    plant = Plant(PlantConfig.load(plant_yaml, robot))
    model, data = plant.model, plant.data
    renderer = mujoco.Renderer(model, 360, 270)
    cam = mujoco.MjvCamera()
    size = plant.q_seated[2] / SEATED_PELVIS_FRAMED_M     # the robot's size: TALOS's seated pelvis is 0.627 m
    cam.lookat[:] = [0.0, 0.0, 0.8 * size]        # the whole robot, seated and standing straight
    cam.distance, cam.azimuth, cam.elevation = 3.7 * size, 90.0, -10.0    # from the robot's left side
    idx = strip_indices(len(qs), frames)
    images = []
    for k in idx:
        q = qs[k]
        data.qpos[:3] = q[:3]
        data.qpos[3:7] = [q[6], q[3], q[4], q[5]]
        data.qpos[plant.qadr] = q[7:]
        mujoco.mj_forward(model, data)
        renderer.update_scene(data, cam)
        images.append(renderer.render().copy())
    renderer.close()
    rows = 1 if bones is None else 2
    fig, ax = plt.subplots(rows, frames, figsize=(2.2 * frames, 3 * rows), squeeze=False)
    for x, img, k in zip(ax[0], images, idx):
        x.imshow(img)
        x.set_title(f"{ts[k]:.1f} s", fontsize=9)
        x.axis("off")
    if bones is not None:
        _skeleton_row(ax[1], bones, chair)
    title = f"{name}: {plant.cfg.profile.title or robot} standing up (simulated, side view)"
    fig.suptitle(title + ("; below, the human at the same share of its rise" if bones is not None else ""),
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(png, dpi=100)
    plt.close(fig)


def _skeleton_row(axes, bones: np.ndarray, chair: np.ndarray | None) -> None:
    """The human skeleton seen from its left (x forward, z up) in each of ``axes``, on one scale, with its chair."""
    lo = np.nanmin(bones[..., 0]) - 0.3
    hi = np.nanmax(bones[..., 0]) + 0.3
    top = max(np.nanmax(bones[..., 2]) + 0.1, 1.0)
    for x, frame in zip(axes, bones):
        if chair is not None:
            (cx, _, cz), (hx, _, hz) = chair
            x.add_patch(plt.Rectangle((cx - hx, cz - hz), 2 * hx, 2 * hz, color="#8c5a33", alpha=0.8))
        x.plot([lo, hi], [0, 0], color="0.5", lw=1)
        for start, end in frame:
            x.plot([start[0], end[0]], [start[2], end[2]], color="#1f77b4", lw=2, solid_capstyle="round")
        x.set_xlim(lo, hi)
        x.set_ylim(-0.05, top)
        x.set_aspect("equal")
        x.axis("off")
