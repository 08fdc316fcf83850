"""`sit2stand retarget BAG --out DIR`: a whole demonstration retargeted offline, optionally executed on the plant.

Reads ``/mocap/markers``, the chair plate and the human COM (``/human/com`` from ``--human-com BAG`` or the bag
itself; else the offline estimator is run), streams every frame through the same
:class:`~sit2stand.retarget.stream.Retargeter` and :class:`~sit2stand.retarget.stream.PlanPlayer` the node uses, and
writes into DIR: ``retarget`` (a bag: ``/robot/joint_command``, ``/robot/planned_com``, ``/robot/planned_zmp``),
``marker_map.yaml``, ``summary.json`` and ``retarget.png``. With ``--simulate`` the commands drive the MuJoCo plant
under its on-board controller (whole-body torque control by default, with the same COM parameters; an optimised
plan's torques go with its commands) and the summary says whether it stood up.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..human.com import estimate_com
from ..human.calibration import StreamCalibration
from ..human.marker_sets import choose_marker_set
from ..human.offline import Trial, calibrate_subject, read_trial
from ..human.skeleton import SAGITTAL_FLEXION, Subject
from ..io import messages as M
from ..io.bag import BagReader, BagWriter, refuse_existing_bag
from ..io.messages import stamp_ns
from ..io.topics import (HUMAN_COM_TOPIC, HUMAN_JOINTS_TOPIC, ROBOT_JOINT_COMMAND_TOPIC, ROBOT_PLANNED_COM_TOPIC,
                         ROBOT_PLANNED_ZMP_TOPIC, WORLD_FRAME)
from ..io.typestore import typestore
from ..robot.identify import read_link_parameters
from ..robot.model import SIDES, PlantConfig
from ..robot.plant import DEFAULT_CONTROLLER, Plant
from ..robot.postures import standing_pelvis_height_m
from ..vectors import pitch_deg, xyzw_from_wxyz
from ..robot.profile import profile_of
from ..robot.wbc import WbcGains
from .dynamic import DynamicsFilter
from .figures import plan_figure, timing_figure
from .phases import Phases, find_phases
from .compare import cycle_rows, flexion_deg, posture_rms_deg
from .report import KNEE_TOLERANCE_DEG, SAT_DOWN_TOLERANCE_M, STOOD_RISE_M
from .player import DEFAULT_MARGIN_M, DEFAULT_MAX_TIME_SCALE, SEAT_OFF_DWELL_S, PlanPlayer
from .stabiliser import ComStabiliser, StabiliserConfig, com_feedback_applies, com_lag_m
from .calibration import map_frame
from .robot import robot_model, robot_setup
from .stream import RetargetConfig, Retargeter, retarget_sequence
from .whole_rise import Progress, WholeRiseConfig, optimised_player

PLANS = ("whole", "frames")
DEFAULT_PLAN = "whole"
"""How ``sit2stand retarget`` plans by default: the rise also optimised as a whole
(:mod:`sit2stand.retarget.whole_rise`), and of that plan and the per-frame one the one that plays shorter played. On
every population measured (30 digital humans each: TALOS, G1 and iCub with CAD parameters, TALOS and G1 with
identified ones) it stood as often as the per-frame plan and played at an equal or lower median time scale (iCub 1.002
against 1.05; TALOS identified 1.000 against 1.078, the optimised torques then their own check). A solve costs
2-7x the rise's duration; "frames" is what the live retargeter runs, and skips it."""

HumanPosture = tuple[np.ndarray, np.ndarray, dict]
"""The human over the trial as :func:`~sit2stand.retarget.compare.posture_rms_deg` compares it: times [s], COM
heights [m] and label -> sagittal flexion [deg]."""


