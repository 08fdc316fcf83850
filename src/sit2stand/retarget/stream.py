"""Streaming retargeting: one human frame in, one robot IK pose out; a player turns the poses into joint commands.

:class:`Retargeter` (per frame, no look-ahead):

1. **Calibration** on the first frame (the human seated; after seat-off, given the human's flexions, the robot posed
   like them): markers fixed to the robot's links (:func:`sit2stand.retarget.calibration.calibrate_markers`), the
   human's left ankle, heel and seated COM noted.
2. **COM target**. The human COM's forward position, relative to the human's left ankle and scaled by the leg-length
   ratio (Mistry et al. 2010 map the COM relative to the left foot), goes through a monotone piecewise-linear map to
   the robot's, relative to the robot's left ankle, with three knots:

   * human seated COM -> robot seated COM (the robot starts where it is);
   * human heel -> ``seat_off_fraction`` of the robot's foot length from its heel (the robot's COM must be over its
     feet, with a margin, before its hips leave the seat; a human can leave the seat with the COM behind the heels,
     carried by momentum, which a joint-controlled robot cannot do);
   * human ankle and forward -> the robot's ankle and forward, one to one.

   Before the robot's seat-off (both: the human has left the seat, by the chair plate or the pelvis rising, and the
   robot's target has reached its seat-off knot) the hips stay on the seat (x and z held, hard: the pelvis's origin,
   or the hips' axis where the trunk only turns: :func:`~sit2stand.robot.model.held_on_seat_b`) and only the COM's x
   is constrained: with the hips on the seat COM height and COM x are one degree of freedom. After it, COM x and y
   are hard; y ramps to the midline between the feet over ``y_ramp_s``. The COM height is left to the markers, above
   one floor: the pelvis rises ``seat_clearance_m`` clear of its seated height over ``seat_clearance_s`` and stays at
   least that high (hard) until the human sits back down: the markers alone can keep the hips at the seat's height,
   or dip them into it, after the plan has the robot on its feet, and the robot's hips then bounce on the seat. 2 cm
   because over the seat's front edge a thigh rises only about a quarter as much as the pelvis (it turns about the
   knee). Measured in docs/results.md.
3. **IK** (:class:`sit2stand.retarget.ik.ComIk`): markers soft (weights by body part; their targets the human's
   scaled by leg length, vertically by the robot's rise to its stance over the human's), COM and feet hard, joint
   and speed limits; after seat-off both knees pulled toward the human's as it stands; warm-started from the
   previous frame. The robot it knows: :mod:`sit2stand.retarget.robot`.

The poses go on to :class:`sit2stand.retarget.player.PlanPlayer`, which turns them into joint commands.

Units SI; world frame REP-103 (x forward, y left, z up).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..errors import InputError
from ..io.frame_rate import MIN_RATE_HZ
from ..robot.model import SIDES, held_on_seat_b
from ..robot.profile import profile_of
from ..human.marker_sets import choose_marker_set
from .calibration import MarkerMap, calibrate_markers, left_leg_points, marker_roles, posed_like
from .demonstration import ComMap, HumanSeated, HumanWatch, MarkerTasks, RobotSeatOff, knee_flexion
from .robot import RobotSetup
from .ik import LIFT_TORQUE_SHARE, ComIk, IkResult, MarkerTargets
from .player import Command, PlanPlayer

SEATED_COM_BEHIND_ANKLE_THIGHS = 0.6
"""Where a seated human's COM is along x: this many thigh lengths behind the ankle (0.60 on both shipped digital
humans: the hips on the seat, the shanks near vertical). The COM map's seated knot when a recording starts after the
human has left the seat."""
LEAD_IN_COM_SPEED_MPS = 0.2
"""Mean forward COM speed [m/s] of the lead-in that a recording starting mid-rise gets (the shipped natural rise
moves its COM 0.26 m in ~1.3 s)."""
MIN_LEAD_IN_S = 0.5
RISE_SCALE_RANGE = (0.8, 1.5)
"""The markers' vertical scale stays within these multiples of the leg-length scale (``Retargeter._rise_scale``)."""
REARM_ABOVE_SEAT_M = 0.01
"""After a sit-down, a plan whose held point (``held_on_seat_b``) is back within this [m] of its seated height is
seated again, its hips held on the seat and its COM target no further back than there: the next rise plays as the
first (a trial of several sit-stand-sit cycles). Left to follow the human's COM back with the hips held, TALOS tipped
backward; seated again only once the human's COM stopped, G1 sank off its seat."""
KNEE_RELEASE_DROP_M = 0.05
"""Once the human's pelvis is this far below its highest, the human is sitting back down: the knee task lets go and
the markers' vertical scale returns to the leg-length one as the pelvis comes down (at the rise's scale all the
way down, the robot fell back onto its seat)."""
KNEE_RAMP_POWER = 2.0
"""The knee task's weight grows with the human's knee extension from its seated flexion, to this power: full only as
the human stands, so that it straightens the end posture without steering the rise."""


