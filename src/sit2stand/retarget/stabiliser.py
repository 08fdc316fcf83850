"""COM feedback on the played plan: the robot's measured COM pulled onto the planned one.

The plan is kinematic: the COM-hard IK of the human's motion, retimed for a ZMP margin
(:mod:`sit2stand.retarget.stream`). Under joint PD control the robot's COM drifts from it: the hips unload from the
chair later than planned, the feet slide a little at lift-off, the joints sag under gravity. Each command, before it
is sent, is therefore moved so that its COM moves by

    delta = kp e + kd de/dt + ki integral(e dt)     e = planned COM - measured COM   (x and y, world frame, [m])

with both feet where the plan has them: the same QP as the retargeting IK (:class:`sit2stand.retarget.ik.ComIk`)
with no markers, the COM shifted by ``delta`` as its hard equality, the feet hard, the joint limits, the pelvis no
lower than the command's, and a posture pull to the command itself (arms and head held). The pelvis bound: a shift
made by bending the knees would lower the hips the plan has just lifted off the seat (docs/results.md).
This is the COM-admittance outer loop of position-controlled humanoid stabilisers (e.g. Kajita et al., "Biped
walking stabilization based on linear inverted pendulum tracking", IROS 2010), here on the COM position and velocity
only: the driver's joint PD and inverse-dynamics feed-forward stay as they are. ``de/dt`` is low-passed
(``velocity_filter_s``). Without it the loop has too little phase margin: a standing TALOS under joint PD sways with
a ~2 s period, and an integral gain of 1/s alone made that sway grow until the robot fell (offline re-simulation of
the natural demonstration).

The loop runs only while the plan has the robot on its feet (from the plan's seat-off, while the hips unload),
fading in over ``ramp_s``; ``delta`` is bounded by ``max_offset_m`` per axis and the integral by the same
(anti-windup). Without a recent measured state the last shift is held; when states come back after a gap longer than
``ramp_s`` the loop fades in again from there, its velocity filter restarted (a robot behind real time for seconds
otherwise met the full gains on the error it had gathered). Units SI; world frame REP-103.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..robot.profile import profile_of
from .ik import ComIk


def com_feedback_applies(asked: bool, controller: str) -> bool:
    """Whether the COM feedback corrects the commands: asked for, and the robot under joint PD (``controller``: one of
    :data:`sit2stand.robot.plant.CONTROLLERS`); whole-body torque control tracks the plan's COM itself."""
    return asked and controller != "wbc"


def com_lag_m(error_m: np.ndarray) -> float:
    """How far the measured COM trails the planned one forward [m], from ``error_m`` = planned - measured COM (x
    first); 0 when it is ahead: a sit-to-stand moves the COM forward, and only a robot behind its plan is helped by
    the plan waiting (``PlanPlayer.pull(lag_m=...)``)."""
    return max(0.0, float(error_m[0]))


@dataclass
class StabiliserConfig:
    """COM feedback gains and bounds (SI units)."""

    kp: float = 2.0                 # proportional gain [m/m]: at 1.0 the 30-body benchmark's COM tracking p90
    #                                 1.02 cm (seed 1: 0.97), at 2.0 0.88 (0.83), all standing
    ki: float = 1.0                 # integral gain [1/s]
    kd: float = 0.5                 # velocity gain [s]: on planned - measured COM velocity
    velocity_filter_s: float = 0.05  # time constant of the measured COM velocity's low-pass [s]
    max_offset_m: float = 0.03      # bound of the COM shift, per axis
    ramp_s: float = 0.5             # the gains fade in over this once the plan has the robot on its feet
    held_weight: float = 100.0      # posture pull on arms and head (legs and torso: 1): the shift is made with
    #                                 the legs and trunk, as the plan's own COM motion is
    iterations: int = 1             # Gauss-Newton steps of the shift: from the command, one leaves < 0.5 mm of
    #                                 a 3 cm shift (the loop closes on the rest), at ~0.55 ms against 0.65 for two


@dataclass
class Correction:
    """One corrected command."""

    q: np.ndarray                   # corrected configuration (Pinocchio, floating base)
    offset_m: np.ndarray            # COM shift applied (x, y) [m]
    error_m: np.ndarray             # planned - measured COM (x, y) [m]
    active: bool                    # the command was shifted

    @property
    def lag_m(self) -> float:
        """How far the measured COM trails the planned one forward [m] (:func:`com_lag_m`)."""
        return com_lag_m(self.error_m)