def human_com_series(bag: Path, human_com_bag: Path | None, trial, calibration: StreamCalibration | None = None,
                     marker_set: str | None = None) -> tuple[np.ndarray, HumanPosture | None]:
    """(N, 3) human COM at the marker frames: ``/human/com`` of a bag, or the offline estimator (with a skeleton
    ``calibration`` made beforehand, if given); and the human's sagittal posture, from that bag's
    ``/human/joint_states`` or the estimator's skeleton fit (None when the bag has a COM but no joints)."""
    for source in (human_com_bag, bag):
        if source is None:
            continue
        with BagReader(source) as b:
            if HUMAN_COM_TOPIC in b.topics():
                msgs = b.read(HUMAN_COM_TOPIC)
                t = np.array([stamp_ns(m.header) for _, m in msgs]) * 1e-9     # the markers' own time
                c = np.array([[m.position.x, m.position.y, m.position.z] for _, m in msgs])
                joints = b.read(HUMAN_JOINTS_TOPIC) if HUMAN_JOINTS_TOPIC in b.topics() else []
                com = np.stack([np.interp(trial.marker_t_s, t, c[:, i]) for i in range(3)], axis=1)
                if not joints:
                    return com, None
                t_j = np.array([stamp_ns(m.header) for _, m in joints]) * 1e-9
                flex = flexion_deg(list(joints[0][1].name), np.array([m.position for _, m in joints]),
                                   SAGITTAL_FLEXION)
                return com, (t_j, np.interp(t_j, t, c[:, 2]), flex)

    subject = Subject(trial.height_m or 1.75, trial.mass_kg or 75.0, trial.sex,
                      marker_set=choose_marker_set(trial.marker_names, marker_set))
    fit = estimate_com(trial.marker_t_s, trial.marker_names, trial.positions, trial.valid, trial.plates,
                       subject, calibration=calibration)
    posture = None
    if fit.q is not None and fit.model is not None:
        posture = (fit.t_s, fit.com_m[:, 2], flexion_deg(list(fit.model.names[2:]), fit.q[:, 7:], SAGITTAL_FLEXION))
    return fit.com_m, posture


def pelvis_height(trial: Trial, marker_set: str | None = None) -> np.ndarray:
    """(N,) the pelvis markers' mean height [m] per marker frame (NaN where none is seen)."""
    pelvis = choose_marker_set(trial.marker_names, marker_set).pelvis.markers
    pel = [trial.marker_names.index(n) for n in pelvis if n in trial.marker_names]
    return np.nanmean(np.where(trial.valid[:, pel], trial.positions[:, pel, 2], np.nan), axis=1)


def trial_phases(trial: Trial, com_h: np.ndarray, chair_fz_n: np.ndarray | None,
                 marker_set: str | None = None) -> Phases:
    """The trial's phases from its pelvis markers, the human COM and the chair plate (if any)."""
    return find_phases(trial.marker_t_s, pelvis_height(trial, marker_set), com_h[:, 0], trial.height_m or 1.75,
                       chair_fz_n)


def _static_calibration(trial: Trial, static: Path, marker_set: str | None) -> StreamCalibration:
    """The human skeleton calibrated on a static trial, for the offline human COM."""
    subject = Subject(trial.height_m or 1.75, trial.mass_kg or 75.0, trial.sex,
                      marker_set=choose_marker_set(trial.marker_names, marker_set))
    return calibrate_subject(trial, subject, static=static)[0]


def _cropped(trial: Trial, keep: np.ndarray) -> Trial:
    """The trial's marker frames where ``keep`` (the plates stay whole: they are looked up by time)."""
    return dataclasses.replace(trial, marker_t_s=trial.marker_t_s[keep], positions=trial.positions[keep],
                               valid=trial.valid[keep])


