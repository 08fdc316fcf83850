"""Whole-body inverse dynamics as one QP per control step: the robot's torque-controlled on-board controller.

The formulation of task-space inverse dynamics (TSID; Del Prete et al., "Implementing torque control with high-rate,
low-latency loops", and the `tsid` library's TALOS examples), written on Pinocchio and solved by
:class:`sit2stand.optim.WarmQp`: a compiled primal-dual active set started from the last step's working set, with
DAQP (Arnström et al., "A dual active-set solver for embedded quadratic programming using recursive LDL' updates",
IEEE TAC 2022) where it gives up. Unknowns: x = (a, lambda): the generalised acceleration (nv) and the contact
forces, 3D forces at the four corners of each sole (shrunk by ``cop_margin_m``, so the feet's centre of pressure
stays that far inside them) and at one seat point under the pelvis, each a nonnegative combination lambda of its
friction pyramid's four edges (:func:`friction_generators`). Constraints:

* the floating base's Newton-Euler rows:   M_b a + h_b = J_b^T f          (6; no actuator at the base)
* both soles fixed (6D rigid contacts):    J_foot a + dJ_foot v = -kd_foot v_foot   (12; on legs without an ankle
  roll only their independent combinations: these rows are dependent wherever the hips' roll axes align)
* the seat point fixed while it is active (3), otherwise its force zero (its coefficients bounded at zero)
* unilateral forces in linearised friction cones (friction coefficient ``friction``): lambda >= 0; the seat's
  normal force at most ``seat_force_max_n`` (ramped to zero before seat-off, as tsid removes a contact)
* joint torques tau = M_j a + h_j - J_j^T f inside the URDF effort limits.

Cost (weighted least squares): COM acceleration toward a_com* = a_ref + kp (c_ref - c) + kd (v_ref - v); every
tangent coordinate (base orientation and joints; the base's translation is left to the COM) toward
a* = a_ref + kp (q_ref - q) + kd (v_ref - v) (the base orientation weighed less while the seat carries weight:
the seat holds the pelvis too); the seat's force (the feet carry what they can); all forces (a small
regularisation, and a hundredth of it on lambda itself, which splits a force among its edges); where the reference
has torques (an optimised plan's), the joint torques toward them, which settles how the contacts share the load where
the tasks leave a choice (tsid's force reference). The same QP is the plan's dynamics filter
(:mod:`sit2stand.retarget.dynamic`: integrated on the model itself) and the simulated robot's controller
(:class:`sit2stand.robot.plant.Plant`, ``controller="wbc"``).

Units SI; world frame REP-103 (x forward, y left, z up); forces in world axes.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import daqp
import numpy as np
import pinocchio as pin

from ..optim import QpProblem, WarmQp
from ..vectors import skew_rows
from .model import SIDES, sole_corners_local
from .profile import profile_of

INF = np.inf         # no bound
FORCE_UNIT_N = 100.0
"""The QP's forces are in this unit: accelerations (~1-10 m/s^2) and forces (~100-1000 N) then weigh alike, a
well-scaled problem for the solver."""
GENERATORS = 4
"""Unknowns per contact point: its friction pyramid's edges."""
GENERATOR_WEIGHT_SHARE = 0.01
"""Each edge's coefficient weighs this share of the force regularisation besides. A point's four edges span three
force directions: this makes their split unique (the QP's Hessian positive definite) and moves the forces by at most
that share of the regularisation's own small say. Unknowns that are the pyramid's edges, not (f_x, f_y, f_z) under
four friction rows, keep an unloaded corner from degenerate rows (its f_z at zero and its friction rows active at
once), where an active-set step is singular: the compiled solver then solves 98-99.8 % of a stand-up's steps, not
92 %."""
CONTACT_DEPENDENT_SV_RATIO = 1e-2
"""On legs without an ankle roll, the soles' contact rows' combinations along a singular value under this share of
the largest are left free (their forces then act through the others). Near the aligned hips' singularity such a
combination is nearly dependent, and held as an equality it locks the motions it couples: a standing H1 with its feet
toed out 0.7 degree (singular value 0.3 % of the largest) held its hips 0.13 rad and its COM 4.8 cm off the plan for
good, the QP's best acceleration zero. At 1 % it reaches the plan's posture in 0.6 s."""