def smoothstep(u: float) -> float:
    """3u^2 - 2u^3 of ``u`` clipped to [0, 1]: a ramp from 0 to 1 that starts and ends at rest."""
    u = min(1.0, max(0.0, u))
    return u * u * (3 - 2 * u)


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
    seat_off_ahead_m: float = 0.01        # ... and this far ahead of its seated COM (docs/method.md, COM mapping)
    toe_margin_m: float = 0.10            # the COM target stays this far behind the robot's toes (2.5 cm ahead of
    #                                       the ankle, where the shipped rises end): a child's COM is 8 cm ahead of
    #                                       its ankles, 12.5 cm scaled to TALOS; at 8 cm the live robot fell 1 in 3
    velocity_limit_rad_s: float = 4.0
    marker_set: str | None = None         # a packaged set's name or a YAML file; None: chosen from the names
    momentum_weight: float = 0.0          # the IK's angular momentum term (a ZMP shift [m] against marker metres)
    stop_torque_share: float | None = 1.0  # a trunk, head or arm joint stays on its stop while gravity presses it
    #                                        there past this share of its effort limit (ik.ComIk; None: off)
    lift_torque_share: float | None = LIFT_TORQUE_SHARE   # ... and accelerates against gravity with at most this
    #                                        share of its limit (ik.ComIk; None: unbounded)
    chair_off_force_n: float = 30.0       # human left the seat when the chair plate reads less
    pelvis_rise_m: float = 0.02           # ... or, without a chair plate, when the pelvis markers rose this much
    y_ramp_s: float = 0.5
    hip_release_s: float = 0.4            # the hips' hold on the seat fades out over this after seat-off
    seat_clearance_m: float = 0.02        # after the robot's seat-off its pelvis stays at least this far above its
    #                                       seated height: hips the plan has taken off the seat must be off it
    seat_clearance_s: float = 0.3         # ... reached along a smoothstep over this [s of human time]
    knee_weight: float = 3.0              # after seat-off, both robot knees pulled toward the human's knee flexion
    #                                       [1/rad^2], ramped in as the human's pelvis rises: with the markers alone
    #                                       the robot ended its rise in a squat (knees 71 degrees, the human's 8)
    iterations: int = 2                   # Gauss-Newton steps per frame (warm-started from the previous frame)
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
    markers: MarkerTargets | list = field(default_factory=list)     # the marker tasks solved
    human_knee_flexion_rad: float | None = None     # the human's (left) knee flexion in the frame, from its markers