def run(bag: Path, out: Path, *, params: Path | None = None, plant: Path | None = None,
        human_com_bag: Path | None = None, margin_m: float = DEFAULT_MARGIN_M, time_scale: float | None = None,
        max_time_scale: float = DEFAULT_MAX_TIME_SCALE, simulate: bool = False, config: RetargetConfig | None = None,
        com_feedback: bool = True, stabiliser: StabiliserConfig | None = None, whole: bool = False,
        dynamic: bool = False, controller: str = DEFAULT_CONTROLLER, seat_off_dwell_s: float = SEAT_OFF_DWELL_S,
        gains: WbcGains | None = None, calibration_frame: int | None = None, static: Path | None = None,
        retiming: str = "local", robot: str | None = None, plan: str = DEFAULT_PLAN,
        whole_rise: WholeRiseConfig | None = None, progress: Progress | None = None) -> dict:
    """Retarget ``bag`` into ``out`` (see the module docstring); returns the summary. ``com_feedback``: the
    simulated robot's commands are corrected by :class:`~sit2stand.retarget.stabiliser.ComStabiliser` (gains
    ``stabiliser``, default :class:`~sit2stand.retarget.stabiliser.StabiliserConfig`), as the node does.
    ``time_scale``: play the plan this many times slower than the human (None: adapt, up to ``max_time_scale``,
    ``retiming`` "local" (slower only where a frame needs it) or "uniform" (one growing factor)).
    ``whole``: play the whole recording; by default a trial that ends seated is played up to the human's sit-down
    (:mod:`sit2stand.retarget.phases`). ``dynamic``: the commands go through the dynamics filter
    (:mod:`sit2stand.retarget.dynamic`, QP gains ``gains``), which stretches time only where it cannot follow;
    ``seat_off_dwell_s``: the player's wait at the robot's seat-off. ``controller``: the simulated robot's
    (``wbc``: whole-body torque control, the default; ``inverse_dynamics``: joint PD with that feed-forward). The
    marker map is made on a seated frame (:func:`~sit2stand.retarget.calibration.map_frame`;
    ``calibration_frame``: that one); a ``static`` trial calibrates the human skeleton when the human COM is
    estimated here. ``plant``: None is a plant without unmodeled effects
    (:meth:`~sit2stand.robot.model.PlantConfig.load`), not the command's default (the packaged ``default`` plant,
    26 kg hidden); parameters identified on one and simulated on the other are a model error of 26 kg. ``robot``:
    the robot profile (a packaged name or a file; None: the plant's, TALOS where it names none). ``plan``: "whole"
    (the rise also optimised as a whole, :mod:`sit2stand.retarget.whole_rise`, settings ``whole_rise``, and the plan
    that plays shorter played; ``progress`` told how the optimisation goes) or "frames" (the per-frame plan, retimed
    by the player)."""
    if plan not in PLANS:
        raise InputError(f"plan {plan!r}: one of {', '.join(PLANS)}")
    refuse_existing_bag(out / "retarget")
    out.mkdir(parents=True, exist_ok=True)
    trial = read_trial(bag)
    config = config or RetargetConfig()
    skeleton = _static_calibration(trial, static, config.marker_set) if static is not None else None
    com_h, human_posture = human_com_series(bag, human_com_bag, trial, skeleton, config.marker_set)
    chair = next((p for p in trial.plates if p.name == "chair"), None)
    fz = None if chair is None else np.interp(trial.marker_t_s, chair.t_s, chair.force_n[:, 2])
    phases = trial_phases(trial, com_h, fz, config.marker_set)
    if not whole:
        keep = phases.rise_and_stand(trial.marker_t_s)
        trial, com_h, fz = _cropped(trial, keep), com_h[keep], None if fz is None else fz[keep]
    sim = None
    q_start = None
    links = read_link_parameters(params) if params else None     # read once: the plan's model and the robot's
    if simulate:
        sim = Plant(PlantConfig.load(plant, robot), controller_params=links)
        sim.settle(2.0)     # at rest on the chair, as the driver starts; the calibration overlays this posture
        q_start = sim.pin_configuration(sim.data.qpos)
    robot = robot_setup(plant, params, q_start=q_start, prebuilt=robot_model(plant, params, links, robot=robot))
    rt = Retargeter(robot, config)
    dt = float(np.median(np.diff(trial.marker_t_s)))
    standing = np.flatnonzero(phases.labels != "seated")
    seated = (int(standing[0]) if len(standing) else len(phases.labels)) if phases.starts_seated else 0
    where = map_frame(trial.marker_t_s, trial.positions, trial.valid, seated, calibration_frame)
    k = where.first
    flexion = None if human_posture is None else \
        {label: float(np.interp(trial.marker_t_s[k], human_posture[0], v)) for label, v in human_posture[2].items()}
    rt.calibrate(trial.marker_names, trial.positions[k], trial.valid[k], com_h[k], frame_period_s=dt,
                 human_flexion_deg=flexion).save(out / "marker_map.yaml")
    dynamics = DynamicsFilter(robot.model, dt, robot.support_xy, gains=gains) if dynamic else None
    player = PlanPlayer(robot.model, dt, robot.support_xy, margin_m=margin_m, fixed_time_scale=time_scale,
                        max_time_scale=max_time_scale, seat_off_dwell_s=seat_off_dwell_s, dynamics=dynamics,
                        retiming=retiming)
    frames, cmds = retarget_sequence(rt, player, trial.marker_t_s, trial.positions, trial.valid, com_h, fz,
                                     pull=sim is None and plan == "frames")
    optimised, chosen = None, {"plan": "frames"}
    if plan == "whole":
        optimised, player, chosen = optimised_player(rt.model, frames, player, config=whole_rise,
                                                     first_scale=time_scale or 1.0, identified=links is not None,
                                                     progress=progress)
        while sim is None and not player.done:
            cmds.append(player.pull())
    simulated = {}
    if sim is not None:      # the commands pulled as the robot moves: a robot that trails its plan slows it
        com_feedback = com_feedback_applies(com_feedback, controller)
        stab = ComStabiliser(robot.model, robot.sole_frames, robot.sole_targets, stabiliser) if com_feedback else None
        torques = None if chosen["plan"] != "whole" else (lambda t: optimised.torque_at(t, dt))
        cmds, simulated = _simulate(sim, player, dt, out, stabiliser=stab, controller=controller,
                                    t0_s=float(trial.marker_t_s[0]), human_posture=human_posture,
                                    plan_torques=torques)
        simulated = {"com_feedback": bool(com_feedback), "controller": controller,
                     "controller_plan_torques": torques is not None, **simulated}
    ik_ms = np.array([f.ik.seconds for f in frames]) * 1e3
    feasible = np.array([f.ik.feasible for f in frames])
    com_err = np.array([f.ik.com_error_m for f in frames])
    on_feet = [c for c in cmds if c.on_feet]
    summary = {
        "bag": str(bag), "robot": profile_of(robot.model).name, "parameters": robot.parameters, "frames": len(frames),
        "calibration_frame": k, "calibration_frame_reason": where.reason,
        "infeasible_frames": int((~feasible).sum()),
        "com_equality_max_error_mm_feasible": float(com_err[feasible].max() * 1e3) if feasible.any() else None,
        "ik_ms_p50": float(np.percentile(ik_ms, 50)), "ik_ms_p99": float(np.percentile(ik_ms, 99)),
        # time_scale: the robot's duration over the human's; the peak local factor beside it
        "time_scale": len(cmds) / max(1, len(frames)), "time_scale_peak": max(c.time_scale for c in cmds),
        "retiming": "fixed" if time_scale else retiming, "commands": len(cmds), "plan_duration_s": len(cmds) * dt,
        **chosen, **(optimised.summary() if optimised is not None else {}),
        "duration_ratio": len(cmds) / max(1, len(frames)), **_filter_summary(cmds), **_marker_fit(frames),
        **_zmp_summary(on_feet), **_com_deviation(frames, cmds),
        "human_seat_off_frame": next((i for i, f in enumerate(frames) if f.human_seat_off), None),
        "robot_seat_off_frame": next((i for i, f in enumerate(frames) if not f.seated), None),
        "lead_in_frames": int(sum(f.t_s < trial.marker_t_s[0] for f in frames)),
        "phases": {"rise_start_s": phases.rise_start_s, "seat_off_s": phases.seat_off_s,
                   "standing_s": phases.standing_s, "sit_down_s": phases.sit_down_s,
                   "played": "whole trial" if whole or phases.sit_down_s is None else "rise and stand"},
    }
    summary.update(simulated)
    if simulated:
        summary.update(end_posture_verdict(summary, frames))
        sim_rows = np.load(out / "simulation.npy")
        summary["cycles"] = cycle_rows(trial.marker_t_s, pelvis_height(trial, config.marker_set), sim_rows[:, 0],
                                       sim_rows[:, 10])
    _write_bag(out / "retarget", cmds, robot.joint_names, float(trial.marker_t_s[0]), dt,
               profile_of(robot.model).root_link)
    plan_figure(trial, com_h, frames, cmds, dt, out / "retarget.png", summary)
    if simulated:
        timing_figure(trial, com_h, frames, cmds, sim_rows, out / "timing.png", summary)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def _marker_fit(frames) -> dict:
    """How far the plan's robot is from the human's markers: the distance [mm] between each robot marker site and
    its human marker mapped onto the robot (the calibration's similarity), RMS over every frame and marker, and the
    worst frame's RMS."""
    rms = np.array([f.ik.marker_rms_m for f in frames], float)
    rms = rms[np.isfinite(rms)]
    if not len(rms):
        return {}
    return {"marker_rms_mm": float(np.sqrt(np.mean(rms**2)) * 1e3), "marker_rms_mm_worst_frame": float(rms.max() * 1e3)}


