"""The simulated robot's whole-body torque controller: the QP of :mod:`sit2stand.robot.wbc` on the measured state.

TALOS is torque controlled; this is the on-board controller a torque-controlled humanoid runs instead of joint PD
(selected with the plant's ``feedforward="wbc"``). At its rate it reads the robot's state (joint encoders and the
base pose and velocity of a state estimator), turns the latest joint command (positions, velocities, accelerations,
followed along its velocity between commands) into a whole-body reference with the soles where they stand
(:func:`sit2stand.robot.wbc.feet_anchored_reference`), and applies the QP's joint torques. The QP's contacts are the
soles only: a robot has no force sensor under its pelvis, so while it sits the seat's force is estimated as the weight
the feet's force sensors do not carry, and enters the dynamics as a known external force (a rigid seat contact in the
QP would let it assume a seat force the real chair, which cannot pull, does not give). The controller's model has only
the identified (or CAD) parameters, never the plant's hidden effects; what those do to the COM it sees in the feet's
centre of pressure once it stands (:class:`ComOffsetObserver`). The latest QPs' wall and CPU times are kept
(``qp_times_s``, ``qp_cpu_times_s``).
"""

from __future__ import annotations

from collections import deque

import numpy as np
import pinocchio as pin

from ..dynamics import G
from .wbc import WbcGains, WholeBodyQP, feet_anchored_reference

QP_TIMES_KEPT = 60_000
"""QP wall times kept (the last 2 min at 500 Hz): a driver runs for hours."""
STANDING_SETTLE_S = 0.2
"""The feet carry the whole weight this long [s] before the reference's sole moves from flat to as measured."""
ANCHOR_BLEND_S = 0.5
"""Time over which the reference's sole moves between flat and as measured [s]."""