@dataclass
class WbcGains:
    """Task gains and weights of the whole-body QP (SI units)."""

    com_kp: float = 300.0          # [1/s^2]: at 100 (kd 20), 26 of 29 benchmark rises stood, at 200 28 of 29; with
    #                                the seated base weight below, 300 tracks the 30 bodies' COM at p90 0.7 cm (200:
    #                                1.1 cm), 400 felled a fast rise of a heavy body (the trunk past its torque)
    com_kd: float = 34.6           # [1/s]: critically damped, 2 sqrt(kp)
    posture_kp: float = 200.0      # joints and base orientation [1/s^2]
    posture_kd: float = 28.0       # [1/s]
    com_weight: float = 100.0
    posture_weight: float = 1.0
    base_orientation_weight: float = 30.0
    base_orientation_weight_seated: float = 10.0   # while the seat carries weight: the seat holds the pelvis too,
    #                                which the QP (no seat contact, a known force) does not know; at 30 the QP turned
    #                                the torso's yaw joint as a reaction wheel to right the base (0.8 rad off its plan
    #                                on a fast rise); at 3 one fast rise fell at seat-off
    seat_force_weight: float = 1e-6     # per N^2 of the seat's normal force: the feet carry what they can
    force_weight: float = 1e-7          # per N^2
    foot_kd: float = 20.0          # contact stabilisation: a sole's residual velocity damped out [1/s]
    friction: float = 0.5          # sole-floor and pelvis-seat friction coefficient (pyramid, inscribed)
    cop_margin_m: float = 0.01     # the corners' forces act this far inside each sole edge. The plan keeps its
    #                                ZMP 4 cm inside (the player's and the optimisation's margin): this is the
    #                                controller's reserve for what its model gets wrong. At 2 cm G1 with CAD
    #                                parameters (6.6 kg missing, its true COM 2 cm behind) held its COP on that
    #                                heel line after seat-off and fell back on 5 of 30 digital humans, at 1 cm on 1
    #                                (identified: 30 of 30 either way)
    limit_horizon_s: float = 0.05  # joint position limits: the acceleration that stops a joint at its limit this
    #                                far ahead
    limit_contact_rad: float = 0.01  # a joint this close to its limit (now or ``limit_horizon_s`` ahead) rests on
    #                                  its mechanical stop, which takes any torque pushing it further
    torque_weight: float = 100.0   # on ((tau - the plan's tau) / limit)^2 where the plan has torques (optimised):
    #                                30 TALOS and 30 iCub digital humans (CAD) stood alike at 0 and 100 (COM
    #                                +0.02 and +0.00 cm median, TALOS's steps at a torque limit 12.9 -> 12.0 %);
    #                                at 1000 the elderly rise's COM tracking 2.6 -> 3.0 cm, at 1e4 it fell


@dataclass
class Reference:
    """What the QP tracks at one instant: a full configuration with its velocity and acceleration (Pinocchio
    tangent order, feet-consistent), and the COM's."""

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    com: np.ndarray
    com_v: np.ndarray
    com_a: np.ndarray
    tau: np.ndarray | None = None   # (nv - 6,) the joint torques the plan asks [N m] (its optimisation's), if any