def _com_deviation(frames, cmds) -> dict:
    """The played plan's forward COM against the COM map's target (the human's mapped COM) at the human time each
    command plays [m]: RMS and largest (x only: after seat-off y is the feet's middle, not the human's)."""
    if not cmds:
        return {}
    t = np.array([f.t_s for f in frames])
    target_x = np.array([f.com_target[0] for f in frames])
    dev = np.array([c.com[0] for c in cmds]) - np.interp([t[0] + c.t_plan_s for c in cmds], t, target_x)
    return {"com_deviation_rms_m": float(np.sqrt(np.mean(dev**2))), "com_deviation_max_m": float(np.abs(dev).max())}


def _zmp_summary(on_feet: list) -> dict:
    """The planned ZMP off the chair: the retiming's criterion (each frame at its time scale) and the commands' own
    ZMP, whose accelerations include the time warp's changes of speed."""
    if not on_feet:
        return {"min_zmp_margin_on_feet_m": None}
    own = np.array([c.margin_m for c in on_feet])
    return {"min_zmp_margin_on_feet_m": float(min(c.margin_at_scale_m for c in on_feet)),
            "zmp_margin_with_warp_p5_m": float(np.percentile(own, 5)),
            "zmp_outside_feet_share": float(np.mean(own < 0))}