class Retargeter:
    """Per-frame human -> robot retargeting (see the module docstring). After :meth:`calibrate`: ``com_map``,
    ``markers`` and ``human`` hold what the calibration frame fixed, ``watch`` what the human has shown since,
    ``seat_off`` the robot's seat-off (None while seated)."""

    def __init__(self, robot: RobotSetup, cfg: RetargetConfig | None = None) -> None:
        self.robot = robot
        self.cfg = cfg or RetargetConfig()
        self.model = pin.Model(robot.model)         # marker frames are added to a copy
        self.data = self.model.createData()
        self.ik: ComIk | None = None
        self.com_map: ComMap | None = None
        self.markers: MarkerTasks | None = None
        self.human: HumanSeated | None = None
        self.watch: HumanWatch | None = None
        self.seat_off: RobotSeatOff | None = None
        self.q, self.seated = robot.q_seated.copy(), True
        self.sat_down = False           # the human sat back down after standing: the plan is on the seat again
        pin.centerOfMass(self.model, self.data, self.q)
        self.com_seated = self.data.com[0].copy()
        self.hold_point_b = held_on_seat_b(self.model)       # the base's point held on the seat [m]
        self.base_seated = self._held_point(self.q)
        self.held_z_seated_m = float(self.base_seated[2])   # the held point's seated height [m]
        self._com_x_floor: float | None = None  # seated again after a sit-down: the COM target goes no further back
        self.pitch_seated = float(np.arctan2(*pin.Quaternion(self.q[3:7]).toRotationMatrix()[[0, 2], 2]))
        self.held_to_seated = np.zeros(self.model.nq, bool)     # arms, head, lateral joints: posture pulled to seated
        self.knees: list = []

    @property
    def calibrated(self) -> bool:
        return self.com_map is not None

    @property
    def human_seat_off(self) -> bool:
        """Whether the human has left the seat (the chair plate unloaded, or the pelvis markers risen)."""
        return self.watch is not None and self.watch.seat_off

    # -- calibration -------------------------------------------------------------------------------------------
    def calibrate(self, names: list[str], positions_m: np.ndarray, valid: np.ndarray, human_com_m: np.ndarray,
                  marker_map: MarkerMap | None = None, frame_period_s: float = 0.01,
                  human_flexion_deg: dict[str, float] | None = None) -> MarkerMap:
        """Fix the markers to the robot (or use ``marker_map``) from one seated frame; note the human's references.

        ``frame_period_s``: the capture's frame period [s], the time one frame stands for. The IK's joint-speed
        limit and trunk lift-off bound are per frame, so they need it; the player plays each pose for the same time.

        The marker set (``cfg.marker_set``, else chosen from ``names``) says which markers are the pelvis, the left
        knee, ankle and heel, and each marker's body part (:func:`~sit2stand.retarget.calibration.marker_roles`).
        A frame after the human's seat-off is overlaid on the robot posed at the human's sagittal flexions
        ``human_flexion_deg`` (:func:`~sit2stand.retarget.calibration.posed_like`; None: on its seated posture).

        Raises:
            ValueError: a marker the calibration needs (pelvis, left knee, ankle, heel) is missing in the frame.
        """
        if not (np.isfinite(frame_period_s) and 0.0 < frame_period_s * MIN_RATE_HZ <= 1.0):
            raise InputError(f"frame period {frame_period_s!r} s: the capture rate must be at least {MIN_RATE_HZ:g} Hz")
        markers = choose_marker_set(names, self.cfg.marker_set)
        roles = marker_roles(markers)
        pelvis, pel, knee, ankle, heel = left_leg_points(roles, names, positions_m, valid, markers)
        thigh = float(np.linalg.norm(knee - pelvis))
        human_leg = float(np.linalg.norm(knee - pelvis) + np.linalg.norm(ankle - knee))
        scale = self.robot.leg_length_m / human_leg
        started_seated = human_com_m[0] < heel[0] and heel[0] < ankle[0]
        overlay = self.robot.q_seated if started_seated or human_flexion_deg is None else \
            posed_like(self.robot.model, self.robot.q_seated, human_flexion_deg)
        if marker_map is None:
            marker_map = calibrate_markers(self.robot.model, overlay, names, positions_m, valid,
                                           human_leg, self.robot.leg_length_m, roles=roles)
        frames = marker_map.add_frames(self.model)
        self.data = self.model.createData()
        self._make_ik(frame_period_s)
        # the left knee's and ankle's marker indices, looked up once: the knee flexion is read every frame
        knee_ankle = [[names.index(m) for m in group if m in names] for group in (roles.knee, roles.ankle)]
        knee_seated = knee_flexion(knee_ankle, positions_m, valid & np.all(np.isfinite(positions_m), axis=1),
                                   pelvis) or np.pi / 2
        # forward-axis knots of the COM map (robot x relative to its left ankle vs scaled human x relative to its)
        ax, rx = ankle[0], self.robot.ankle_left[0]
        foot = self.robot.toe_x_m - self.robot.heel_x_m
        # a frame whose COM is not behind the heel is after the human's seat-off: the seated knot then comes from
        # the body's proportions, and a lead-in (see :meth:`lead_in`) takes the robot from its seat to this frame
        # a recording that starts mid-rise has no seated pelvis to scale the rise from: leg lengths alone
        rise = self._rise_scale(pelvis, knee, ankle, human_leg, scale) if started_seated else scale
        seated_com_x = float(human_com_m[0] if started_seated else ax - SEATED_COM_BEHIND_ANKLE_THIGHS * thigh)
        h = [scale * (seated_com_x - ax), scale * (heel[0] - ax), 0.0]
        r = [self.com_seated[0] - rx, self.robot.heel_x_m + self.cfg.seat_off_fraction * foot - rx, 0.0]
        # a knot behind the one before moves up to it (iCub's seat-off knot, 30 % along its short feet, is 1.7 cm
        # ahead of its ankle; Alexander sits past its seat-off point): the map stays monotone
        r[1] = max(r[1], r[0] + self.cfg.seat_off_ahead_m)
        r[2] = max(r[2], r[1])
        if not h[0] < h[1] < h[2]:
            raise InputError(f"calibration frame: the human's seated COM ({seated_com_x:.3f} m), heel "
                             f"({heel[0]:.3f} m) and ankle ({ax:.3f} m) are not in that order along x")
        weights = np.array([0.0 if n not in frames else self.cfg.weights.get(roles.group(n), 0.0) for n in names])
        self.markers = MarkerTasks(marker_map, frames, list(names), weights,
                                   np.array([frames.get(n, -1) for n in names], int), pel, knee_ankle,
                                   np.array([scale, scale, rise]), pelvis, overlay[:3].copy())
        self.human = HumanSeated(thigh, knee_seated, seated_com_x, started_seated)
        self.watch = HumanWatch(pelvis, seat_off=not started_seated)
        self.com_map = ComMap(scale, ax, rx, np.array(h), np.array(r))
        return marker_map

    def _make_ik(self, frame_period_s: float) -> None:
        """The per-frame IK on the model with its marker frames; arms, head and the lateral joints regularised
        toward the seated posture (the rest: toward the previous frame)."""
        mu = np.full(self.model.nv, self.cfg.posture_weight)
        self.held_to_seated = np.zeros(self.model.nq, bool)
        profile = profile_of(self.model)
        lateral = set(profile.lateral_joints())
        for j in range(2, self.model.njoints):
            name, jt = self.model.names[j], self.model.joints[j]
            w = self.cfg.upper_limb_weight if profile.is_upper_limb(name) else \
                self.cfg.lateral_weight if name in lateral else None
            if w is not None:
                mu[jt.idx_v:jt.idx_v + jt.nv] = w
                self.held_to_seated[jt.idx_q:jt.idx_q + jt.nq] = True
        self.knees = [self.model.joints[self.model.getJointId(profile.leg(s, "knee"))] for s in SIDES]
        self.ik = ComIk(self.model, self.robot.sole_frames, self.cfg.velocity_limit_rad_s, posture_weight=mu,
                        damping=self.cfg.damping, momentum_weight=self.cfg.momentum_weight,
                        stop_torque_share=self.cfg.stop_torque_share,
                        lift_torque_share=self.cfg.lift_torque_share, dt=frame_period_s,
                        hold_point_b=self.hold_point_b)

    def _rise_scale(self, pelvis: np.ndarray, knee: np.ndarray, ankle: np.ndarray, human_leg: float,
                    scale: float) -> float:
        """The markers' vertical scale: the robot's pelvis rise from its seat to its straight-legged stance over the
        human's (each stance estimated as the ankle's height plus the leg's length, from a seated frame), within
        ``RISE_SCALE_RANGE`` of the leg-length ``scale``. Scaled by leg length alone, the rise fell short (a robot's
        seated posture is not the human's: TALOS's shanks lean 40 degrees back), and the robot ended bowed at the
        hips with its pelvis at 84-92 % of its stance. The human's seated leg (pelvis centre -> knee -> ankle)
        underestimates its standing one, so on the shipped demonstrations the ratio meets the range's top."""
        robot = self.robot
        data = robot.model.createData()
        pin.forwardKinematics(robot.model, data, robot.q_seated)
        hip = data.oMi[robot.model.getJointId(profile_of(robot.model).leg("left", "hip_pitch"))].translation
        robot_rise = robot.ankle_height_m + robot.leg_length_m - hip[2]
        human_rise = ankle[2] + human_leg - pelvis[2]
        if not (robot_rise > 0 and human_rise > 0):
            return scale
        return float(np.clip(robot_rise / human_rise, *(np.array(RISE_SCALE_RANGE) * scale)))

    def com_target_x(self, human_com_x_m: float | np.ndarray) -> np.ndarray:
        """The robot's forward COM target [m] for a human COM x [m] (lab), through the COM map, at most
        ``toe_margin_m`` behind the robot's toes."""
        return self.com_map.target_x(human_com_x_m, self.robot.toe_x_m - self.cfg.toe_margin_m)

    def lead_in(self, t0_s: float, dt: float, positions_m: np.ndarray, valid: np.ndarray, human_com_m: np.ndarray,
                human_com_vx_mps: float = 0.0, on_frame=None) -> list[RetargetFrame]:
        """The frames that take the robot from its seat to the calibration frame when the recording starts after
        the human left the seat (none when it starts seated).

        The human COM is led from the seated knot to the first frame's along a cubic (at rest at the start, at the
        frame's own forward velocity at the end) over ``max(MIN_LEAD_IN_S, distance / LEAD_IN_COM_SPEED_MPS)``,
        while the first frame's markers fade in (weight 0 -> 1, smoothstep) and their targets move from the seated
        robot's marker sites to the frame's along the same smoothstep; the hips stay on the seat until the
        robot's COM target passes the seat-off knot, as in a recording that starts seated. The frames are stamped
        before ``t0_s``, every ``dt``; ``on_frame`` is called with each as it is made.
        """
        if self.human.started_seated:
            return []
        x0, x1 = self.human.com_x_m, float(human_com_m[0])
        duration = max(MIN_LEAD_IN_S, (x1 - x0) / LEAD_IN_COM_SPEED_MPS)
        n = int(round(duration / dt))
        gap, frames = self._targets_from_here(positions_m), []
        for k in range(n):
            u, ease = k / n, smoothstep(k / n)   # Hermite: from rest at x0 to x1, arriving with the human's COM speed
            x = x0 + (x1 - x0) * ease + human_com_vx_mps * duration * (u**3 - u**2)
            com = np.array([x, human_com_m[1], human_com_m[2]])
            frames.append(self.step(t0_s - (n - k) * dt, positions_m, valid, com, None, marker_weight=ease,
                                    marker_shift_m=-(1.0 - ease) * gap))
            if on_frame is not None:
                on_frame(frames[-1])
        return frames

    def _targets_from_here(self, positions_m: np.ndarray) -> np.ndarray:
        """(M, 3) [m] each marker's target for ``positions_m`` less its robot site in the current pose (0: a marker
        not on the robot, or not seen)."""
        mk, gap = self.markers, np.zeros((len(self.markers.names), 3))
        pin.framesForwardKinematics(self.model, self.data, self.q)
        on = np.flatnonzero(mk.frame_ids >= 0)
        gap[on] = mk.targets(positions_m[on], mk.scale) - [self.data.oMf[int(mk.frame_ids[i])].translation for i in on]
        return np.where(np.isfinite(gap), gap, 0.0)

    # -- per frame ---------------------------------------------------------------------------------------------
    def step(self, t_s: float, positions_m: np.ndarray, valid: np.ndarray, human_com_m: np.ndarray,
             chair_force_n: float | None = None, marker_weight: float = 1.0,
             marker_shift_m: np.ndarray | None = None) -> RetargetFrame:
        """Retarget one frame (the first call calibrates). ``chair_force_n``: the chair plate's vertical force, if
        there is a chair plate (None: seat-off from the pelvis markers). ``marker_weight`` scales every marker's
        weight and ``marker_shift_m`` (M, 3) [m] moves their targets (the lead-in's)."""
        if not self.calibrated:
            raise RuntimeError("Retargeter.step before calibrate")
        cfg, robot, mk = self.cfg, self.robot, self.markers
        ok = valid & np.all(np.isfinite(positions_m), axis=1)
        self._watch_seat_off(positions_m, ok, chair_force_n)
        target = self.com_seated.copy()
        target[0] = float(self.com_target_x(human_com_m[0]))
        pel = [i for i in mk.pelvis if ok[i]]
        pelvis_now = positions_m[pel].mean(axis=0) if pel else self.watch.pelvis_last_m
        self.watch.pelvis_last_m = pelvis_now
        if not self.seated and not self.sat_down:
            self.sat_down = self._human_touched_down(pelvis_now, chair_force_n)
        elif self.sat_down and self._held_point(self.q)[2] < self.held_z_seated_m + REARM_ABOVE_SEAT_M:
            self._seated_again()
            self._com_x_floor = float(target[0])
        if self._com_x_floor is not None:        # seated again: the COM stays where the hips landed, or ahead
            target[0] = max(target[0], self._com_x_floor)
        if self.seated and self.watch.seat_off and target[0] >= self.com_map.seat_off_x_m - 1e-3:
            self._leave_seat(t_s, pelvis_now)
        mid_y = float(np.mean([X.translation[1] for X in robot.sole_targets]))
        axes = (0,) if self.seated else (0, 1)
        if not self.seated:
            y0 = self.seat_off.com_y_m
            target[1] = y0 + self._since_seat_off(t_s, cfg.y_ramp_s) * (mid_y - y0)
        markers, knees, flexion = self._marker_tasks(positions_m, ok, pelvis_now, marker_weight, marker_shift_m)
        # hips on the seat: x and z held (hard); after seat-off the hold fades out as a soft task, so that
        # the pose does not jump to where the human's pelvis already is
        hold, weight, z_min = self.base_seated, None, None
        if not self.seated:
            fade = (t_s - self.seat_off.t_s) / max(cfg.hip_release_s, 1e-9)
            weight = 1e4 * (1.0 - min(1.0, fade)) ** 2 if fade < 1.0 else None
            lift = 0.0 if self.sat_down else self.seat_clearance(t_s)
            z_min = None if self.sat_down else self.held_z_seated_m + lift
            hold = self.base_seated + [0.0, 0.0, lift] if weight is not None else None
        q_ref = np.where(self.held_to_seated, robot.q_seated, self.q)
        res = self.ik.solve(self.q, markers, target, robot.sole_targets, q_ref=q_ref, com_axes=axes,
                            q_prev=self.q, max_iterations=cfg.iterations, tol=cfg.tolerance, base_xz=hold,
                            base_weight=weight, base_pitch_min=self.pitch_seated if self.seated else None,
                            base_z_min=z_min, joint_targets=knees)
        self.q = res.q
        pin.centerOfMass(self.model, self.data, self.q)
        return RetargetFrame(t_s, res.q, target, axes, self.data.com[0].copy(), self.seated or self.sat_down,
                             self.watch.seat_off, res, markers, flexion)

    def _watch_seat_off(self, positions_m: np.ndarray, ok: np.ndarray, chair_force_n: float | None) -> None:
        """The human's seat-off: the chair plate unloaded after it was loaded, or without one, the pelvis markers
        risen ``pelvis_rise_m`` over their seated height."""
        watch, cfg = self.watch, self.cfg
        if watch.seat_off:
            return
        if chair_force_n is not None and np.isfinite(chair_force_n):
            watch.chair_loaded |= chair_force_n > 2 * cfg.chair_off_force_n
            watch.seat_off = watch.chair_loaded and chair_force_n < cfg.chair_off_force_n
        else:
            pel = [i for i in self.markers.pelvis if ok[i]]
            if pel:
                rise = positions_m[pel, 2].mean() - self.markers.human_pelvis0_m[2]
                watch.seat_off = rise > cfg.pelvis_rise_m

    def _leave_seat(self, t_s: float, pelvis_now: np.ndarray) -> None:
        """The robot's seat-off: its COM's lateral target ramps from where it is; the human's pelvis has already
        moved (the robot leaves the seat later): that displacement is taken out of the marker targets and given
        back as the human's pelvis rises, so the robot's pelvis does not lunge."""
        self.seated, self._com_x_floor = False, None
        pin.centerOfMass(self.model, self.data, self.q)
        mk = self.markers
        self.seat_off = RobotSeatOff(t_s, float(self.data.com[0][1]), mk.scale * (pelvis_now - mk.human_pelvis0_m),
                                     pelvis_now[2])

    def _marker_tasks(self, positions_m: np.ndarray, ok: np.ndarray, pelvis_now: np.ndarray, marker_weight: float,
                      shift_m: np.ndarray | None = None) -> tuple[MarkerTargets, list, float | None]:
        """The frame's marker targets (the calibration's similarity, fixed for the whole demonstration), the knee
        targets, and the human's knee flexion [rad]."""
        mk, watch = self.markers, self.watch
        rise = pelvis_now[2] - mk.human_pelvis0_m[2]
        scale = mk.scale.copy()
        if self.sat_down or watch.rise_peak_m - rise > KNEE_RELEASE_DROP_M:   # sitting back down
            share = np.clip(rise / max(watch.rise_peak_m, 1e-6), 0.0, 1.0)
            scale[2] = self.com_map.scale + share * (scale[2] - self.com_map.scale)
        tgt = mk.targets(positions_m, scale) + (0.0 if shift_m is None else shift_m)
        knees = []
        flexion = mk.knee_flexion(positions_m, ok, pelvis_now)
        if not self.seated:
            off = self.seat_off
            progress = np.clip((pelvis_now[2] - off.pelvis_z_m) / (0.9 * self.human.thigh_m), 0.0, 1.0)
            tgt = tgt - (1.0 - progress) * off.marker_offset_m
            lowering = watch.rise_peak_m - (pelvis_now[2] - mk.human_pelvis0_m[2]) > KNEE_RELEASE_DROP_M
            knees = [] if lowering else self._knee_targets(flexion, marker_weight)
        use = ok & (mk.weights > 0) & (marker_weight > 0)
        return MarkerTargets(mk.frame_ids[use], tgt[use], marker_weight * mk.weights[use]), knees, flexion

    def _knee_targets(self, flexion: float | None, share: float) -> list[tuple[int, float, float]]:
        """Both robot knees' soft targets at the human's knee ``flexion`` [rad], weighted ``knee_weight`` x
        ``share`` x (how far the human's knee has extended from its seated flexion) ** ``KNEE_RAMP_POWER``."""
        if flexion is None or self.sat_down or self.cfg.knee_weight <= 0 or share <= 0:
            return []
        seated = max(self.human.knee_flexion_rad, 1e-3)
        share *= float(np.clip((seated - flexion) / seated, 0.0, 1.0)) ** KNEE_RAMP_POWER
        lo, hi = self.model.lowerPositionLimit, self.model.upperPositionLimit
        return [(j.idx_v, float(np.clip(flexion, lo[j.idx_q], hi[j.idx_q])), self.cfg.knee_weight * share)
                for j in self.knees]

    def seat_clearance(self, t_s: float) -> float:
        """How far above its seated height the held point must be at ``t_s`` [s] after the robot's seat-off [m]
        (``seat_clearance_m`` along a smoothstep over ``seat_clearance_s``)."""
        return self.cfg.seat_clearance_m * self._since_seat_off(t_s, self.cfg.seat_clearance_s)

    def _held_point(self, q: np.ndarray) -> np.ndarray:
        """The world position [m] of the base's ``hold_point_b`` at ``q``."""
        return q[:3] + pin.Quaternion(q[3:7]).toRotationMatrix() @ self.hold_point_b

    def _since_seat_off(self, t_s: float, duration_s: float) -> float:
        """A 0 -> 1 smoothstep over ``duration_s`` [s] from the robot's seat-off."""
        return smoothstep((t_s - self.seat_off.t_s) / max(duration_s, 1e-9))

    def _seated_again(self) -> None:
        """After a sit-down, the plan's held point back within ``REARM_ABOVE_SEAT_M`` of the seat: the next rise starts
        as the first (hips held on the seat where they are, the human's seat-off awaited, then the robot's), so a
        trial of several cycles plays each one."""
        self.seated, self.sat_down = True, False
        # the sit-down loaded the chair (with a plate): its unloading is the seat-off
        self.watch.seat_off, self.watch.chair_loaded, self.watch.rise_peak_m = False, True, 0.0
        self.seat_off = None
        self.base_seated = np.r_[self._held_point(self.q)[:2], self.held_z_seated_m]   # where it is, on the seat
        R = pin.Quaternion(self.q[3:7]).toRotationMatrix()
        self.pitch_seated = min(self.pitch_seated, float(np.arctan2(R[0, 2], R[2, 2])))

    def _human_touched_down(self, pelvis_m: np.ndarray, chair_force_n: float | None) -> bool:
        """After the rise, has the human sat back down? The chair plate loaded again (over twice the seat-off
        threshold), or without one, the pelvis markers back within ``pelvis_rise_m`` of their seated height after
        rising over five times that. From then on the plan's frames are seated again (the chair takes the load: no
        ZMP criterion, the seat in the torque criterion); the IK keeps following the markers and the COM map,
        which bring the hips back onto the seat."""
        cfg, watch = self.cfg, self.watch
        rise = float(pelvis_m[2] - self.markers.human_pelvis0_m[2])
        watch.rise_peak_m = max(watch.rise_peak_m, rise)
        if watch.rise_peak_m < 5 * cfg.pelvis_rise_m:
            return False
        if chair_force_n is not None and np.isfinite(chair_force_n):
            return chair_force_n > 2 * cfg.chair_off_force_n
        return rise < cfg.pelvis_rise_m


