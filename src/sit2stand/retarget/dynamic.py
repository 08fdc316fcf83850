"""Dynamic retargeting: the kinematic plan made dynamically feasible at the human's timing.

The COM-hard IK (Mistry et al. 2010) gives poses; played at the human's speed their centroidal dynamics can ask for
a ZMP outside the feet (a trunk raised fast needs angular momentum the feet cannot give), and for torques past the
URDF limits. Instead of slowing the whole plan down, each command goes through a dynamics filter (Yamane and
Nakamura's, in the form of Yamane and Hodgins 2009: a tracking controller on the full-body dynamics): the whole-body
QP of :mod:`sit2stand.robot.wbc`, run on the model itself and integrated (semi-implicit Euler, ``substeps`` per
frame). It follows the plan's poses and its COM as closely as the contact forces allow: while seated the seat and
the feet share the load (the seat's share ramped to zero over ``seat_release_s`` before the plan's seat-off, as a
contact is removed in tsid); on the feet alone the feet's centre of pressure stays ``cop_margin_m`` inside the soles,
the forces in their friction cones and the torques inside their limits, by construction. What comes out is a plan
the robot can realise; how far it is from the kinematic one is reported (COM deviation, per command).

Units SI; world frame REP-103 (x forward, y left, z up).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin

from ..dynamics import G
from ..robot.wbc import Reference, WbcGains, WholeBodyQP
from .feasibility import support_margin


@dataclasses.dataclass
class FilterReport:
    """What the filter did to one command."""

    com_deviation_m: float         # filtered COM - kinematic plan's COM (horizontal distance)
    seat_force_n: float            # the seat's normal force
    torque_ratio: float            # largest |tau| / effort limit
    solved: bool


class DynamicsFilter:
    """The plan's dynamics filter (see the module docstring).

    Args:
        model: the retargeter's robot model (the identified parameters), with a ``seat`` frame.
        dt: period of the commands [s].
        polygon_xy: the feet's support polygon (for the reported margin).
    """

    def __init__(self, model: pin.Model, dt: float, polygon_xy: np.ndarray, *, substeps: int = 5,
                 seat_release_s: float = 0.3, gains: WbcGains | None = None, free_deviation_m: float = 0.02,
                 stretch_per_m: float = 50.0) -> None:
        self.model, self.data = model, model.createData()
        self.qp = WholeBodyQP(model, model.getFrameId("seat"), gains)
        self.dt, self.substeps = dt, max(1, int(substeps))
        self.polygon = polygon_xy
        self.seat_release_s = seat_release_s
        self.weight_n = self.qp.mass * G
        self.q: np.ndarray | None = None
        self.v = np.zeros(model.nv)
        self.reports: list[FilterReport] = []
        self.free_deviation_m, self.stretch_per_m = free_deviation_m, stretch_per_m

    def stretch(self, max_scale: float) -> float:
        """The time scale the filter asks of the player: 1 (the human's timing) while its COM keeps within
        ``free_deviation_m`` of the plan's, then ``stretch_per_m`` more per metre beyond, at most ``max_scale``:
        time is stretched only where the dynamics cannot follow, and only there."""
        dev = self.reports[-1].com_deviation_m if self.reports else 0.0
        return float(np.clip(1.0 + self.stretch_per_m * max(0.0, dev - self.free_deviation_m), 1.0, max_scale))

    def seat_force_cap(self, seconds_to_seat_off: float | None) -> float:
        """The seat's largest normal force [N]: the robot's weight (twice: a margin for its own accelerations) until
        ``seat_release_s`` before the plan's seat-off, then down to zero; None: no seat-off within sight."""
        if seconds_to_seat_off is None:
            return 2.0 * self.weight_n
        return 2.0 * self.weight_n * float(np.clip(seconds_to_seat_off / self.seat_release_s, 0.0, 1.0))

    def _reference(self, q: np.ndarray, v: np.ndarray, a: np.ndarray, tau_s: float) -> Reference:
        """The command's reference ``tau_s`` after its time, followed along its velocity and acceleration."""
        q_t = pin.integrate(self.model, q, v * tau_s + 0.5 * a * tau_s**2)
        v_t = v + a * tau_s
        pin.centerOfMass(self.model, self.data, q_t, v_t, a)
        d = self.data
        return Reference(q_t, v_t, a, d.com[0].copy(), d.vcom[0].copy(), d.acom[0].copy())

    def step(self, q: np.ndarray, v: np.ndarray, a: np.ndarray, on_feet: bool,
             seconds_to_seat_off: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, FilterReport]:
        """Filter one command (q, v, a of the kinematic plan): the filtered (q, v, a) at the command's time, the
        feet's centre of pressure [m] over the coming period, and the report."""
        if self.q is None:                      # start where the plan starts, at rest
            self.q, self.v = q.copy(), np.zeros(self.model.nv)
        cap = 0.0 if on_feet else self.seat_force_cap(seconds_to_seat_off)
        h = self.dt / self.substeps
        q_out, v_out, a_out = self.q.copy(), self.v.copy(), None
        cops, worst_tau, solved = [], 0.0, True
        seat = 0.0
        for j in range(self.substeps):
            ref = self._reference(q, v, a, j * h)
            res = self.qp.solve(self.q, self.v, ref, cap)
            if a_out is None:
                a_out = res.a.copy()
            solved = solved and res.solved
            worst_tau = max(worst_tau, float(np.max(np.abs(res.tau) / self.qp.tau_max)))
            cops.append(res.cop)
            seat = max(seat, float(res.seat_force[2]))
            self.v = self.v + h * res.a
            self.q = pin.integrate(self.model, self.q, h * self.v)
        pin.centerOfMass(self.model, self.data, q, False)
        com_plan = self.data.com[0].copy()
        pin.centerOfMass(self.model, self.data, q_out, False)
        dev = float(np.linalg.norm(self.data.com[0][:2] - com_plan[:2]))
        report = FilterReport(dev, seat, worst_tau, solved)
        self.reports.append(report)
        return q_out, v_out, a_out, _mean_cop(cops), report

    def margin(self, cop: np.ndarray, on_feet: bool) -> float:
        """The feet's COP distance inside the support polygon [m] (inf while the seat carries the robot)."""
        if not on_feet or not np.all(np.isfinite(cop[:2])):
            return np.inf
        return float(support_margin(cop[None, :2], self.polygon)[0])


def _mean_cop(cops: list[np.ndarray]) -> np.ndarray:
    """Mean of the sub-steps' centres of pressure (NaN where the feet were unloaded)."""
    arr = np.array(cops)
    ok = np.all(np.isfinite(arr), axis=1)
    return arr[ok].mean(axis=0) if ok.any() else np.full(3, np.nan)