def _filter_summary(cmds) -> dict:
    """What the dynamics filter did over the plan (nothing when it did not run)."""
    reports = [c.filter for c in cmds if c.filter is not None]
    if not reports:
        return {}
    return {"dynamic": True,
            "filter_com_deviation_max_m": max(r.com_deviation_m for r in reports),
            "filter_com_deviation_rms_m": float(np.sqrt(np.mean([r.com_deviation_m**2 for r in reports]))),
            "filter_torque_ratio_max": max(r.torque_ratio for r in reports),
            "filter_qp_solved_fraction": float(np.mean([r.solved for r in reports]))}


def _write_bag(path: Path, cmds, joint_names: list[str], t0_s: float, dt: float, root_frame: str) -> None:
    """The plan as the retargeter node publishes it: joint commands (frame: the robot's root link), planned COM and
    ZMP (world)."""

    ts = typestore().types
    with BagWriter(path) as w:
        w.add_topic(ROBOT_JOINT_COMMAND_TOPIC, "trajectory_msgs/msg/JointTrajectory")
        w.add_topic(ROBOT_PLANNED_COM_TOPIC, "geometry_msgs/msg/PointStamped")
        w.add_topic(ROBOT_PLANNED_ZMP_TOPIC, "geometry_msgs/msg/PointStamped")
        for k, c in enumerate(cmds):
            t_ns = int(round((t0_s + k * dt) * 1e9))
            point = ts["trajectory_msgs/msg/JointTrajectoryPoint"](
                positions=c.q[7:].copy(), velocities=c.v[6:].copy(), accelerations=c.a[6:].copy(),
                effort=np.zeros(0), time_from_start=ts["builtin_interfaces/msg/Duration"](sec=0, nanosec=0))
            w.write(ROBOT_JOINT_COMMAND_TOPIC, t_ns,
                    ts["trajectory_msgs/msg/JointTrajectory"](header=M.header(t_ns, root_frame),
                                                            joint_names=list(joint_names), points=[point]))
            w.write(ROBOT_PLANNED_COM_TOPIC, t_ns,
                    ts["geometry_msgs/msg/PointStamped"](header=M.header(t_ns, WORLD_FRAME), point=M.point(*c.com)))
            w.write(ROBOT_PLANNED_ZMP_TOPIC, t_ns,
                    ts["geometry_msgs/msg/PointStamped"](header=M.header(t_ns, WORLD_FRAME), point=M.point(*c.zmp)))