@dataclass
class WbcResult:
    """One solved step."""

    a: np.ndarray                  # (nv,) generalised acceleration
    tau: np.ndarray                # (nv - 6,) joint torques [N m]
    feet_forces: np.ndarray        # (8, 3) corner forces [N], left sole's four then right's
    seat_force: np.ndarray         # (3,) [N]
    cop: np.ndarray                # (3,) the feet's centre of pressure on the floor [m]; NaN when unloaded
    corners: np.ndarray            # (8, 3) where the corner forces act [m]
    com: np.ndarray                # (3,) COM of the state [m]
    solved: bool
    qp_s: float                    # wall time of matrix building + solve [s]
    qp_cpu_s: float                # this thread's CPU time for the same [s] (apart from a shared host's steal)


def friction_generators(mu: float) -> np.ndarray:
    """(3, 4): the edges of the friction pyramid |f_x|, |f_y| <= mu / sqrt(2) f_z inscribed in the cone of
    coefficient ``mu`` (world z normal), each of unit f_z: a force lies in the pyramid exactly when it is a
    nonnegative combination of them."""
    m = mu / np.sqrt(2.0)
    return np.array([[m, m, 1.0], [m, -m, 1.0], [-m, m, 1.0], [-m, -m, 1.0]]).T


@dataclass
class PostureCost:
    """The QP cost's constant part: the posture weights per tangent coordinate (the base's translation left to the
    COM task) and the Hessian they make with the forces' regularisation, standing and seated."""

    weights: np.ndarray
    weights_seated: np.ndarray
    H0: np.ndarray
    H0_seated: np.ndarray

    @staticmethod
    def of(g: WbcGains, nv: int, force_hessian: np.ndarray) -> PostureCost:
        """For ``nv`` tangent coordinates and the forces' regularisation over the edges' coefficients."""
        weights = np.full(nv, g.posture_weight)
        weights[:3] = 0.0                 # base translation: the COM task's
        weights[3:6] = g.base_orientation_weight
        seated = weights.copy()
        seated[3:6] = g.base_orientation_weight_seated
        H0 = [np.zeros((nv + len(force_hessian),) * 2) for _ in range(2)]
        for H, w in zip(H0, (weights, seated)):
            H[:nv, :nv] = np.diag(w)
            H[nv:, nv:] = force_hessian
        return PostureCost(weights, seated, *H0)

    def at(self, seated: bool) -> tuple[np.ndarray, np.ndarray]:
        """(weights, H0) while the seat carries weight or not."""
        return (self.weights_seated, self.H0_seated) if seated else (self.weights, self.H0)


@dataclass
class QpWorkspace:
    """The arrays a step fills in place: the points' force Jacobian, the contact rows and right-hand side, the
    corners' positions, the COM Jacobian."""

    Jf: np.ndarray          # (3 points, nv): each contact point's linear Jacobian, world axes
    A_c: np.ndarray         # (n_eq - 6, nv)
    b_c: np.ndarray         # (n_eq - 6,)
    corners: np.ndarray     # (8, 3) [m]
    jcom: np.ndarray        # (3, nv)


