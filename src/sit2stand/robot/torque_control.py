"""The simulated robot's whole-body torque controller: the QP of :mod:`sit2stand.robot.wbc` on the measured state.

TALOS is torque controlled; this is the on-board controller a torque-controlled humanoid runs instead of joint PD
(selected with the plant's ``feedforward="wbc"``). At its rate it reads the robot's state (joint encoders and the
base pose and velocity of a state estimator), turns the latest joint command (positions, velocities, accelerations,
followed along its velocity between commands) into a whole-body reference with the soles where they stand
(:func:`sit2stand.robot.wbc.feet_anchored_reference`), and applies the QP's joint torques. The QP's contacts are the
soles only: a robot has no force sensor under its pelvis, so while it sits the seat's force is estimated as the weight
the feet's force sensors do not carry, and enters the dynamics as a known external force (a rigid seat contact in the
QP would let it assume a seat force the real chair, which cannot pull, does not give). The controller's model has only
the identified (or CAD) parameters, never the plant's hidden effects. The latest QPs' wall and CPU times are kept
(``qp_times_s``, ``qp_cpu_times_s``).
"""

from __future__ import annotations

from collections import deque

import numpy as np
import pinocchio as pin

from .wbc import WbcGains, WholeBodyQP, feet_anchored_reference

QP_TIMES_KEPT = 60_000
"""QP wall times kept (the last 2 min at 500 Hz): a driver runs for hours."""
STANDING_SETTLE_S = 0.2
"""The feet carry the whole weight this long [s] before the reference's sole moves from flat to as measured."""
ANCHOR_BLEND_S = 0.5
"""Time over which the reference's sole moves between flat and as measured [s]."""


class WholeBodyController:
    """Whole-body torque control of a :class:`~sit2stand.robot.plant.Plant` (see the module docstring).

    Where the reference's left sole is (``anchor``): seated and through the rise, flat on the floor. The plan keeps
    the soles as the seated robot measured them, pitched by its soft contact (weight on the heels, about -0.6 degree
    on TALOS); a flat reference sole turns the reference body forward by that angle, its COM ~0.7 cm ahead of the
    plan's, toward the feet: margin for the seat-off. Once the feet have carried the whole weight for
    ``STANDING_SETTLE_S`` the reference sole moves, over ``ANCHOR_BLEND_S``, to the pose measured at the start, where
    the plan has it: the standing robot then holds the plan's COM (the flat sole alone left it 0.6-0.8 cm ahead). It
    moves back if the seat takes weight again.
    """

    def __init__(self, model: pin.Model, seat_frame: int, gains: WbcGains | None = None,
                 period_s: float = 0.002) -> None:
        self.model, self.data = model, model.createData()
        self.qp = WholeBodyQP(model, seat_frame, gains, seat_contact=False)     # the seat's force: from the feet
        self.sole = model.getFrameId("sole_left")
        self.period_s = period_s
        self.oM_sole: pin.SE3 | None = None
        self.sole_flat: pin.SE3 | None = None
        self.sole_measured: pin.SE3 | None = None
        self.standing_s = 0.0          # how long the feet have carried the whole weight [s]
        self.measured_share = 0.0      # 0: the reference sole flat, 1: as measured at the start
        self.qp_times_s: deque[float] = deque(maxlen=QP_TIMES_KEPT)
        self.qp_cpu_times_s: deque[float] = deque(maxlen=QP_TIMES_KEPT)
        self.last = None

    def qp_figures(self) -> dict[str, float]:
        """The QP's wall time per control step over the kept steps, p50 and p99 [ms], its CPU time (the thread's: a
        shared host's steal left out), their count, and the QPs whose warm start failed (solved again from an empty
        active set); empty before the first step."""
        if not self.qp_times_s:
            return {}
        ms, cpu = np.array(self.qp_times_s) * 1e3, np.array(self.qp_cpu_times_s) * 1e3
        return {"qp_ms_p50": float(np.percentile(ms, 50)), "qp_ms_p99": float(np.percentile(ms, 99)),
                "qp_cpu_ms_p50": float(np.percentile(cpu, 50)), "qp_cpu_ms_p99": float(np.percentile(cpu, 99)),
                "qp_steps": len(ms), "qp_cold_solves": self.qp.cold_solves}

    def anchor(self, q: np.ndarray) -> None:
        """Take the left sole's pose in the measured configuration ``q``, as measured and flattened onto the floor;
        the reference's starts flat."""
        pin.framesForwardKinematics(self.model, self.data, q)
        M = self.data.oMf[self.sole]
        yaw = np.arctan2(M.rotation[1, 0], M.rotation[0, 0])
        self.sole_measured = M.copy()
        self.sole_flat = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, yaw), np.array([*M.translation[:2], 0.0]))
        self.oM_sole = self.sole_flat

    def _move_anchor(self, seat_load_n: float) -> None:
        """The reference sole toward as measured while the robot stands on its feet alone, toward flat otherwise."""
        self.standing_s = self.standing_s + self.period_s if seat_load_n <= 0.0 else 0.0
        step = self.period_s / ANCHOR_BLEND_S
        share = self.measured_share + (step if self.standing_s >= STANDING_SETTLE_S else -step)
        share = min(1.0, max(0.0, share))
        if share != self.measured_share:
            self.measured_share = share
            delta = pin.log6(self.sole_flat.actInv(self.sole_measured))
            self.oM_sole = self.sole_flat * pin.exp6(share * delta)

    def torques(self, q: np.ndarray, v: np.ndarray, q_ref: np.ndarray, v_ref: np.ndarray,
                a_ref: np.ndarray, seat_load_n: float = 0.0, tau_ref: np.ndarray | None = None) -> np.ndarray:
        """Joint torques [N m] at the measured state (q, v) (Pinocchio order; base velocity in the base frame)
        tracking the joint reference (q_ref, v_ref, a_ref); ``seat_load_n``: the seat's vertical force on the pelvis
        as estimated from the feet's force sensors (the weight they do not carry) [N]; ``tau_ref``: the joint torques
        the plan asks [N m] (its optimisation's), tracked with ``WbcGains.torque_weight``."""
        if self.oM_sole is None:
            self.anchor(q)
        self._move_anchor(seat_load_n)
        q_full = q.copy()
        q_full[7:] = q_ref
        ref = feet_anchored_reference(self.model, self.data, q_full, v_ref, a_ref, self.oM_sole, self.sole)
        ref.tau = tau_ref
        seat = np.array([0.0, 0.0, seat_load_n]) if seat_load_n > 0 else None
        res = self.qp.solve(q, v, ref, 0.0, seat)
        self.qp_times_s.append(res.qp_s)
        self.qp_cpu_times_s.append(res.qp_cpu_s)
        self.last = res
        return res.tau