def _write_robot_bag(path: Path, sensed: list, joint_names: list[str], root_frame: str, t0_s: float,
                     dt: float) -> None:
    """The simulated robot's sensed states, one per command period ``dt`` from ``t0_s``, as the driver publishes
    them (joint states, feet wrenches, COP, base pose)."""
    with BagWriter(path, custom_data={"source": "sit2stand retarget --simulate", "robot_root": root_frame}) as w:
        for topic, msgtype in M.ROBOT_STATE_TOPICS.items():
            w.add_topic(topic, msgtype)
        for k, s in enumerate(sensed, start=1):
            t_ns = int(round((t0_s + k * dt) * 1e9))
            for topic, msg in M.robot_state(t_ns, joint_names, s.q, s.qd, s.tau, s.wrench_world, s.cop_m, s.base_pose,
                                            root_frame):
                w.write(topic, t_ns, msg)


def physics_steps_due(commands: int, dt: float, timestep_s: float, taken: int) -> int:
    """Physics steps to take after the ``commands``-th command (period ``dt`` [s]) when ``taken`` have been: the
    simulation kept on the commands' clock. A 120 Hz frame is 8.33 steps of 1 ms; 8 a frame would play the plan
    4 % fast."""
    return max(1, int(round(commands * dt / timestep_s)) - taken)


