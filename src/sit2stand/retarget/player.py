"""The plan player: the dynamic-feasibility stage between the per-frame IK and the robot's joint commands.

It smooths the poses (Savitzky-Golay on the tangent coordinates, ``smooth_frames`` wide), computes each pose's ZMP
from the centroidal dynamics, and plays the plan back ``time_scale`` times slower. ``time_scale`` is the smallest
factor that keeps the ZMP ``margin_m`` inside the feet wherever the robot is off the chair, and the joint speeds
under ``max_joint_speed``, over the poses known ``lookahead_s`` ahead of the playback point; it is capped at
``max_time_scale``. At the robot's seat-off the player dwells ``seat_off_dwell_s``, so that the COM settles over the
feet before the hips lift. ``time_scale`` only grows, at a bounded rate, so the command stays smooth. Each command
carries positions, velocities and accelerations (time-warp included). Live, the commands lag the human by
``lookahead_s`` plus half the smoothing window, plus the stretching.

Units SI; world frame REP-103 (x forward, y left, z up).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.signal import savgol_coeffs   # at import: a live node's first frames must not pay for it

from .dynamic import DynamicsFilter, FilterReport
from .feasibility import frame_time_scales, support_margin, zmp_at_scale

DEFAULT_MAX_TIME_SCALE = 4.0
"""The slowest the plan is played by default (x the human's timing); a parameter of the player, the node and the
``sit2stand retarget`` command."""


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
    com_kinematic: np.ndarray | None = None   # the kinematic plan's COM [m], when a dynamics filter changed it
    filter: FilterReport | None = None        # what the dynamics filter did


class PlanPlayer:
    """Smooths, checks and retimes a stream of IK poses (see the module docstring).

    ``push`` one pose per human frame (period ``dt``); ``pull`` once per output tick (same period) returns the next
    command, or None while the look-ahead fills. ``fixed_time_scale`` set: no adaptation (1.0: the human's
    timing); ``max_time_scale`` caps the adaptation."""

    def __init__(self, model: pin.Model, dt: float, polygon_xy: np.ndarray, *, margin_m: float = 0.06,
                 lookahead_s: float = 0.8, smooth_frames: int = 21, max_time_scale: float = DEFAULT_MAX_TIME_SCALE,
                 max_time_scale_rate: float = 1.5, fixed_time_scale: float | None = None,
                 max_joint_speed: float = 0.6, seat_off_dwell_s: float = 1.0,
                 dynamics: DynamicsFilter | None = None) -> None:
        self.model, self.data = model, model.createData()
        self.dt = dt
        self.polygon = polygon_xy
        self.margin_m = margin_m
        self.lookahead = max(0, int(round(lookahead_s / dt)))
        self.half = max(0, smooth_frames // 2)
        self.max_time_scale = max_time_scale
        self.max_time_scale_rate = max_time_scale_rate
        self.fixed_time_scale = fixed_time_scale
        self.max_speed = max_joint_speed
        self.dwell_pulls = int(round(seat_off_dwell_s / dt))
        self._dwelt = 0
        self.time_scale = 1.0 if fixed_time_scale is None else float(fixed_time_scale)
        self.time_scale_goal = self.time_scale
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
        self.dynamics = dynamics

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
            s = float(frame_time_scales(com, acc, dl, self.mass, self.polygon, self.margin_m, self.max_time_scale)[0])
        return min(max(s, speed), self.max_time_scale)

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
        if self.fixed_time_scale is None and self.dynamics is not None:
            self.time_scale_goal = self.dynamics.stretch(self.max_time_scale)     # local: up and down
        elif self.fixed_time_scale is None:
            ahead = range(int(self.u), min(known, int(self.u) + self.lookahead + 1))
            self.time_scale_goal = max(self.time_scale_goal, self.required_scale(ahead))
        s_prev = self.time_scale
        rate = self.max_time_scale_rate * self.dt
        self.time_scale = float(np.clip(self.time_scale_goal, self.time_scale - rate, self.time_scale + rate))
        s_dot = (self.time_scale - s_prev) / self.dt
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
        u_dot = 0.0 if hold else 1.0 / self.time_scale
        u_ddot = 0.0 if hold else -s_dot / self.time_scale**2
        v = v_plan * u_dot
        a = a_plan * u_dot**2 + v_plan * u_ddot
        com, acom, dl = self._dyn[k]
        zmp = zmp_at_scale(com[None], acom[None], dl[None], self.mass, self.time_scale)[0] if not hold else \
            np.array([com[0], com[1], 0.0])
        on_feet = self._feet[k]
        margin = float(support_margin(zmp[None, :2], self.polygon)[0]) if on_feet else np.inf
        if not hold:
            self.u += u_dot
        cmd = Command(k * self.dt + frac * self.dt, q, v, a, self.time_scale, com, zmp, margin, on_feet)
        return cmd if self.dynamics is None else self._filtered(cmd, k)

    def seconds_to_seat_off(self, k: int) -> float | None:
        """Robot time [s] from plan frame ``k`` to the plan's seat-off (0 once on the feet); None when the known
        frames do not reach it."""
        for j in range(k, len(self._feet)):
            if self._feet[j]:
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

    @property
    def done(self) -> bool:
        return self.finished and self.u >= len(self._v) - 1
