"""Streaming retargeting: one human frame in, one robot IK pose out; a player turns the poses into joint commands.

:class:`Retargeter` (per frame, no look-ahead):

1. **Calibration** on the first frame (the human seated): markers fixed to the robot's links
   (:func:`sit2stand.retarget.calibration.calibrate_markers`), the human's left ankle, heel and seated COM noted.
2. **COM target**. The human COM's forward position, relative to the human's left ankle and scaled by the leg-length
   ratio (Mistry et al. 2010 map the COM relative to the left foot), goes through a monotone piecewise-linear map to
   the robot's, relative to the robot's left ankle, with three knots:

   * human seated COM -> robot seated COM (the robot starts where it is);
   * human heel -> ``seat_off_fraction`` of the robot's foot length from its heel (the robot's COM must be over its
     feet, with a margin, before its hips leave the seat; a human can leave the seat with the COM behind the heels,
     carried by momentum, which a joint-controlled robot cannot do);
   * human ankle and forward -> the robot's ankle and forward, one to one.

   Before the robot's seat-off (both: the human has left the seat, by the chair plate or the pelvis rising, and the
   robot's target has reached its seat-off knot) the hips stay on the seat (pelvis x and z held: hard) and only the
   COM's x is constrained: with the hips on the seat COM height and COM x are one degree of freedom. After it, COM x and
   y are hard; y ramps to the midline between the feet over ``y_ramp_s``. The COM height is left to the markers.
3. **IK** (:class:`sit2stand.retarget.ik.ComIk`): markers soft (weights by body part), COM and feet hard, joint and
   speed limits; warm-started from the previous frame.

:class:`PlanPlayer` (the dynamic-feasibility stage): smooths the poses (Savitzky-Golay on the tangent coordinates,
``smooth_frames`` wide), computes each pose's ZMP from the centroidal dynamics, and plays the plan back ``s`` times
slower, with ``s`` the smallest factor that keeps the ZMP ``margin_m`` inside the feet wherever the robot is off the
chair, and the joint speeds under ``max_joint_speed``, evaluated over the poses already known ``lookahead_s`` ahead
of the playback point; at the robot's seat-off it dwells ``seat_off_dwell_s`` (the COM settles over the feet before
the hips lift). ``s`` only grows and at a
bounded rate, so the command stays smooth; each command carries positions, velocities and accelerations (time-warp
included). Live, the commands lag the human by ``lookahead_s`` + half the smoothing window, plus the stretching.

Units SI; world frame REP-103 (x forward, y left, z up).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.signal import savgol_coeffs   # at import: a live node's first frames must not pay for it

from ..robot.model import UPPER_LIMB_PREFIXES
from .calibration import PELVIS_MARKERS, MarkerMap, calibrate_markers, marker_group
from .feasibility import frame_time_scales, support_margin, support_polygon, zmp_at_scale
from .ik import ComIk, IkResult

FOOT_MARKERS = ("LANK", "RANK", "LHEE", "RHEE", "LTOE", "RTOE")


@dataclass
class RobotSetup:
    """The robot as the retargeter knows it: kinematics with the COM parameters to use, and its seated start."""

    model: pin.Model
    joint_names: list[str]
    q_seated: np.ndarray                 # Pinocchio configuration (free flyer x y z qx qy qz qw + joints)
    sole_frames: list[int]
    sole_targets: list[pin.SE3]
    support_xy: np.ndarray               # support polygon of both soles (counter-clockwise)
    heel_x_m: float
    toe_x_m: float
    ankle_left: np.ndarray               # left ankle projected on the floor [m]
    leg_length_m: float                  # hip joint -> knee -> ankle
    parameters: str                      # "CAD" or the identified YAML


def robot_model(plant_yaml: str | Path | None = None,
                params_yaml: str | Path | None = None) -> tuple[pin.Model, np.ndarray, str]:
    """The retargeter's robot model (TALOS with the identified COM parameters of ``params_yaml``, ``sit2stand
    identify --model full`` output, or CAD's), its nominal seated configuration from the plant file (Pinocchio
    order; only the posture and chair, never ``unmodeled``), and the parameters' label. The slow part of
    :func:`robot_setup` (~0.6 s): a node builds it before the stream starts."""
    from ..robot.identify import read_link_parameters
    from ..robot.model import PlantConfig, build_spec, controller_model
    from ..robot.plant import apply_parameters, seated_configuration

    cfg = PlantConfig.load(plant_yaml)
    model = controller_model(cfg)
    label = "CAD"
    if params_yaml:
        apply_parameters(model, read_link_parameters(params_yaml))     # IdentificationError is a ValueError
        label = str(params_yaml)
    qpos = seated_configuration(build_spec(cfg, plant=False).compile(), cfg)
    q = qpos.copy()
    q[3:7] = [qpos[4], qpos[5], qpos[6], qpos[3]]
    return model, q, label


def robot_setup(plant_yaml: str | Path | None = None, params_yaml: str | Path | None = None,
                q_start: np.ndarray | None = None, start_joint_names: list[str] | None = None,
                prebuilt: tuple[pin.Model, np.ndarray, str] | None = None) -> RobotSetup:
    """TALOS seated as in the plant file, with the identified COM parameters of ``params_yaml`` or the CAD ones
    (see :func:`robot_model`; ``prebuilt``: its result, made earlier). ``q_start``: the robot's measured seated
    configuration (Pinocchio order), as the paper calibrates on the robot's measured sitting posture; default: the
    plant file's nominal one. ``start_joint_names``: the joint of each of ``q_start[7:]`` when they come in another
    order (e.g. a JointState's)."""
    from ..robot.model import SIDES, SOLE_CENTRE_X_M, SOLE_HALF_SIZE_M

    model, q, label = prebuilt if prebuilt is not None else robot_model(plant_yaml, params_yaml)
    q = q.copy()
    if q_start is not None:
        if np.shape(q_start) != q.shape or not np.all(np.isfinite(q_start)):
            raise ValueError(f"start configuration: {np.shape(q_start)} values (finite), expected {q.shape}")
        q = np.asarray(q_start, float).copy()
        if start_joint_names is not None:
            by_name = dict(zip(start_joint_names, q_start[7:]))
            missing = [n for n in model.names[2:] if n not in by_name]
            if missing:
                raise ValueError(f"start configuration: no position for {', '.join(missing[:5])}")
            q[7:] = [by_name[n] for n in model.names[2:]]
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    soles = [model.getFrameId(f"sole_{s}") for s in SIDES]
    targets = [data.oMf[f].copy() for f in soles]
    corners = []
    for X in targets:
        for sx in (-1, 1):
            for sy in (-1, 1):
                corners.append(X.act(np.array([SOLE_CENTRE_X_M + sx * SOLE_HALF_SIZE_M[0], sy * SOLE_HALF_SIZE_M[1],
                                               0.0]))[:2])
    corners = np.array(corners)
    hip, knee, ankle = (data.oMi[model.getJointId(f"leg_left_{i}_joint")].translation for i in (3, 4, 6))
    ankle_floor = targets[0].translation.copy()
    return RobotSetup(model, list(model.names[2:]), q, soles, targets, support_polygon(corners),
                      float(corners[:, 0].min()), float(corners[:, 0].max()), ankle_floor,
                      float(np.linalg.norm(knee - hip) + np.linalg.norm(ankle - knee)), label)


@dataclass
class RetargetConfig:
    """Retargeting settings (SI units)."""

    weights: dict[str, float] = field(default_factory=lambda: {
        "head": 1.0, "trunk": 1.0, "pelvis": 1.0, "thigh": 0.3, "shank": 0.1, "arm": 0.05})
    posture_weight: float = 1e-3          # pull toward the previous frame (smoothness)
    upper_limb_weight: float = 0.1        # arms and head: pull toward their seated posture. The COM equality could
    #                                       otherwise be met by swinging the heavy arms, frame by frame
    lateral_weight: float = 0.1           # torso yaw, hip yaw and roll, ankle roll: pull toward the seated posture
    #                                       (a sit-to-stand is sagittal; twists would trade marker errors)
    seat_off_fraction: float = 0.3        # robot COM this far along its foot (heel -> toe) before its hips leave
    velocity_limit_rad_s: float = 4.0
    chair_off_force_n: float = 30.0       # human left the seat when the chair plate reads less
    pelvis_rise_m: float = 0.02           # ... or, without a chair plate, when the pelvis markers rose this much
    y_ramp_s: float = 0.5
    hip_release_s: float = 0.4            # the hips' hold on the seat fades out over this after seat-off
    iterations: int = 2                   # Gauss-Newton steps per frame (warm-started from the previous frame)
    qp_tolerance: float = 1e-6            # proxsuite eps_abs of each step's QP
    damping: float = 0.1                  # Levenberg-Marquardt damping of each Gauss-Newton step: with less, the
    #                                       steps in the weakly fixed yaw directions (base, hips, torso) overshoot
    tolerance: float = 1e-4


@dataclass
class RetargetFrame:
    """One retargeted frame."""

    t_s: float
    q: np.ndarray
    com_target: np.ndarray        # [m]; only ``com_axes`` are constrained
    com_axes: tuple[int, ...]
    com: np.ndarray               # the pose's COM [m] (robot model)
    seated: bool                  # hips held on the seat
    human_seat_off: bool
    ik: IkResult
    markers: list = field(default_factory=list)     # the marker tasks solved: (frame id, target [m], weight)


class Retargeter:
    """Per-frame human -> robot retargeting (see the module docstring)."""

    def __init__(self, robot: RobotSetup, cfg: RetargetConfig | None = None) -> None:
        self.robot = robot
        self.cfg = cfg or RetargetConfig()
        self.model = pin.Model(robot.model)         # marker frames are added to a copy
        self.data = self.model.createData()
        self.ik: ComIk | None = None
        self.marker_map: MarkerMap | None = None
        self.q = robot.q_seated.copy()
        self.calibrated = False
        self.seated = True
        self.human_seat_off = False
        self._chair_loaded = False
        self._t_off: float | None = None
        self._y_off = 0.0
        pin.centerOfMass(self.model, self.data, self.q)
        self.com_seated = self.data.com[0].copy()
        self.base_seated = self.q[:3].copy()
        R = pin.Quaternion(self.q[3:7]).toRotationMatrix()
        self.pitch_seated = float(np.arctan2(R[0, 2], R[2, 2]))

    # -- calibration -------------------------------------------------------------------------------------------
    def calibrate(self, names: list[str], positions_m: np.ndarray, valid: np.ndarray, human_com_m: np.ndarray,
                  marker_map: MarkerMap | None = None) -> MarkerMap:
        """Fix the markers to the robot (or use ``marker_map``) from one seated frame; note the human's references.

        Raises:
            ValueError: a marker the calibration needs (pelvis, left knee, ankle, heel) is missing in the frame.
        """
        idx = {n: i for i, n in enumerate(names)}
        need = ("LKNE", "LANK", "LHEE")
        missing = [m for m in need if m not in idx or not valid[idx[m]]]
        if missing:
            raise ValueError(f"calibration frame: marker(s) {', '.join(missing)} missing")
        pel = [idx[m] for m in PELVIS_MARKERS if m in idx and valid[idx[m]]]
        if len(pel) < 3:
            raise ValueError(f"calibration frame: {len(pel)} of {', '.join(PELVIS_MARKERS)} valid; need 3")
        pelvis = positions_m[pel].mean(axis=0)
        knee, ankle, heel = (positions_m[idx[m]] for m in need)
        self.human_thigh = float(np.linalg.norm(knee - pelvis))
        self._pelvis_last = pelvis
        human_leg = float(np.linalg.norm(knee - pelvis) + np.linalg.norm(ankle - knee))
        self.scale = self.robot.leg_length_m / human_leg
        if marker_map is None:
            marker_map = calibrate_markers(self.robot.model, self.robot.q_seated, names, positions_m, valid,
                                           human_leg, self.robot.leg_length_m)
        self.marker_map = marker_map
        self.marker_frames = marker_map.add_frames(self.model)
        self.data = self.model.createData()
        mu = np.full(self.model.nv, self.cfg.posture_weight)
        # arms, head and the lateral joints are regularised toward the seated posture (the rest: the previous frame)
        self.held_to_seated = np.zeros(self.model.nq, bool)
        lateral = ("torso_1_joint",) + tuple(f"leg_{s}_{i}_joint" for s in ("left", "right") for i in (1, 2, 6))
        for j in range(2, self.model.njoints):
            name, jt = self.model.names[j], self.model.joints[j]
            w = self.cfg.upper_limb_weight if name.startswith(UPPER_LIMB_PREFIXES) else \
                self.cfg.lateral_weight if name in lateral else None
            if w is not None:
                mu[jt.idx_v:jt.idx_v + jt.nv] = w
                self.held_to_seated[jt.idx_q:jt.idx_q + jt.nq] = True
        self.ik = ComIk(self.model, self.robot.sole_frames, self.cfg.velocity_limit_rad_s, posture_weight=mu,
                        damping=self.cfg.damping)
        self.ik.eps_abs = self.cfg.qp_tolerance
        self.names = list(names)
        self.weights = np.array([0.0 if n not in self.marker_frames else
                                 self.cfg.weights.get(marker_group(n), 0.0) for n in names])
        self.human_pelvis0 = pelvis
        self.robot_pelvis0 = self.robot.q_seated[:3].copy()
        self.pelvis_markers = pel
        # forward-axis knots of the COM map (robot x relative to its left ankle vs scaled human x relative to its)
        ax, rx = ankle[0], self.robot.ankle_left[0]
        foot = self.robot.toe_x_m - self.robot.heel_x_m
        h = [self.scale * (human_com_m[0] - ax), self.scale * (heel[0] - ax), 0.0]
        r = [self.com_seated[0] - rx, self.robot.heel_x_m + self.cfg.seat_off_fraction * foot - rx, 0.0]
        if not (h[0] < h[1] < h[2]) or not (r[0] < r[1] <= r[2] + 0.05):
            raise ValueError(f"calibration frame: the human's seated COM ({human_com_m[0]:.3f} m), heel "
                             f"({heel[0]:.3f} m) and ankle ({ax:.3f} m) are not in that order along x: not seated")
        self.knots_h, self.knots_r = np.array(h), np.array(r)
        self.human_ankle_x, self.robot_ankle_x = ax, rx
        self.calibrated = True
        return marker_map

    def com_target_x(self, human_com_x_m: float | np.ndarray) -> np.ndarray:
        """The robot's forward COM target [m] for a human COM x [m] (lab), through the piecewise-linear map."""
        h = self.scale * (np.asarray(human_com_x_m, float) - self.human_ankle_x)
        r = np.interp(h, self.knots_h, self.knots_r, left=self.knots_r[0], right=np.nan)
        beyond = h > self.knots_h[-1]
        r = np.where(beyond, self.knots_r[-1] + (h - self.knots_h[-1]), r)
        return self.robot_ankle_x + r

    # -- per frame ---------------------------------------------------------------------------------------------
    def step(self, t_s: float, positions_m: np.ndarray, valid: np.ndarray, human_com_m: np.ndarray,
             chair_force_n: float | None = None) -> RetargetFrame:
        """Retarget one frame (the first call calibrates). ``chair_force_n``: the chair plate's vertical force, if
        there is a chair plate (None: seat-off from the pelvis markers)."""
        if not self.calibrated:
            raise RuntimeError("Retargeter.step before calibrate")
        cfg, robot = self.cfg, self.robot
        ok = valid & np.all(np.isfinite(positions_m), axis=1)
        # human seat-off
        if not self.human_seat_off:
            if chair_force_n is not None and np.isfinite(chair_force_n):
                self._chair_loaded |= chair_force_n > 2 * cfg.chair_off_force_n
                self.human_seat_off = self._chair_loaded and chair_force_n < cfg.chair_off_force_n
            else:
                pel = [i for i in self.pelvis_markers if ok[i]]
                if pel:
                    rise = positions_m[pel, 2].mean() - self.human_pelvis0[2]
                    self.human_seat_off = rise > cfg.pelvis_rise_m
        target = self.com_seated.copy()
        target[0] = float(self.com_target_x(human_com_m[0]))
        pel = [i for i in self.pelvis_markers if ok[i]]
        pelvis_now = positions_m[pel].mean(axis=0) if pel else self._pelvis_last
        self._pelvis_last = pelvis_now
        if self.seated and self.human_seat_off and target[0] >= robot.ankle_left[0] + self.knots_r[1] - 1e-3:
            self.seated = False
            self._t_off = t_s
            pin.centerOfMass(self.model, self.data, self.q)
            self._y_off = float(self.data.com[0][1])
            # the human's pelvis has already moved (the robot leaves the seat later): take that displacement out of
            # the marker targets, and give it back as the human's pelvis rises, so the robot's pelvis does not lunge
            self._marker_offset = self.scale * (pelvis_now - self.human_pelvis0)
            self._z_off = pelvis_now[2]
        mid_y = float(np.mean([X.translation[1] for X in robot.sole_targets]))
        if self.seated:
            axes = (0,)
        else:
            axes = (0, 1)
            ramp = min(1.0, (t_s - self._t_off) / max(cfg.y_ramp_s, 1e-9))
            ramp = ramp * ramp * (3 - 2 * ramp)          # smoothstep
            target[1] = self._y_off + ramp * (mid_y - self._y_off)
        # markers: the calibration's similarity (pelvis on pelvis, scaled), fixed for the whole demonstration
        tgt = self.robot_pelvis0 + self.scale * (positions_m - self.human_pelvis0)
        if not self.seated:
            progress = np.clip((pelvis_now[2] - self._z_off) / (0.9 * self.human_thigh), 0.0, 1.0)
            tgt = tgt - (1.0 - progress) * self._marker_offset
        markers = [(self.marker_frames[self.names[i]], tgt[i], float(self.weights[i]))
                   for i in range(len(self.names)) if ok[i] and self.weights[i] > 0]
        # hips on the seat: pelvis x and z held (hard); after seat-off the hold fades out as a soft task, so that
        # the pose does not jump to where the human's pelvis already is
        hold, weight = self.base_seated, None
        if not self.seated:
            fade = (t_s - self._t_off) / max(cfg.hip_release_s, 1e-9)
            weight = 1e4 * (1.0 - min(1.0, fade)) ** 2 if fade < 1.0 else None
            hold = self.base_seated if weight is not None else None
        q_ref = np.where(self.held_to_seated, robot.q_seated, self.q)
        res = self.ik.solve(self.q, markers, target, robot.sole_targets, q_ref=q_ref, com_axes=axes,
                            q_prev=self.q, max_iterations=cfg.iterations, tol=cfg.tolerance, base_xz=hold,
                            base_weight=weight, base_pitch_min=self.pitch_seated if self.seated else None)
        self.q = res.q
        pin.centerOfMass(self.model, self.data, self.q)
        return RetargetFrame(t_s, res.q, target, axes, self.data.com[0].copy(), self.seated, self.human_seat_off, res,
                             markers)


@dataclass
class Command:
    """One joint command of the played plan."""

    t_plan_s: float              # the human time it plays
    q: np.ndarray                # full Pinocchio configuration
    v: np.ndarray                # (nv,) [rad/s, m/s]
    a: np.ndarray                # (nv,)
    time_scale: float
    com: np.ndarray              # planned COM [m]
    zmp: np.ndarray              # planned ZMP [m] on the floor at this time scale
    margin_m: float              # ZMP distance inside the feet (negative: outside); inf while seated
    on_feet: bool


class PlanPlayer:
    """Smooths, checks and retimes a stream of IK poses (see the module docstring).

    ``push`` one pose per human frame (period ``dt``); ``pull`` once per output tick (same period) returns the next
    command, or None while the look-ahead fills. ``fixed_scale`` set: no adaptation (1.0: the human's timing)."""

    def __init__(self, model: pin.Model, dt: float, polygon_xy: np.ndarray, *, margin_m: float = 0.06,
                 lookahead_s: float = 0.8, smooth_frames: int = 21, max_scale: float = 4.0,
                 max_scale_rate: float = 1.5, fixed_scale: float | None = None,
                 max_joint_speed: float = 0.6, seat_off_dwell_s: float = 1.0) -> None:
        self.model, self.data = model, model.createData()
        self.dt = dt
        self.polygon = polygon_xy
        self.margin_m = margin_m
        self.lookahead = max(0, int(round(lookahead_s / dt)))
        self.half = max(0, smooth_frames // 2)
        self.max_scale = max_scale
        self.max_rate = max_scale_rate
        self.fixed = fixed_scale
        self.max_speed = max_joint_speed
        self.dwell_pulls = int(round(seat_off_dwell_s / dt))
        self._dwelt = 0
        self.s = 1.0 if fixed_scale is None else float(fixed_scale)
        self.s_goal = self.s
        self.mass = float(pin.computeTotalMass(model))
        self._raw_q: list[np.ndarray] = []
        self._raw_feet: list[bool] = []
        self._q: list[np.ndarray] = []         # smoothed poses
        self._v: list[np.ndarray] = []
        self._a: list[np.ndarray] = []
        self._feet: list[bool] = []
        self._dyn: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []    # (com, com acc, dL/dt) at s = 1
        self.u = 0.0              # playback point, in frames of the plan
        self.started = False
        self.finished = False
        self._coef_cache: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._s_req: list[float] = []          # each frame's own smallest time scale

    # -- input -------------------------------------------------------------------------------------------------
    def push(self, q: np.ndarray, on_feet: bool) -> None:
        self._raw_q.append(np.asarray(q, float).copy())
        self._raw_feet.append(bool(on_feet))
        self._smooth_available(final=False)

    def close(self) -> None:
        """No more poses: the tail is smoothed with what there is and played to the end."""
        self._smooth_available(final=True)
        self.finished = True

    def _smooth_available(self, final: bool) -> None:
        """Savitzky-Golay fit (cubic) of the poses' tangent coordinates around each frame once its window is
        known: the smoothed pose and its velocity and acceleration from the same fit; then the frame's dynamics."""
        n = len(self._raw_q)
        model, dt = self.model, self.dt
        while len(self._q) < n and (final or len(self._q) + self.half < n):
            k = len(self._q)
            half = min(self.half, k, n - 1 - k)
            ref = self._raw_q[k]
            if half >= 2:
                X = np.array([pin.difference(model, ref, self._raw_q[j]) for j in range(k - half, k + half + 1)])
                c0, c1, c2 = self._coefs(half)
                q, v, a = pin.integrate(model, ref, c0 @ X), c1 @ X / dt, c2 @ X / dt**2
            else:        # the ends of a closed plan: at rest
                q, v, a = ref, np.zeros(model.nv), np.zeros(model.nv)
            self._q.append(q)
            self._v.append(v)
            self._a.append(a)
            self._feet.append(self._raw_feet[k])
            pin.centerOfMass(model, self.data, q, v, a)
            com, acom = self.data.com[0].copy(), self.data.acom[0].copy()
            pin.computeCentroidalMomentumTimeVariation(model, self.data, q, v, a)
            # dL/dt's velocity-product and acceleration parts both scale with 1/s^2 when played s x slower
            self._dyn.append((com, acom, self.data.dhg.angular.copy()))
            self._s_req.append(self.frame_scale(len(self._dyn) - 1))

    def _coefs(self, half: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        c = self._coef_cache.get(half)
        if c is None:
            order = min(3, 2 * half)
            c = tuple(savgol_coeffs(2 * half + 1, order, deriv=d, use="dot") for d in (0, 1, 2))
            self._coef_cache[half] = c
        return c

    # -- output ------------------------------------------------------------------------------------------------
    def frame_scale(self, k: int) -> float:
        """Smallest time scale (grid of 0.02, at most ``max_scale``) keeping frame ``k``'s ZMP ``margin_m`` inside the
        feet (none while the robot is on the chair) and its joint speeds under ``max_joint_speed`` [rad/s]."""
        speed = float(np.abs(self._v[k][6:]).max()) / self.max_speed if self.max_speed > 0 else 1.0
        s = 1.0
        if self._feet[k]:
            com, acc, dl = self._dyn[k]
            s = float(frame_time_scales(com, acc, dl, self.mass, self.polygon, self.margin_m, self.max_scale)[0])
        return min(max(s, speed), self.max_scale)

    def required_scale(self, frames: range) -> float:
        """Smallest time scale keeping the ZMP ``margin_m`` inside the feet on all of ``frames`` (known ones)."""
        ks = [k for k in frames if k < len(self._s_req)]
        return max((self._s_req[k] for k in ks), default=1.0)

    def ready(self) -> bool:
        known = len(self._v)
        return self.finished or known >= self.lookahead + 2

    def pull(self) -> Command | None:
        known = len(self._v)
        if known < 1 or (not self.started and not self.ready()):
            return None
        self.started = True
        if self.fixed is None:
            ahead = range(int(self.u), min(known, int(self.u) + self.lookahead + 1))
            self.s_goal = max(self.s_goal, self.required_scale(ahead))
        s_prev = self.s
        self.s = min(self.s_goal, self.s + self.max_rate * self.dt)
        s_dot = (self.s - s_prev) / self.dt
        k = int(np.floor(self.u))
        if k >= known - 1:          # starved (live input late) or at the end: hold the last pose
            k, frac = known - 1, 0.0
            self.u = float(k)
            hold = True
        elif self._feet[k] and self._dwelt < self.dwell_pulls:
            # at the robot's seat-off: wait, so that the COM settles over the feet before the hips lift
            frac, hold = 0.0, True
            self.u = float(k)
            self._dwelt += 1
        else:
            frac = self.u - k
            hold = False
        q = pin.interpolate(self.model, self._q[k], self._q[min(k + 1, known - 1)], frac)
        v_plan = (1 - frac) * self._v[k] + frac * self._v[min(k + 1, known - 1)]
        a_plan = (1 - frac) * self._a[k] + frac * self._a[min(k + 1, known - 1)]
        u_dot = 0.0 if hold else 1.0 / self.s
        u_ddot = 0.0 if hold else -s_dot / self.s**2
        v = v_plan * u_dot
        a = a_plan * u_dot**2 + v_plan * u_ddot
        com, acom, dl = self._dyn[k]
        zmp = zmp_at_scale(com[None], acom[None], dl[None], self.mass, self.s)[0] if not hold else \
            np.array([com[0], com[1], 0.0])
        on_feet = self._feet[k]
        margin = float(support_margin(zmp[None, :2], self.polygon)[0]) if on_feet else np.inf
        if not hold:
            self.u += u_dot
        return Command(k * self.dt + frac * self.dt, q, v, a, self.s, com, zmp, margin, on_feet)

    @property
    def done(self) -> bool:
        return self.finished and self.u >= len(self._v) - 1


def retarget_sequence(retargeter: Retargeter, player: PlanPlayer, t_s: np.ndarray, positions_m: np.ndarray,
                      valid: np.ndarray, human_com_m: np.ndarray, chair_force_n: np.ndarray | None = None
                      ) -> tuple[list[RetargetFrame], list[Command]]:
    """A whole recorded demonstration through a calibrated ``retargeter`` and a ``player``, as the node streams it:
    one pull per frame, then the rest of the (retimed) plan. Returns (frames, commands)."""
    frames, cmds = [], []
    for k, t in enumerate(t_s):
        fz = None if chair_force_n is None else float(chair_force_n[k])
        f = retargeter.step(float(t), positions_m[k], valid[k], human_com_m[k], fz)
        frames.append(f)
        player.push(f.q, not f.seated)
        c = player.pull()
        if c is not None:
            cmds.append(c)
    player.close()
    while not player.done:
        cmds.append(player.pull())
    return frames, cmds
