"""The plan player: the dynamic-feasibility stage between the per-frame IK and the robot's joint commands.

It smooths the poses (Savitzky-Golay on the tangent coordinates, ``smooth_s`` wide), computes each pose's ZMP from
the centroidal dynamics, and plays the plan back ``time_scale`` times slower, where ``time_scale`` is a local
factor. Each frame has its own smallest factor (:meth:`PlanPlayer.frame_scale`): its ZMP ``margin_m`` inside the
feet wherever the robot is off the chair, its joint speeds under ``max_joint_speed`` and its inverse-dynamics
torques within the URDF's limits (played s x slower, velocities scale by 1/s and accelerations and velocity products
by 1/s^2). With ``retiming="local"`` (the default) the factor rises just in time for each frame that needs more than
1, at a bounded rate, and comes back down once it is played: the human's timing is kept wherever the robot can
follow it. With ``retiming="uniform"`` it is one factor that only grows, up to ``max_time_scale``. At the robot's
seat-off the player can dwell ``seat_off_dwell_s``. Each command carries positions, velocities and accelerations
(time-warp included). Live, the commands lag the human by ``lookahead_s`` plus half the smoothing window, plus the
stretching.

Units SI; world frame REP-103 (x forward, y left, z up).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import pinocchio as pin
from scipy.signal import savgol_coeffs   # at import: a live node's first frames must not pay for it

from ..dynamics import model_cop, savgol_frames
from ..errors import InputError
from ..robot.profile import profile_of
from ..robot.plant import contact_joint_torques
from .dynamic import DynamicsFilter, FilterReport
from .feasibility import frame_time_scales, support_margin, zmp_at_scale

DEFAULT_MAX_TIME_SCALE = 4.0
"""The slowest the plan is played by default (x the human's timing); a parameter of the player, the node and the
``sit2stand retarget`` command."""
DEFAULT_MAX_JOINT_SPEED = 4.0
"""The plan's joint speed limit [rad/s]: the IK's own (:class:`~sit2stand.retarget.stream.RetargetConfig`), so that
by default the torques, not a speed, decide where time is stretched. The uniform player needs 0.6 to stand the
robot up."""
SEAT_OFF_DWELL_S = 0.0
"""The player's fixed wait at the robot's seat-off [s]; none by default: the lag of the robot behind the plan slows
the plan instead (``pull(lag_m=...)``). The uniform player needs 1 s."""
LAG_DEADBAND_M = 0.02
LAG_GAIN_PER_M = 100.0
"""Off the chair, a robot whose COM trails the plan's by more than ``LAG_DEADBAND_M`` slows the plan to at least
1 + ``LAG_GAIN_PER_M`` x the excess (2x at 3 cm): the plan waits for the robot. Measured: the real child trial
under CAD's parameters (its true COM 2.5 cm behind the model's) fell at the human's timing after seat-off, the COM
feedback at its bound; a fixed 0.5 s wait at seat-off made it stand. 2 cm, not 1: under torque control with CAD's
parameters on the default plant (26 kg the model lacks) the robot trails its plan by up to 2.2 cm for 0.3 s after
its seat-off and then catches up by itself; waiting from 1 cm slowed TALOS's natural rise to 1.056 (2 cm: 1.041,
the child 1.156 -> 1.112, G1 1.026 -> 1.018), and at 2 cm the 30-body CAD population still stands 30 of 30 (time
scale p90 1.06 -> 1.05); the population with identified parameters is unchanged (the shipped elderly rise with
them 1.073 -> 1.058)."""
MAX_TIME_SCALE_RATE = 20.0
"""How fast the time scale may change [1/s of robot time]. A change adds v_plan * d(1/s)/dt to the accelerations,
which the commands carry and their ZMP includes; ramps are what local retiming costs (measured on the shipped
rises with a 4 cm margin: duration ratio natural 1.66 / elderly 1.37 at 3/s, 1.25 / 1.13 at 10/s, 1.19 / 1.09 at
20/s, all standing)."""
LOOKAHEAD_S = 0.5
"""How far ahead of the playback point the player knows the plan [s]: enough for the local time scale to ramp from
1 to ``DEFAULT_MAX_TIME_SCALE`` at ``MAX_TIME_SCALE_RATE`` before the frame that needs it (0.15 s); live, the
commands lag the human by this much more."""
SMOOTH_S = 0.3
"""The plan's Savitzky-Golay window [s] (31 frames at 100 Hz), the human COM's (``human.com.WINDOW_S``). In seconds,
not frames: a 200 Hz capture of the elderly rise smoothed over 21 frames (0.1 s) carried the marker noise into its
accelerations, and the ZMP and torque criteria read it as a need to slow down (time scale 1.25 at 200 Hz, 1.10 at
100 Hz). 0.3 s rather than 0.2: the population's time scale p90 1.30 -> 1.25 (joint PD) and 1.29 -> 1.23 (torque
control), COM tracking p90 1.05 -> 0.97 cm (PD); the plan's COM stays within 0.5 cm of the mapped human's."""
DEFAULT_MARGIN_M = 0.04
"""The ZMP's margin inside the feet [m]: what joint PD with an inverse-dynamics feed-forward was measured to need
(../shared/notes/robot-talos.md); the uniform player used 6 cm."""
STOP_REACH_RAD = 0.1
"""A joint this close to a position limit, its static torque pressing it into that stop, is left out of the torque
criterion, as one whose static torque alone is past its limit, unless the plan lifts it off (``LIFT_OFF_SPEED_RAD_S``):
the stop carries the load while the joint rests on it, and a joint landing on it lands a little early (the plan takes
it there next). Measured on the elderly rise: the torso pitch, leaning onto its stop with 77 of its 78 N m static, held
the plan at the cap for 0.1 s of human time (time scale 1.18, then 1.07)."""
ON_STOP_RAD = 1e-4
"""A joint the IK's pose (before smoothing) puts this close to a position limit is on that stop."""
LIFT_OFF_SPEED_RAD_S = 0.05
"""A joint within ``STOP_REACH_RAD`` of a stop its static torque presses it into, moving away from that stop faster
than this in the plan, is lifting off: its motor bears static and motion torque alone, and it counts in the torque
criterion. Left out, the CAD plant's trunk lifted off with ~1 N m above gravity at the plan's pace, lagged, and the
natural rise fell. Slower, it still rests on the stop: the IK starts a trunk's lift from rest
(``ik.LIFT_TORQUE_SHARE``), and its first frames, micro-radians apiece, would otherwise count the hips' pull on the
resting trunk as the motor's (the elderly rise 1.10 -> 1.13)."""
RETIMING = ("local", "uniform")