def retarget_sequence(retargeter: Retargeter, player: PlanPlayer, t_s: np.ndarray, positions_m: np.ndarray,
                      valid: np.ndarray, human_com_m: np.ndarray, chair_force_n: np.ndarray | None = None,
                      pull: bool = True) -> tuple[list[RetargetFrame], list[Command]]:
    """A whole recorded demonstration through a calibrated ``retargeter`` and a ``player``, as the node streams it:
    one pull per frame, then the rest of the (retimed) plan; a recording that starts after the human left the seat
    is led in first (:meth:`Retargeter.lead_in`). Returns (frames, commands), lead-in frames included. ``pull``
    False: the poses only (the player closed, its commands left for a caller that pulls them with the robot's lag,
    as :func:`sit2stand.retarget.offline.run` does when it simulates)."""
    frames, cmds = [], []

    def play(f: RetargetFrame) -> None:
        frames.append(f)
        c = player.pull(coming=1) if pull else None     # the command first, then the pose (as the node does)
        player.push(f.q, not f.seated)
        if c is not None:
            cmds.append(c)

    vx0 = float(np.gradient(human_com_m[:, 0], t_s)[0]) if len(t_s) > 1 else 0.0
    for f in retargeter.lead_in(float(t_s[0]), float(np.median(np.diff(t_s))), positions_m[0], valid[0],
                                human_com_m[0], vx0):
        play(f)
    for k, t in enumerate(t_s):
        fz = None if chair_force_n is None else float(chair_force_n[k])
        play(retargeter.step(float(t), positions_m[k], valid[k], human_com_m[k], fz))
    player.close()
    while pull and not player.done:
        cmds.append(player.pull())
    return frames, cmds