class ComStabiliser:
    """COM feedback (see the module docstring).

    Args:
        model: the robot model with the COM parameters to use (as the retargeter's).
        sole_frames, sole_targets: the soles and where the plan has them.
        cfg: gains and bounds.
    """

    def __init__(self, model: pin.Model, sole_frames: list[int], sole_targets: list[pin.SE3],
                 cfg: StabiliserConfig | None = None) -> None:
        self.cfg = cfg or StabiliserConfig()
        self.model = model
        self.data = model.createData()
        self.sole_targets = sole_targets
        mu = np.ones(model.nv)
        for j in range(2, model.njoints):
            if profile_of(model).is_upper_limb(model.names[j]):
                jt = model.joints[j]
                mu[jt.idx_v:jt.idx_v + jt.nv] = self.cfg.held_weight
        self.ik = ComIk(model, sole_frames, velocity_limit=1e3, posture_weight=mu, damping=1e-6)
        self.integral = np.zeros(2)
        self.offset = np.zeros(2)              # the COM shift in force [m]
        self.on_feet_s = 0.0               # on the feet with measured states, since the loop (re)started [s]
        self.unmeasured_s = 0.0            # on the feet without a measured state, since the last one [s]
        self._held = np.zeros(2)           # the shift beyond the integral held when the loop restarted, faded out
        self._last: tuple[np.ndarray, np.ndarray] | None = None     # (planned, measured) COM of the last call
        self.velocity_error = np.zeros(2)

    def measured_com(self, q_measured: np.ndarray) -> np.ndarray:
        """COM [m] of a measured configuration (Pinocchio order, base pose included)."""
        return pin.centerOfMass(self.model, self.data, q_measured, False).copy()

    def reset(self) -> None:
        self.integral[:] = 0.0
        self.offset[:] = 0.0
        self.on_feet_s = self.unmeasured_s = 0.0
        self._last = None
        self.velocity_error[:] = 0.0
        self._held[:] = 0.0

    def _restart_after_gap(self) -> None:
        """After more than ``ramp_s`` without a measured state: fade in again from the shift held (no step), the
        velocity filter anew."""
        if self.unmeasured_s > self.cfg.ramp_s:
            self.on_feet_s, self._last = 0.0, None
            self.velocity_error[:] = 0.0
            self._held = self.offset - self.integral
        self.unmeasured_s = 0.0

    def correct(self, q_command: np.ndarray, com_planned_m: np.ndarray, q_measured: np.ndarray | None,
                on_feet: bool, dt_s: float) -> Correction:
        """The command ``q_command`` (whose planned COM is ``com_planned_m``) corrected for the measured
        configuration ``q_measured``; ``dt_s``: time since the last call [s]. ``q_measured`` None (no recent
        state): the last shift is kept, not updated (dropping it would step the command by up to
        ``max_offset_m``)."""
        cfg = self.cfg
        if not on_feet:
            self.reset()
            return Correction(q_command, np.zeros(2), np.zeros(2), False)
        err = np.zeros(2)
        if q_measured is None:
            self.unmeasured_s += dt_s
        else:
            self._restart_after_gap()
            plan, meas = np.asarray(com_planned_m, float)[:2], self.measured_com(q_measured)[:2]
            err = plan - meas
            if self._last is not None and dt_s > 0:
                ev = ((plan - self._last[0]) - (meas - self._last[1])) / dt_s
                alpha = dt_s / (dt_s + cfg.velocity_filter_s)
                self.velocity_error += alpha * (ev - self.velocity_error)
            self._last = (plan, meas)
            self.on_feet_s += dt_s
            fade = min(1.0, self.on_feet_s / cfg.ramp_s) if cfg.ramp_s > 0 else 1.0
            bound = cfg.max_offset_m
            self.integral = np.clip(self.integral + fade * cfg.ki * dt_s * err, -bound, bound)
            self.offset = np.clip(fade * (cfg.kp * err + cfg.kd * self.velocity_error) + self.integral
                                  + (1.0 - fade) * self._held, -bound, bound)
        if not np.any(self.offset):
            return Correction(q_command, self.offset.copy(), err, False)
        target = self.measured_com(q_command)       # the command's own COM, shifted
        target[:2] += self.offset
        res = self.ik.solve(q_command, [], target, self.sole_targets, q_ref=q_command, com_axes=(0, 1),
                            max_iterations=cfg.iterations, tol=1e-9, base_z_min=q_command[2])
        return Correction(res.q, self.offset.copy(), err, True)