@dataclass
class Command:
    """One joint command of the played plan."""

    t_plan_s: float              # the human time it plays
    q: np.ndarray                # full Pinocchio configuration
    v: np.ndarray                # (nv,) [rad/s, m/s]
    a: np.ndarray                # (nv,)
    time_scale: float
    com: np.ndarray              # planned COM [m]
    zmp: np.ndarray              # the command's ZMP [m] on the floor (its accelerations, time warp included)
    margin_m: float              # its distance inside the feet (negative: outside); inf while seated
    on_feet: bool
    margin_at_scale_m: float = np.inf   # the frame's ZMP margin played uniformly at this time scale: the retiming's
    #                                     criterion (the warp's change of speed left out)
    com_kinematic: np.ndarray | None = None   # the kinematic plan's COM [m], when a dynamics filter changed it
    filter: FilterReport | None = None        # what the dynamics filter did


@dataclass(frozen=True)
class PlayerSettings:
    """A plan player's settings (see :class:`PlanPlayer`)."""

    margin_m: float = DEFAULT_MARGIN_M
    lookahead_s: float = LOOKAHEAD_S
    smooth_s: float = SMOOTH_S
    max_time_scale: float = DEFAULT_MAX_TIME_SCALE
    max_time_scale_rate: float = MAX_TIME_SCALE_RATE
    fixed_time_scale: float | None = None
    max_joint_speed: float = DEFAULT_MAX_JOINT_SPEED
    seat_off_dwell_s: float = SEAT_OFF_DWELL_S
    retiming: str = "local"
    torque_limited: bool = True
    planned_time_scale: float | None = None


@dataclass
class PlanFrames:
    """The plan as pushed and as smoothed, frame by frame at the human's timing: the IK's poses and whether each is
    on the feet; the smoothed poses (nq), velocities and accelerations (nv), on the feet; each frame's dynamics at
    its own timing (COM [m], COM acceleration [m/s^2], rate of angular momentum [N m]); and each frame's own smallest
    time scale."""

    raw_q: list[np.ndarray] = field(default_factory=list)
    raw_feet: list[bool] = field(default_factory=list)
    q: list[np.ndarray] = field(default_factory=list)
    v: list[np.ndarray] = field(default_factory=list)
    a: list[np.ndarray] = field(default_factory=list)
    feet: list[bool] = field(default_factory=list)
    dyn: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)
    s_req: list[float] = field(default_factory=list)