def _simulate(plant, player: PlanPlayer, dt: float, out: Path, hold_s: float = 3.0,
              stabiliser: ComStabiliser | None = None, *, controller: str, t0_s: float = 0.0,
              human_posture: HumanPosture | None = None,
              plan_torques: Callable[[float], np.ndarray | None] | None = None) -> tuple[list, dict]:
    """Drive the plant with the player's commands (under its on-board ``controller``), pulled one per frame period
    with the robot's lag behind the plan (the COM feedback's error), then hold the last one. Returns (commands,
    figures). Writes ``simulation.npy``: t, true COM (3), planned COM (3), COP (3), pelvis z, pelvis x, planned
    pelvis x, largest joint tracking error [rad] and its joint index, chair force [N], COM of the measured state
    with the controller's model (3), COM feedback offset (x, y) [m], pelvis pitch [deg], knee flexion [rad].
    ``stabiliser``: a :class:`~sit2stand.retarget.stabiliser.ComStabiliser` correcting each command for the plant's
    measured state (None: the commands as planned). Writes the robot's sensed state once per command period into the bag
    ``robot`` (the driver's topics, stamped from ``t0_s`` on the commands' clock): what ``sit2stand export``
    reads. ``human_posture``: the human's, to give the simulated robot's posture RMS against it
    (:func:`~sit2stand.retarget.compare.posture_rms_deg`). ``plan_torques``: the joint torques [N m] the plan asks
    at a human time (the optimisation's; None outside its span), given to the controller with each command."""
    ticks = taken = 0
    sensed = []
    rows, cmds, torque = [], [], []
    profile = plant.cfg.profile
    knees = plant.qadr[[plant.joint_names.index(profile.leg(s, "knee")) for s in SIDES]]
    offset, lag = np.zeros(2), 0.0
    held = 0
    while held < int(hold_s / dt):
        if not player.done:
            c = player.pull(lag_m=lag)
            cmds.append(c)
        else:           # the last pose held at rest, its COM feedback still on, as the retargeter holds it
            held += 1
            c = dataclasses.replace(cmds[-1], v=np.zeros_like(cmds[-1].v), a=np.zeros_like(cmds[-1].a))
        if not held or stabiliser is not None:
            q = c.q
            if stabiliser is not None:
                fix = stabiliser.correct(c.q, c.com, plant.pin_configuration(plant.data.qpos), c.on_feet, dt)
                q, offset, lag = fix.q, fix.offset_m, fix.lag_m
            elif c.on_feet:      # no COM feedback (torque control has its own COM task, or it is off): the plan
                #                  still waits for a robot behind it, from the measured state
                lag = com_lag_m(c.com - plant.model_com())
            tau = None if plan_torques is None or held else plan_torques(c.t_plan_s)
            plant.command(q[7:], c.v[6:], c.a[6:], feedforward=controller, tau=tau)
        ticks += 1
        steps = physics_steps_due(ticks, dt, plant.cfg.timestep_s, taken)
        plant.step(steps)
        taken += steps
        jm = plant.joints
        torque.append(np.abs(plant.data.actuator_force[jm.pd_ids] + plant.data.actuator_force[jm.ff_ids]) / jm.effort)
        s = plant.sensors()
        sensed.append(s)
        err = plant.data.qpos[plant.qadr] - plant.q_ref
        rows.append([plant.t_s, *plant.true_com(), *c.com,
                     *s.cop_m, plant.data.qpos[2], plant.data.qpos[0], c.q[0],
                     float(np.abs(err).max()), float(np.argmax(np.abs(err))), plant.chair_force_n(),
                     *plant.model_com(), *offset, pitch_deg(xyzw_from_wxyz(plant.data.qpos[3:7])),
                     float(np.mean(plant.data.qpos[knees]))])
        if plant.fallen:
            while not player.done:      # the rest of the plan, for its bag and figures
                cmds.append(player.pull())
            break
    arr = np.array(rows)
    np.save(out / "simulation.npy", arr)
    _write_robot_bag(out / "robot", sensed, plant.joint_names, profile.root_link, t0_s, dt)
    stood, sat_down = _verdict(plant.fallen, arr[:, 10], np.array([c.q[2] for c in cmds]),
                               not cmds[-1].on_feet and any(c.on_feet for c in cmds))
    err = arr[:, 1:4] - arr[:, 4:7]
    up = int(np.argmax(arr[:, 10])) if sat_down is not None else -1     # the standing instant judged
    return cmds, {"stood_up": stood, "sat_down": sat_down, "fall": plant.status_text if plant.fallen else None,
                  "pelvis_final_m": float(arr[-1, 10]), "pelvis_planned_final_m": float(cmds[-1].q[2]),
                  "final_knee_flexion_deg_robot": float(np.degrees(arr[up, -1])),
                  "final_pelvis_height_ratio": float(arr[up, 10] / standing_pelvis_height_m(plant)),
                  "final_pelvis_pitch_deg": float(arr[up, -2]),
                  "com_tracking_rms_m": float(np.sqrt(np.mean(np.sum(err[:, :2] ** 2, axis=1)))),
                  "com_feedback_max_offset_m": float(np.abs(arr[:, 19:21]).max()), **_torques(plant, np.array(torque)),
                  **_qp_times(plant), **_robot_posture_rms(plant, arr, sensed, human_posture)}