class ComOffsetObserver:
    """The horizontal offset of the robot's true COM from its model's [m], seen in the feet's centre of pressure.

    Standing on its feet, a robot's measured centre of pressure (its ankle force sensors') and its model's zero-moment
    point for the motion it measures (the model's centroidal momentum's rate, :meth:`model_zmp`) differ by what the
    model does not know: mass it misses moves the true COM, and with it the measured centre of pressure, off the
    model's (statically by the same amount). The offset is that difference low-passed (``time_constant_s``); the
    controller then steers its model's COM to the plan's less the offset, which puts the true one on the plan (the
    COM offset estimation of Xinjilefu and Atkeson, "Center of mass estimator for humanoids and its application in
    modelling error compensation, fall detection and prevention", Humanoids 2015, here as a first-order filter).
    On the seat the feet's centre of pressure says nothing of the COM (the seat's share is unknown: with mass the
    model misses, the feet of a robot leaning forward on its seat carry more than the model's weight while the seat
    still carries some), nor until the feet have carried the whole weight for ``STANDING_SETTLE_S``; the offset is
    then held. It is bounded by ``max_offset_m`` per axis: a model further off than that needs identifying, not
    steering."""

    def __init__(self, model: pin.Model, period_s: float, time_constant_s: float = 0.15,
                 max_offset_m: float = 0.05) -> None:
        self.model, self.data, self.period_s = model, model.createData(), float(period_s)
        self.weight_n = float(pin.computeTotalMass(model)) * G
        self.time_constant_s, self.max_offset_m = float(time_constant_s), float(max_offset_m)
        self.offset_m = np.zeros(2)
        self.momentum: np.ndarray | None = None      # the last state's centroidal momentum (linear, angular)

    def model_zmp(self, q: np.ndarray, v: np.ndarray) -> np.ndarray | None:
        """The model's zero-moment point on the floor (x, y) [m] for the motion from the last state to (q, v): the
        contact wrench its centroidal momentum's change over ``period_s`` asks; None at the first state."""
        h = pin.computeCentroidalMomentum(self.model, self.data, q, v)
        now = np.concatenate([h.linear, h.angular])
        last, self.momentum = self.momentum, now
        if last is None:
            return None
        rate = (now - last) / self.period_s
        f = rate[:3] + np.array([0.0, 0.0, self.weight_n])       # the contacts' force [N]
        c, dl = self.data.com[0], rate[3:]                         # the COM [m], the angular momentum's rate [N m]
        if f[2] <= 0.1 * self.weight_n:
            return None
        return np.array([c[0] - (c[2] * f[0] + dl[1]) / f[2], c[1] + (dl[0] - c[2] * f[1]) / f[2]])

    def update(self, q: np.ndarray, v: np.ndarray, measured_cop: np.ndarray | None, on_feet: bool) -> np.ndarray:
        """The offset (x, y) [m] at the measured state (q, v) (Pinocchio order), the feet's centre of pressure measured
        over the last period at ``measured_cop`` (world [m]; None: unloaded); ``on_feet``: the feet have carried the
        whole weight long enough."""
        if not on_feet or measured_cop is None:
            self.momentum = None            # the momentum's change is taken again from the next state on
            return self.offset_m
        zmp = self.model_zmp(q, v)
        if zmp is not None:
            gain = min(1.0, self.period_s / self.time_constant_s)
            self.offset_m += gain * (measured_cop[:2] - zmp - self.offset_m)
            np.clip(self.offset_m, -self.max_offset_m, self.max_offset_m, out=self.offset_m)
        return self.offset_m


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
        self.com_offset = ComOffsetObserver(model, period_s)

    def qp_figures(self) -> dict[str, float]:
        """The QP's wall time per control step over the kept steps, p50 and p99 [ms], its CPU time (the thread's: a
        shared host's steal left out), their count, and the QPs whose warm start failed (solved again from an empty
        active set); empty before the first step."""
        if not self.qp_times_s:
            return {}
        ms, cpu = np.array(self.qp_times_s) * 1e3, np.array(self.qp_cpu_times_s) * 1e3
        return {"qp_ms_p50": float(np.percentile(ms, 50)), "qp_ms_p99": float(np.percentile(ms, 99)),
                "qp_cpu_ms_p50": float(np.percentile(cpu, 50)), "qp_cpu_ms_p99": float(np.percentile(cpu, 99)),
                "qp_steps": len(ms), "qp_fallback_solves": self.qp.fallback_solves}

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
                a_ref: np.ndarray, seat_load_n: float = 0.0, tau_ref: np.ndarray | None = None,
                measured_cop: np.ndarray | None = None) -> np.ndarray:
        """Joint torques [N m] at the measured state (q, v) (Pinocchio order; base velocity in the base frame)
        tracking the joint reference (q_ref, v_ref, a_ref); ``seat_load_n``: the seat's vertical force on the pelvis
        as estimated from the feet's force sensors (the weight they do not carry) [N]; ``tau_ref``: the joint torques
        the plan asks [N m] (its optimisation's), tracked with ``WbcGains.torque_weight``; ``measured_cop``: the feet's
        centre of pressure from their force sensors (world, [m]; None: on the seat, unloaded or not sensed), for
        :class:`ComOffsetObserver`."""
        if self.oM_sole is None:
            self.anchor(q)
        self._move_anchor(seat_load_n)
        offset = self.com_offset.update(q, v, measured_cop, self.standing_s >= STANDING_SETTLE_S)
        q_full = q.copy()
        q_full[7:] = q_ref
        ref = feet_anchored_reference(self.model, self.data, q_full, v_ref, a_ref, self.oM_sole, self.sole)
        ref.tau = tau_ref
        ref.com[:2] -= offset
        seat = np.array([0.0, 0.0, seat_load_n]) if seat_load_n > 0 else None
        res = self.qp.solve(q, v, ref, 0.0, seat)
        self.qp_times_s.append(res.qp_s)
        self.qp_cpu_times_s.append(res.qp_cpu_s)
        self.last = res
        return res.tau