class TorqueCriterion:
    """The torque criterion of a frame's time scale: the joints that carry the body (legs, trunk) within the URDF
    effort limits. The upper limbs' own motors (TALOS's shoulders, 22 N m) bound the natural rise in 20 of its 60
    slowed frames for a swing that moves the COM little: they lag there instead, within their limits, as the
    whole-body controller keeps them."""

    def __init__(self, model: pin.Model) -> None:
        self.model, self.data = model, model.createData()
        self.limits = model.effortLimit[6:].copy()
        self.carries_body = np.ones(model.nv - 6, bool)
        for j in range(2, model.njoints):
            if profile_of(model).is_upper_limb(model.names[j]):
                self.carries_body[model.joints[j].idx_v - 6] = False
        self.q_index = np.array([model.joints[j].idx_q for j in range(2, model.njoints)])     # joint i -> its q

    def scale(self, q: np.ndarray, raw_q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, seated: bool) -> float:
        """Smallest time scale keeping a frame's torques of the legs and trunk (contact-consistent inverse dynamics
        at pose ``q``, joint velocities ``qd`` and accelerations ``qdd``, the chair taking load while ``seated``)
        within the URDF effort limits. Played s x slower, tau = tau_static + tau_motion / s^2; a joint whose static
        torque alone is past its limit, or one resting on its stop, cannot be helped by slowing down and is left
        out."""
        model, data = self.model, self.data
        v, a = np.zeros(model.nv), np.zeros(model.nv)
        v[6:], a[6:] = qd, qdd
        gravity = pin.computeGeneralizedGravity(model, data, q).copy()
        full = pin.rnea(model, data, q, v, a)
        static, motion = contact_joint_torques(model, data, q, np.stack([gravity, full - gravity]), seated)
        room = self.limits - np.sign(motion) * static
        need = np.where((room > 0) & self.carries_body, np.abs(motion) / np.maximum(room, 1e-9), 0.0)
        need[self.resting_on_stop(q, raw_q, v[6:], static)] = 0.0
        return float(np.sqrt(max(1.0, need.max())))

    def resting_on_stop(self, q: np.ndarray, raw_q: np.ndarray, v: np.ndarray, static: np.ndarray) -> np.ndarray:
        """The joints of a smoothed pose ``q`` within ``STOP_REACH_RAD`` of a position limit whose static torque
        presses them into it (a stop at the upper limit pushes back with negative torque: such a joint needs negative
        torque), and which the plan (joint speeds ``v`` [rad/s]) does not lift off it faster than
        ``LIFT_OFF_SPEED_RAD_S``, or which the IK's own pose ``raw_q`` holds on the stop (``ON_STOP_RAD``): the
        smoothing's fit of a joint that lands on its stop and stays overshoots the limit and comes back at ~0.15 rad/s,
        a lift-off that is not one (TALOS's trunk at 45 degrees on the natural rise: counted, it slowed the seat-off
        2.6 times)."""
        qj, raw = q[self.q_index], raw_q[self.q_index]
        lo, hi = self.model.lowerPositionLimit[self.q_index], self.model.upperPositionLimit[self.q_index]
        on_hi = (hi - qj < STOP_REACH_RAD) & (static < 0) & ((v > -LIFT_OFF_SPEED_RAD_S) | (hi - raw < ON_STOP_RAD))
        on_lo = (qj - lo < STOP_REACH_RAD) & (static > 0) & ((v < LIFT_OFF_SPEED_RAD_S) | (raw - lo < ON_STOP_RAD))
        return on_hi | on_lo