def _robot_posture_rms(plant, arr: np.ndarray, sensed: list, human: HumanPosture | None) -> dict:
    """``posture_rms_deg`` of the simulated robot (its sensed joints, its true COM) against the human's posture
    (nothing without it, or when either body does not rise)."""
    if human is None:
        return {}
    robot = flexion_deg(plant.joint_names, np.array([x.q for x in sensed]), plant.cfg.profile.sagittal_flexion())
    rms = posture_rms_deg(human, (arr[:, 0], arr[:, 3], robot))
    return {} if rms is None else {"posture_rms_deg": rms}


def end_posture_verdict(summary: dict, frames: list) -> dict:
    """The human's final knee flexion [deg] (the last frame's; the most extended one when the trial sits back
    down) beside the robot's, and ``stood_up`` only when they are within ``KNEE_TOLERANCE_DEG``."""
    flexion = [f.human_knee_flexion_rad for f in frames if f.human_knee_flexion_rad is not None]
    if not flexion or "final_knee_flexion_deg_robot" not in summary:
        return {"final_knee_flexion_deg_human": None}
    human = float(np.degrees(min(flexion) if summary.get("sat_down") is not None else flexion[-1]))
    knees_match = abs(summary["final_knee_flexion_deg_robot"] - human) <= KNEE_TOLERANCE_DEG
    return {"final_knee_flexion_deg_human": human, "standing_knees_match": bool(knees_match),
            "stood_up": bool(summary["stood_up"] and knees_match)}


def _verdict(fallen: bool, pelvis_z: np.ndarray, planned_z: np.ndarray, ends_seated: bool) -> tuple[bool, bool | None]:
    """(stood up, sat back down) from the simulated and planned pelvis heights [m]: stood up when, not fallen, the
    pelvis came within 8 cm of the plan's standing height and 20 cm above its start (at the end, or for a plan that
    ends seated, at its highest); sat back down (None unless the plan ends seated) when it ended within 5 cm of the
    plan's last height."""
    up = float(pelvis_z.max() if ends_seated else pelvis_z[-1])
    stand_z = float(planned_z.max() if ends_seated else planned_z[-1])
    stood = not fallen and up > stand_z - 0.08 and up > pelvis_z[0] + STOOD_RISE_M
    sat = (not fallen and abs(float(pelvis_z[-1] - planned_z[-1])) < SAT_DOWN_TOLERANCE_M) if ends_seated else None
    return bool(stood), sat


def _torques(plant, demand: np.ndarray) -> dict:
    """The joint torques the controller asked for (servo + feed-forward) over the URDF limits, once per command:
    the peak, its joint, and the share of commands with some joint clamped at its limit."""
    k = np.unravel_index(np.argmax(demand), demand.shape)
    return {"torque_demand_peak_ratio": float(demand[k]), "torque_demand_peak_joint": plant.joint_names[k[1]],
            "torque_saturated_share": float(np.mean((demand >= 0.999).any(axis=1)))}


def _qp_times(plant) -> dict:
    """The torque controller's QP figures (``WholeBodyController.qp_figures``) and its estimate of the true COM's
    offset from its model's at the end (x, y [m]: :class:`~sit2stand.robot.torque_control.ComOffsetObserver`),
    prefixed ``controller_``, when it ran."""
    if plant.wbc is None:
        return {}
    return {**{f"controller_{k}": v for k, v in plant.wbc.qp_figures().items()},
            "controller_com_offset_m": plant.wbc.com_offset.offset_m.tolist()}