class WholeBodyQP:
    """Task-space inverse dynamics (see the module docstring).

    Args:
        model: the robot model with the parameters the controller knows (identified or CAD; never the plant's truth).
        seat_frame: id of the pelvis frame the seat carries (:func:`~sit2stand.robot.model.add_seat_frame`; None: none).
        gains: tasks' gains and weights.
        seat_contact: the seat point is a contact of the QP, its force unknowns (the plan's dynamics filter);
            False: the seat acts only as a known force (the robot's controller: its force comes from the feet's
            sensors), and the QP has its unknowns and three equalities fewer.
    """

    def __init__(self, model: pin.Model, seat_frame: int | None, gains: WbcGains | None = None,
                 seat_contact: bool = True) -> None:
        self.model, self.data = model, model.createData()
        self.g = gains or WbcGains()
        self.soles = [model.getFrameId(f"sole_{s}") for s in SIDES]
        self.seat = seat_frame
        self.seat_contact = seat_contact and seat_frame is not None
        self.nv = nv = model.nv
        self.n_points = 4 * len(self.soles) + self.seat_contact
        self.n = nv + GENERATORS * self.n_points
        self.n_eq = 6 + 6 * len(self.soles) + 3 * self.seat_contact     # with the seat's rows
        self.tau_max = model.effortLimit[6:].copy()
        self._q_limits = model.lowerPositionLimit[7:].copy(), model.upperPositionLimit[7:].copy()
        self.mass = float(pin.computeTotalMass(model))
        self._qp = WarmQp()
        # a point's force [N] from its edges' coefficients: FORCE_UNIT_N * force_map @ lambda
        self.force_map = np.kron(np.eye(self.n_points), friction_generators(self.g.friction))
        # the cost's constant part: posture weights and force regularisation (in FORCE_UNIT_N), the seat's normal
        # force more (the feet carry what they can)
        fw = np.full(3 * self.n_points, self.g.force_weight)
        if self.seat_contact:
            fw[-1] += self.g.seat_force_weight
        force_hessian = FORCE_UNIT_N**2 * (self.force_map.T * fw) @ self.force_map
        force_hessian += np.diag(np.full(self.n_f, GENERATOR_WEIGHT_SHARE * self.g.force_weight * FORCE_UNIT_N**2))
        self._posture = PostureCost.of(self.g, nv, force_hessian)
        # the corners in their sole's frame, and a corner's velocity in its sole's axes from the sole's 6D one
        # (LOCAL: v, omega): v + omega x r = K_i (v, omega), K_i = [I, -[r_i]x]; constant, the corners fixed on it
        corners = sole_corners_local(profile_of(model), self.g.cop_margin_m)
        self._corner_map = corners, np.concatenate([np.broadcast_to(np.eye(3), (4, 3, 3)), -skew_rows(corners)],
                                                   axis=2)
        self._ws = QpWorkspace(np.zeros((3 * self.n_points, nv)), np.zeros((self.n_eq - 6, nv)),
                               np.zeros(self.n_eq - 6), np.zeros((4 * len(self.soles), 3)), np.zeros((3, nv)))
        self.redundant_contacts = profile_of(model).redundant_sole_contacts

    @property
    def nj(self) -> int:
        """Actuated joints."""
        return self.nv - 6

    @property
    def n_f(self) -> int:
        """Force unknowns: the edges' coefficients, ``GENERATORS`` per contact point."""
        return self.n - self.nv

    @property
    def fallback_solves(self) -> int:
        """The steps the compiled active set gave up on and DAQP solved (all of them without a C compiler)."""
        return self._qp.daqp_solves

    # -- matrices ---------------------------------------------------------------------------------------------
    def _kinematics(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """M and h = C v + g at (q, v); fills data with Jacobians and zero-acceleration drifts. The passes this QP
        needs (half the time of ``computeAllTerms``, which computes the centroidal terms and energies too)."""
        model, data = self.model, self.data
        pin.crba(model, data, q)
        M = data.M.copy()                     # whole: Pinocchio 4's crba fills both triangles
        h = pin.nonLinearEffects(model, data, q, v).copy()
        pin.computeJointJacobians(model, data, q)
        pin.forwardKinematics(model, data, q, v, np.zeros(self.nv))     # a = 0: the drifts
        pin.centerOfMass(model, data, pin.KinematicLevel.ACCELERATION)
        self._ws.jcom[:] = pin.jacobianCenterOfMass(model, data)
        pin.updateFramePlacements(model, data)
        return M, h

    def _contacts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Force Jacobian Jf (3 points, nv) (the corner and seat points' linear Jacobians in world axes, stacked),
        the contact rows (A_c, b_c) of the soles and the seat (A_c a = b_c), and the corners' positions (8, 3):
        arrays the QP owns, filled in place."""
        model, data = self.model, self.data
        ws = self._ws
        Jf, A_c, b_c, corners = ws.Jf, ws.A_c, ws.b_c, ws.corners
        corner_local, corner_map = self._corner_map
        for k, fid in enumerate(self.soles):
            J6 = pin.getFrameJacobian(model, data, fid, pin.LOCAL)
            drift = pin.getFrameAcceleration(model, data, fid, pin.LOCAL).vector
            vel = pin.getFrameVelocity(model, data, fid, pin.LOCAL).vector
            A_c[6 * k:6 * k + 6] = J6
            b_c[6 * k:6 * k + 6] = -drift - self.g.foot_kd * vel
            oMf = data.oMf[fid]
            R = oMf.rotation
            # the corners' velocities in world axes: R K_i J6 v
            np.matmul((R @ corner_map).reshape(12, 6), J6, out=Jf[12 * k:12 * k + 12])
            corners[4 * k:4 * k + 4] = oMf.translation + corner_local @ R.T
        s = 6 * len(self.soles)
        if self.seat_contact:
            Js = self._seat_jacobian()
            Jf[-3:], A_c[s:] = Js, Js
            b_c[s:] = -pin.getFrameClassicalAcceleration(model, data, self.seat, pin.LOCAL_WORLD_ALIGNED).linear
        return Jf, A_c, b_c, corners

    def _seat_jacobian(self) -> np.ndarray:
        """(3, nv): the seat point's linear Jacobian in world axes."""
        return pin.getFrameJacobian(self.model, self.data, self.seat, pin.LOCAL_WORLD_ALIGNED)[:3]

    def _cost(self, q: np.ndarray, v: np.ndarray, ref: Reference, seated: bool, H: np.ndarray, c: np.ndarray
              ) -> None:
        """H, c (filled in place) of the weighted tasks over x = (a, lambda); ``seated``: the seat carries weight."""
        g, nv = self.g, self.nv
        weights, H0 = self._posture.at(seated)
        H[:] = H0                              # posture weights, force regularisation
        c[:] = 0.0
        # posture (base orientation and joints): a = a*
        a_post = ref.a + g.posture_kp * pin.difference(self.model, q, ref.q) + g.posture_kd * (ref.v - v)
        c[:nv] -= weights * a_post
        # COM: Jcom a + drift = a_com*
        com, vcom, drift = self.data.com[0], self.data.vcom[0], self.data.acom[0]
        a_com = ref.com_a + g.com_kp * (ref.com - com) + g.com_kd * (ref.com_v - vcom)
        J = self._ws.jcom
        H[:nv, :nv] += (g.com_weight * J).T @ J
        c[:nv] -= g.com_weight * J.T @ (a_com - drift)

    def _torque_task(self, H: np.ndarray, c: np.ndarray, T: np.ndarray, offset: np.ndarray) -> None:
        """``torque_weight`` |(T x + offset) / limit|^2 added to H, c in place: T x + h_j is the joint torques,
        offset h_j - the plan's torques."""
        WT = (self.g.torque_weight / self.tau_max**2)[:, None] * T
        H += T.T @ WT
        c += WT.T @ offset

    def _independent_contact_rows(self, A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The contact rows A a = b replaced by their independent combinations (U^T A for A = U S V^T), less those
        along a singular value under ``CONTACT_DEPENDENT_SV_RATIO`` of the largest (left free): legs without an
        ankle roll make the soles' rows dependent wherever the hips' roll axes are aligned, and there a drift off
        their range asks an infinite acceleration."""
        U, S, Vt = np.linalg.svd(A, full_matrices=False)
        held = S >= CONTACT_DEPENDENT_SV_RATIO * S[0]
        return (S[:, None] * Vt)[held], (U.T @ b)[held]

    def _joint_limits(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The joint accelerations that keep each joint inside its limits ``limit_horizon_s`` ahead (lower, upper),
        and the joints on (or reaching within that horizon) their lower and upper mechanical stops."""
        eps, H = self.g.limit_contact_rad, self.g.limit_horizon_s
        q_ahead = q[7:] + v[6:] * H
        q_lo, q_hi = self._q_limits
        a_hi = 2.0 / H**2 * (q_hi - q_ahead)
        a_lo = 2.0 / H**2 * (q_lo - q_ahead)
        return a_lo, np.maximum(a_hi, a_lo), q_ahead <= q_lo + eps, q_ahead >= q_hi - eps

    # -- solve ------------------------------------------------------------------------------------------------
    def _problem(self, q: np.ndarray, v: np.ndarray, M: np.ndarray, h: np.ndarray, Jg: np.ndarray,
                 seat_force_max_n: float) -> QpProblem:
        """The step's QP (see the module docstring) but its cost: equalities A x = b (the base's Newton-Euler rows,
        then the contacts'), inequality rows C x >= d (the joint torques above their lower limits, below their
        upper ones, the seat's normal force under its cap), and the bounds of x. ``Jg`` (n_f, nv): each edge
        coefficient's Jacobian, whose transpose maps it to generalised forces."""
        nv, nj, ws = self.nv, self.nj, self._ws
        seat_on = self.seat_contact and seat_force_max_n > 0
        rows = 6 * len(self.soles) + 3 * seat_on
        A_c, b_c = ws.A_c[:rows], ws.b_c[:rows]
        if self.redundant_contacts:
            A_c, b_c = self._independent_contact_rows(A_c, b_c)
        p = self._qp.problem(self.n, 6 + len(b_c), 2 * nj + self.seat_contact)
        p.A[:6, :nv] = M[:6]                                            # the base's Newton-Euler rows
        np.multiply(Jg[:, :6].T, -FORCE_UNIT_N, out=p.A[:6, nv:])
        np.negative(h[:6], out=p.b[:6])
        p.A[6:, :nv], p.A[6:, nv:], p.b[6:] = A_c, 0.0, b_c                # the contacts
        T = p.C[:nj]                                                     # the joint torques, less h_j
        T[:, :nv] = M[6:]
        np.multiply(Jg[:, 6:].T, -FORCE_UNIT_N, out=T[:, nv:])
        np.negative(T, out=p.C[nj:2 * nj])
        p.lo[6:nv], p.hi[6:nv], at_lo, at_hi = self._joint_limits(q, v)
        np.subtract(-self.tau_max, h[6:], out=p.d[:nj])
        np.subtract(h[6:], self.tau_max, out=p.d[nj:2 * nj])
        p.d[:nj][at_hi] = -INF                 # the stop at the upper limit pushes down: any demand below
        p.d[nj:2 * nj][at_lo] = -INF
        p.lo[:6], p.hi[:6], p.lo[nv:], p.hi[nv:] = -INF, INF, 0.0, INF
        if self.seat_contact:                  # the seat's normal force: the sum of its edges' coefficients
            p.C[-1], p.C[-1, -GENERATORS:] = 0.0, -1.0
            p.d[-1] = -seat_force_max_n / FORCE_UNIT_N if seat_on else -INF
            if not seat_on:
                p.hi[-GENERATORS:] = 0.0
        return p

    def _solve_qp(self, p: QpProblem) -> tuple[np.ndarray, bool]:
        """x minimising the problem, and whether it was solved; where it has no solution, DAQP's last iterate (zero
        where that is not finite: a NaN torque would end the simulation)."""
        x = self._qp.solve_problem(p)
        if x is not None:
            return x, True
        upper = np.concatenate((p.hi, p.b, np.full(len(p.d), INF)))
        lower = np.concatenate((p.lo, p.b, p.d))
        sense = np.zeros(len(upper), np.int32)
        sense[self.n:self.n + len(p.b)] = 5            # DAQP: an equality
        x = daqp.solve(p.H, p.g, p.rows(), upper, lower, sense)[0]
        return (x if np.isfinite(x).all() else np.zeros(self.n)), False

    def solve(self, q: np.ndarray, v: np.ndarray, ref: Reference, seat_force_max_n: float = 0.0,
              seat_force_known_n: np.ndarray | None = None) -> WbcResult:
        """One QP at the state (q, v) for ``ref``; the seat point is a contact while ``seat_force_max_n`` > 0.
        ``seat_force_known_n``: a measured (estimated) force of the seat on the pelvis [N, world axes], taken as a
        known external force instead (what a robot without a sensor under its pelvis does)."""
        t0, cpu0 = time.perf_counter(), time.thread_time()
        nv, nj = self.nv, self.nj
        M, h = self._kinematics(q, v)
        Jf, _, _, corners = self._contacts()
        if seat_force_known_n is not None and self.seat is not None:
            h = h - self._seat_jacobian().T @ np.asarray(seat_force_known_n, float)
        Jg = self.force_map.T @ Jf
        p = self._problem(q, v, M, h, Jg, seat_force_max_n)
        seat_on = self.seat_contact and seat_force_max_n > 0
        self._cost(q, v, ref, seat_on or seat_force_known_n is not None, p.H, p.g)
        if ref.tau is not None and self.g.torque_weight > 0:           # toward the plan's torques
            self._torque_task(p.H, p.g, p.C[:nj], h[6:] - ref.tau)
        x, solved = self._solve_qp(p)
        a, f = x[:nv], FORCE_UNIT_N * (self.force_map @ x[nv:])
        tau = M[6:] @ a + h[6:] - Jf[:, 6:].T @ f
        np.minimum(np.maximum(tau, -self.tau_max, out=tau), self.tau_max, out=tau)    # the stops take the rest
        n_feet = 3 * len(corners)
        feet = f[:n_feet].reshape(-1, 3)
        fz = feet[:, 2].sum()
        cop = (feet[:, 2] @ corners) / fz if fz > 1.0 else np.full(3, np.nan)
        seat_force = f[n_feet:].copy() if self.seat_contact else np.zeros(3)
        return WbcResult(a, tau, feet, seat_force, cop, corners.copy(), self.data.com[0].copy(), solved,
                         time.perf_counter() - t0, time.thread_time() - cpu0)


_IDENTITY_XYZQUAT = pin.SE3ToXYZQUAT(pin.SE3.Identity())


def feet_anchored_reference(model: pin.Model, data: pin.Data, q: np.ndarray, v_joints: np.ndarray,
                            a_joints: np.ndarray, oM_left_sole: pin.SE3, left_sole: int | None = None) -> Reference:
    """The full reference of joint positions, velocities and accelerations ``q[7:]``, ``v_joints``, ``a_joints``
    with the left sole held at ``oM_left_sole``: the base placement, velocity and acceleration that keep it there
    (both soles, when the joints are a double-support plan), and the COM's. ``q``'s base part is ignored.
    ``left_sole``: the left sole's frame id, when the caller has it."""
    nv = model.nv
    q = q.copy()
    q[:7] = _IDENTITY_XYZQUAT
    fid = model.getFrameId("sole_left") if left_sole is None else left_sole
    pin.forwardKinematics(model, data, q)
    base_to_sole = pin.updateFramePlacement(model, data, fid).copy()
    q[:7] = pin.SE3ToXYZQUAT(oM_left_sole * base_to_sole.inverse())
    # the sole's LOCAL velocity is X v_base + J_joints v_joints, X the motion transform from the base to the sole:
    # the base's velocity (and acceleration) that holds the sole is -X^-1 times the rest, X^-1 = base_to_sole's
    to_base = base_to_sole.action
    v = np.zeros(nv)
    v[6:] = v_joints
    J_joints = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)[:, 6:]
    v[:6] = -to_base @ (J_joints @ v_joints)
    a = np.zeros(nv)
    a[6:] = a_joints
    pin.forwardKinematics(model, data, q, v, a)
    a[:6] = -to_base @ pin.getFrameAcceleration(model, data, fid, pin.LOCAL).vector
    pin.centerOfMass(model, data, q, v, a)
    return Reference(q, v, a, data.com[0].copy(), data.vcom[0].copy(), data.acom[0].copy())