class PlanPlayer:
    """Smooths, checks and retimes a stream of IK poses (see the module docstring).

    ``push`` one pose per human frame (period ``dt``); ``pull`` once per output tick (same period) returns the next
    command, or None while the look-ahead fills. ``fixed_time_scale`` set: no adaptation (1.0: the human's
    timing); ``max_time_scale`` caps the adaptation. ``torque_limited``: the torques count in each frame's factor
    (the model's URDF effort limits). ``planned_time_scale``: the scale the plan was made at (a whole-rise
    optimisation's, :mod:`sit2stand.retarget.whole_rise`): every frame needs at least it."""

    def __init__(self, model: pin.Model, dt: float, polygon_xy: np.ndarray, *, margin_m: float = DEFAULT_MARGIN_M,
                 lookahead_s: float = LOOKAHEAD_S, smooth_s: float = SMOOTH_S,
                 max_time_scale: float = DEFAULT_MAX_TIME_SCALE, max_time_scale_rate: float = MAX_TIME_SCALE_RATE,
                 fixed_time_scale: float | None = None,
                 max_joint_speed: float = DEFAULT_MAX_JOINT_SPEED, seat_off_dwell_s: float = SEAT_OFF_DWELL_S,
                 dynamics: DynamicsFilter | None = None, retiming: str = "local", torque_limited: bool = True,
                 planned_time_scale: float | None = None) -> None:
        if retiming not in RETIMING:
            raise InputError(f"retiming {retiming!r}: one of {', '.join(RETIMING)}")
        self.cfg = PlayerSettings(margin_m, lookahead_s, smooth_s, max_time_scale, max_time_scale_rate,
                                        fixed_time_scale, max_joint_speed, seat_off_dwell_s, retiming, torque_limited,
                                        planned_time_scale)
        self.model, self.data = model, model.createData()
        self.dt = dt
        self.polygon = polygon_xy
        self.mass = float(pin.computeTotalMass(model))
        self.lookahead = max(0, int(round(lookahead_s / dt)))          # frames
        self.half = savgol_frames(smooth_s, dt, minimum=1) // 2       # frames either side
        self.dwell_pulls = int(round(seat_off_dwell_s / dt))
        self.dynamics = dynamics
        self.torque = TorqueCriterion(model) if torque_limited else None
        self.plan = PlanFrames()
        self._coef_cache: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self.u = 0.0              # playback point, in frames of the plan
        self.started = False
        self.finished = False
        self.pulled = 0.0             # periods played
        self._dwelt = 0
        self.time_scale = 1.0 if fixed_time_scale is None else float(fixed_time_scale)
        self.time_scale_goal = self.time_scale

    @property
    def max_time_scale(self) -> float:
        return self.cfg.max_time_scale

    def like(self, **changes) -> PlanPlayer:
        """A new, empty player with this one's model, settings and dynamics filter, but ``changes``."""
        settings = {**asdict(self.cfg), "dynamics": self.dynamics, **changes}
        return PlanPlayer(self.model, self.dt, self.polygon, **settings)

    # -- input -------------------------------------------------------------------------------------------------
    def push(self, q: np.ndarray, on_feet: bool) -> None:
        self.plan.raw_q.append(np.asarray(q, float).copy())
        self.plan.raw_feet.append(bool(on_feet))
        self._smooth_available(final=False)

    def close(self) -> None:
        """No more poses: the tail is smoothed with what there is and played to the end."""
        self._smooth_available(final=True)
        self.finished = True

    def _smooth_available(self, final: bool) -> None:
        """Savitzky-Golay fit (cubic) of the poses' tangent coordinates around each frame once its window is
        known: the smoothed pose and its velocity and acceleration from the same fit; then the frame's dynamics."""
        plan = self.plan
        n = len(plan.raw_q)
        model, dt = self.model, self.dt
        while len(plan.q) < n and (final or len(plan.q) + self.half < n):
            k = len(plan.q)
            half = min(self.half, k, n - 1 - k)
            ref = plan.raw_q[k]
            if half >= 2:
                X = np.array([pin.difference(model, ref, plan.raw_q[j]) for j in range(k - half, k + half + 1)])
                c0, c1, c2 = self._coefs(half)
                q, v, a = pin.integrate(model, ref, c0 @ X), c1 @ X / dt, c2 @ X / dt**2
            else:        # the ends of a closed plan: at rest
                q, v, a = ref, np.zeros(model.nv), np.zeros(model.nv)
            self._append(q, v, a, plan.raw_feet[k])

    def _append(self, q: np.ndarray, v: np.ndarray, a: np.ndarray, on_feet: bool) -> None:
        """A frame of the plan (pose, velocity, acceleration) and its dynamics: COM, COM acceleration and angular
        momentum rate, and the frame's own smallest time scale."""
        plan = self.plan
        plan.q.append(q)
        plan.v.append(v)
        plan.a.append(a)
        plan.feet.append(on_feet)
        pin.centerOfMass(self.model, self.data, q, v, a)
        com, acom = self.data.com[0].copy(), self.data.acom[0].copy()
        pin.computeCentroidalMomentumTimeVariation(self.model, self.data, q, v, a)
        # dL/dt's velocity-product and acceleration parts both scale with 1/s^2 when played s x slower
        plan.dyn.append((com, acom, self.data.dhg.angular.copy()))
        plan.s_req.append(self.frame_scale(len(plan.dyn) - 1))

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
        feet (none while the robot is on the chair), its joint speeds under ``max_joint_speed`` [rad/s] and, when
        ``torque_limited``, the inverse-dynamics torques of the joints that carry the body (not the upper limbs)
        within the URDF effort limits; at least
        ``planned_time_scale``."""
        cfg, plan = self.cfg, self.plan
        speed = float(np.abs(plan.v[k][6:]).max()) / cfg.max_joint_speed if cfg.max_joint_speed > 0 else 1.0
        s = 1.0
        if plan.feet[k]:
            com, acc, dl = plan.dyn[k]
            s = float(frame_time_scales(com, acc, dl, self.mass, self.polygon, cfg.margin_m, cfg.max_time_scale)[0])
        torque = 1.0 if self.torque is None else \
            self.torque.scale(plan.q[k], plan.raw_q[k], plan.v[k][6:], plan.a[k][6:], not plan.feet[k])
        return min(max(s, speed, torque, cfg.planned_time_scale or 1.0), cfg.max_time_scale)

    def required_scale(self, frames: range) -> float:
        """Smallest time scale keeping the ZMP ``margin_m`` inside the feet on all of ``frames`` (known ones)."""
        ks = [k for k in frames if k < len(self.plan.s_req)]
        return max((self.plan.s_req[k] for k in ks), default=1.0)

    def ready(self, coming: int = 0) -> bool:
        """Whether the look-ahead has filled (``coming``: see :meth:`pull`)."""
        return self.finished or len(self.plan.v) + coming >= self.lookahead + 2

    def pull(self, lag_m: float = 0.0, periods: float = 1.0, coming: int = 0) -> Command | None:
        """The next command; ``lag_m``: how far the robot's measured COM trails the plan's [m] (0: unknown), which
        slows the local plan once the robot is off the chair (``LAG_DEADBAND_M``, ``LAG_GAIN_PER_M``);
        ``periods``: the robot's time since the last command, in periods ``dt`` (live, a command can come late: the
        plan is where the robot's clock says, not one frame on).

        ``coming``: poses the caller pushes right after this pull, counted as known for the look-ahead's fill and
        the buffer (not played). A live caller sends a frame's command first and pushes the frame's pose after it:
        the frame that pose completes lies past the look-ahead window, so the commands are those of pushing first
        while the robot is fed in time; a starved stream plays from one frame less."""
        cfg, plan = self.cfg, self.plan
        known = len(plan.v)
        if known < 1 or (not self.started and not self.ready(coming)):
            return None
        self.started = True
        if cfg.fixed_time_scale is None and self.dynamics is not None:
            self.time_scale_goal = self.dynamics.stretch(cfg.max_time_scale)     # local: up and down
        elif cfg.fixed_time_scale is None and cfg.retiming == "local":
            # local: just in time for each frame about to be played (its own scale less what the bounded rate of
            # change can add before it is reached; plan time is a lower bound on the robot's), back down after
            ahead = range(int(self.u), min(known, int(self.u) + self.lookahead + 1))
            off_chair = plan.feet[min(int(self.u), known - 1)]
            wait = 1.0 + LAG_GAIN_PER_M * max(0.0, lag_m - LAG_DEADBAND_M) if off_chair else 1.0
            # live, poses can arrive late (an estimator catching up): with less than the look-ahead known, slow
            # down in proportion, as a streaming player's buffer does, rather than run dry and hold
            buffered = known + coming - 1 - self.u
            if not self.finished and buffered < self.lookahead:
                wait = max(wait, min(cfg.max_time_scale, self.lookahead / max(buffered, 1.0)))
            self.time_scale_goal = min(cfg.max_time_scale, max(
                [wait] + [plan.s_req[k] - cfg.max_time_scale_rate * max(0.0, k - self.u) * self.dt
                          for k in ahead if k < len(plan.s_req)]))
        elif cfg.fixed_time_scale is None:
            ahead = range(int(self.u), min(known, int(self.u) + self.lookahead + 1))
            self.time_scale_goal = max(self.time_scale_goal, self.required_scale(ahead))
        s_prev = self.time_scale
        rate = cfg.max_time_scale_rate * self.dt * periods
        self.time_scale = float(np.clip(self.time_scale_goal, self.time_scale - rate, self.time_scale + rate))
        s_dot = (self.time_scale - s_prev) / (self.dt * max(periods, 1e-9))
        k = int(np.floor(self.u))
        if k >= known - 1:          # starved (live input late) or at the end: hold the last pose
            k, frac = known - 1, 0.0
            self.u = float(k)
            hold = True
        elif plan.feet[k] and self._dwelt < self.dwell_pulls:
            # at the robot's seat-off: wait, so that the COM settles over the feet before the hips lift
            frac, hold = 0.0, True
            self.u = float(k)
            self._dwelt += periods
        else:
            frac = self.u - k
            hold = False
        q = pin.interpolate(self.model, plan.q[k], plan.q[min(k + 1, known - 1)], frac)
        v_plan = (1 - frac) * plan.v[k] + frac * plan.v[min(k + 1, known - 1)]
        a_plan = (1 - frac) * plan.a[k] + frac * plan.a[min(k + 1, known - 1)]
        u_dot = 0.0 if hold else 1.0 / self.time_scale
        u_ddot = 0.0 if hold else -s_dot / self.time_scale**2
        v = v_plan * u_dot
        a = a_plan * u_dot**2 + v_plan * u_ddot
        # the command's own ZMP: its accelerations carry the time warp's change of speed too
        com, _, _, zmp = model_cop(self.model, self.data, q, v, a)
        on_feet = plan.feet[k]
        margin = float(support_margin(zmp[None, :2], self.polygon)[0]) if on_feet else np.inf
        if not hold:
            self.u += u_dot * periods
        self.pulled += periods
        criterion = np.inf
        if on_feet:
            zmp_s = zmp_at_scale(*(x[None] for x in plan.dyn[k]), self.mass, self.time_scale)
            criterion = float(support_margin(zmp_s[:, :2], self.polygon)[0])
        cmd = Command(k * self.dt + frac * self.dt, q, v, a, self.time_scale, com, zmp, margin, on_feet, criterion)
        return cmd if self.dynamics is None else self._filtered(cmd, k)

    def seconds_to_seat_off(self, k: int) -> float | None:
        """Robot time [s] from plan frame ``k`` to the plan's seat-off (0 once on the feet); None when the known
        frames do not reach it."""
        for j in range(k, len(self.plan.feet)):
            if self.plan.feet[j]:
                return (j - k) * self.dt * self.time_scale
        return None

    def _filtered(self, cmd: Command, k: int) -> Command:
        """The command through the dynamics filter: the feasible motion, its COP as the ZMP."""
        dyn = self.dynamics
        q, v, a, cop, report = dyn.step(cmd.q, cmd.v, cmd.a, cmd.on_feet, self.seconds_to_seat_off(k))
        com = pin.centerOfMass(self.model, self.data, q, False).copy()
        zmp = np.array([cop[0], cop[1], 0.0]) if np.all(np.isfinite(cop[:2])) else np.array([com[0], com[1], 0.0])
        return Command(cmd.t_plan_s, q, v, a, cmd.time_scale, com, zmp, dyn.margin(cop, cmd.on_feet), cmd.on_feet,
                       com_kinematic=cmd.com, filter=report)

    def smoothed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The smoothed poses (N, nq) of the frames known so far, their velocities and accelerations (N, nv) at the
        human's timing."""
        return np.array(self.plan.q), np.array(self.plan.v), np.array(self.plan.a)

    def played_ratio(self) -> float:
        """How many times longer than the human's the plan pushed so far plays for a robot that keeps up with it: a
        copy of this player played out without lag (this one is left as it is)."""
        dry = self.like()
        for q, on_feet in zip(self.plan.raw_q, self.plan.raw_feet):
            dry.push(q, on_feet)
        dry.close()
        while not dry.done:
            dry.pull()
        return dry.duration_ratio

    @property
    def duration_ratio(self) -> float:
        """Periods played per pose pushed so far: the robot's duration over the human's (``time_scale`` in
        ``sit2stand retarget``'s summary)."""
        return self.pulled / max(1, len(self.plan.raw_q))

    @property
    def done(self) -> bool:
        return self.finished and self.u >= len(self.plan.v) - 1
