"""Whole-rise optimal control: the per-frame IK plan made dynamically feasible as one problem, at the human's timing.

The per-frame IK (Mistry et al. 2010) gives a pose per frame with the COM on the mapped human's; nothing in it knows
forces, so played at the human's speed it can ask for torques past the motors' limits or a centre of pressure
outside the soles. Here the whole rise is one multiple-shooting optimal-control problem (Crocoddyl's contact forward
dynamics, solved by box-FDDP): a knot every ``knot_period_s``; while the plan is seated the feet and the seat
carry the robot (6D contacts at the soles, a 3D contact at the ``seat`` frame under the buttocks), after the human's
seat-off the feet alone. It spans the plan's motion (:meth:`WholeRiseProblem.moving`); the still seated start and
standing end keep the plan's poses. Every knot costs the COM's distance to the plan's (the mapped human COM), the
markers' distances to the human's (the IK's marker tasks, with their weights), the posture's and velocity's distance
to the IK's, and the torques over their limits; the contact wrenches are kept in their cones (friction, centre of
pressure ``cop_margin_m`` inside the soles, the seat's friction cone) by barriers; torques are boxed by the URDF's
limits and joint speeds by ``max_joint_speed``. The last knot is the IK's standing end posture, at rest. The problem
is warm-started from the plan player's smoothed poses and velocities, with contact-consistent inverse-dynamics torques.

The rise is played at the human's timing when the solution is one: dynamically consistent, the contact forces inside
their cones, every loaded sole's centre of pressure at least half ``cop_side_margin_m`` inside it, the COM within
``com_tolerance_m`` of the plan's. Otherwise the problem is solved again a little slower (``time_scale`` up by
``scale_step``, the knots' period with it) until one is, and the factor is reported; where none is, the first try
whose COM stays within ``com_relaxed_tolerance_m`` and passes the other checks is taken. :func:`optimised_player`
then plays whichever of the optimised and the per-frame plan the player's own checks play shorter.

Units SI; world frame REP-103 (x forward, y left, z up).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import crocoddyl
import numpy as np
import pinocchio as pin

from ..dynamics import G
from ..errors import Sit2StandError
from ..robot.model import SIDES
from ..robot.plant import contact_joint_torques
from ..robot.profile import profile_of
from ..scheduling import hold_openmp_threads
from .player import PlanPlayer
from .solve_end import Progress, SolveEnd

FRICTION = 0.7
"""The feet's and the seat's friction coefficient in the cones (rubber soles on the floor, cloth on a seat)."""
COP_LOAD_SHARE = 0.02
"""A sole's centre of pressure counts in a solution's check where the sole carries at least this share of the
robot's weight: a lighter one tips nothing (TALOS: 20 N at most 0.1 m from the sole's centre, 2 N m), and its centre
of pressure, a moment over a small force, swings with the last bits of the plan (a left sole at 2 N lay 0.95 or
2 cm inside its edge in two runs of the same rise, the plans 1e-14 apart)."""
ROOT_JOINT = "root_joint"
"""Crocoddyl's floating-base actuation finds the free flyer by this name."""


def knot_frames(n: int, every: int) -> list[int]:
    """The plan frames (of ``n``) the problem has a knot at: every ``every``-th, and the last."""
    knots = list(range(0, n, every))
    return knots if knots[-1] == n - 1 else [*knots, n - 1]


class WholeRiseError(Sit2StandError, RuntimeError):
    """The optimal-control problem cannot be made for this robot model (a frame it needs is missing)."""


@dataclasses.dataclass(frozen=True)
class WholeRiseConfig:
    """The whole-rise problem's settings (weights are Crocoddyl's: cost = 0.5 w |r|^2)."""

    knot_period_s: float = 0.02          # a knot every this long at the human's timing, in whole frames [s]
    threads: int = 1                     # Crocoddyl's threads for the knots (a batch's case: 1; `retarget`: the
    #                                      usable cores, on 2 idle cores 1.3x faster)
    iterations: int = 150                # box-FDDP iterations per time scale tried, at most (at 100, 4 of TALOS's
    #                                      30 identified digital humans ended the try at 1.0 still converging, the
    #                                      COM 3-4 cm off, and played at 1.05-1.065; at 150, at 1.000-1.006)
    regularisation: float = 1e-4         # box-FDDP's first regularisation (at Crocoddyl's 1e-9 its first full steps
    #                                      are rejected while the gaps close: natural 60 -> 28 iterations)
    passed_iterations: int = 5           # a solve ends once its solution has passed its checks this many
    passed_cost_share: float = 1e-2      # iterations running, its cost falling less than this share over them
    plateau_iterations: int = 5          # ... or once its rollout is feasible and its cost fell less than
    plateau_cost_share: float = 1e-3     # this share over this many iterations (box-FDDP's own gradient test
    #                                      rarely ends it: the cost flat to 4 digits, the step lengths cycling)
    com_weight: float = 1e4              # per knot, on the COM [m]
    marker_weight: float = 10.0          # per knot, times each marker task's own weight, on the position [m]
    posture_weight: float = 1.0          # on the joints' distance to the IK's [rad]
    lateral_weight: float = 10.0         # ... on the lateral joints' (trunk and hip yaw and roll, ankle roll:
    #                                      RobotProfile.lateral_joints), which the IK holds near the seated pose
    velocity_weight: float = 0.1         # on the joints' speed's distance to the IK's [rad/s]
    torque_weight: float = 1e-2          # on (tau / limit)^2
    torque_share: float = 1.0            # the torques' box: this share of the URDF limits (the rest: the robot's
    #                                      controller, which corrects what the model does not know)
    cone_weight: float = 10.0            # the contact cones' barriers
    redundant_damping: float = 1e-4      # the contact dynamics' damping of J M^-1 J^T where the soles' contacts
    #                                      are redundant (RobotProfile.redundant_sole_contacts), else 0.
    #                                      Undamped, G1 with fixed ankle rolls cost 1e10-1e11 on the shipped
    #                                      natural rise, the seated cones broken, no solution; at 1e-6 a solution
    #                                      from the nominal seated pose, none from the simulated robot's settled one;
    #                                      at 1e-4 and 1e-3 from both (38-58 iterations)
    end_weight: float = 100.0            # the last knot's posture (and rest) over ``posture_weight``
    seat_friction: float = 0.1           # the seat's friction coefficient in its cone: the robot's controller
    #                                      estimates the seat's force as the weight the feet do not carry (vertical)
    cop_margin_m: float = 0.04           # the centre of pressure's margin inside each sole's edges (x) [m]
    cop_side_margin_m: float = 0.02      # the same across the sole (y) [m]
    max_joint_speed: float = 4.0         # [rad/s]
    com_tolerance_m: float = 0.03        # a solution keeps every knot's COM this close to the plan's
    com_relaxed_tolerance_m: float = 0.06  # ... or this close, where no try has one within com_tolerance_m
    #                                      (H1's fast rises: its COM 4.9 cm above the plan's and 3.0 cm off it
    #                                      horizontally at every scale up to 1.5; played per frame it fell)
    force_tolerance_n: float = 5.0       # a solution's largest contact force outside its cone [N]
    scale_step: float = 0.05             # how much slower each retry is played
    max_time_scale: float = 1.5
    still_joint_rad: float = 0.035       # the plan is still while every joint is this close to its first (or its
    #                                      last) pose [rad] (2 deg; the smoothed plan's own start and end move ~0.5)
    still_margin_s: float = 0.2          # the still frames kept before the plan's motion [s]
    still_end_s: float = 0.8             # ... and after it, where the last knot is at rest [s]
    max_knots: int = 400                 # longer plans are not optimised: a knot holds ~8 MB (each cost term keeps
    #                                      its own derivatives; 196 knots: 1.7 GB), and a five-cycle trial ran out

    def frames_per_knot(self, frame_period_s: float) -> int:
        """The plan frames between two knots for frames ``frame_period_s`` apart (at least one)."""
        return max(1, int(round(self.knot_period_s / frame_period_s)))


@dataclasses.dataclass
class WholeRise:
    """The optimised rise, resampled at the plan's frames; and how it was found."""

    q: np.ndarray                  # (N, nq) per plan frame
    tau: np.ndarray                # (K - 1, nq - 7) the joint torques [N m] between the K knots
    knot_t_s: np.ndarray           # (K,) the knots' robot times from the first [s]
    time_scale: float              # the plan played this many times slower than the human (1: the human's timing)
    converged: bool                # the solver met its stopping criterion at that scale
    feasible: bool                 # a solution (see the module docstring) at that scale
    iterations: int
    solve_s: float                 # wall time of all the solves [s]
    knots: int
    com_error_rms_m: float         # the knots' COM against the plan's
    com_error_max_m: float
    torque_saturated_share: float  # knots with a joint torque at its limit
    cop_margin_min_m: float        # the smallest centre-of-pressure margin inside a sole on the feet
    span: tuple[int, int] = (0, 0)  # the first and last plan frames optimised (:meth:`WholeRiseProblem.moving`)
    com_relaxed: bool = False      # a solution only within ``com_relaxed_tolerance_m`` (see solve)
    tries: list[tuple[float, bool]] = dataclasses.field(default_factory=list)  # (time scale, within com_tolerance_m)
    threads: int = 1               # the solves' threads (WholeRiseConfig.threads)

    def torque_at(self, t_plan_s: float, frame_period_s: float) -> np.ndarray | None:
        """The joint torques [N m] the optimisation asks at the plan's human time ``t_plan_s`` [s from its first
        frame] (each knot interval's torques at its middle, linear between; frames ``frame_period_s`` apart), or
        None outside the span it optimised."""
        knot_t = self.span[0] * frame_period_s + self.knot_t_s / self.time_scale
        if not knot_t[0] <= t_plan_s <= knot_t[-1] or len(self.tau) == 0:
            return None
        middle = 0.5 * (knot_t[:-1] + knot_t[1:])
        return np.array([np.interp(t_plan_s, middle, self.tau[:, j]) for j in range(self.tau.shape[1])])

    def summary(self) -> dict:
        """The figures for ``summary.json`` (``whole_rise_*``)."""
        return {"whole_rise_time_scale": self.time_scale, "whole_rise_feasible": self.feasible,
                "whole_rise_converged": self.converged, "whole_rise_iterations": self.iterations,
                "whole_rise_solve_s": self.solve_s, "whole_rise_threads": self.threads, "whole_rise_knots": self.knots,
                "whole_rise_com_error_rms_m": self.com_error_rms_m, "whole_rise_com_error_max_m": self.com_error_max_m,
                "whole_rise_torque_saturated_share": self.torque_saturated_share,
                "whole_rise_cop_margin_min_m": self.cop_margin_min_m, "whole_rise_span_frames": list(self.span),
                "whole_rise_com_relaxed": self.com_relaxed,
                "whole_rise_tries": [[s, ok] for s, ok in self.tries]}


@dataclasses.dataclass
class RisePlan:
    """The IK's plan the problem starts from: a pose per frame, its COM, whether it is seated, its marker tasks."""

    q: np.ndarray                  # (N, nq)
    com: np.ndarray                # (N, 3) [m]
    seated: np.ndarray             # (N,) bool
    markers: list                  # per frame: [(frame id, target (3,) [m], weight)]
    dt: float                      # the frames' period [s]
    v: np.ndarray | None = None    # (N, nv) the poses' velocities at the human's timing (None: differences)
    a: np.ndarray | None = None    # (N, nv) their accelerations (None: the warm start's torques are static)

    @classmethod
    def of_frames(cls, frames, dt: float,
                  smoothed: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> RisePlan:
        """From :class:`~sit2stand.retarget.stream.RetargetFrame` s; ``smoothed``: their poses and velocities as the
        plan player smooths them, with their velocities and accelerations
        (:meth:`~sit2stand.retarget.player.PlanPlayer.smoothed`), which the problem then starts from and tracks (the
        IK's raw poses carry the markers' noise into their velocities)."""
        q, v, a = smoothed if smoothed is not None else (np.array([f.q for f in frames]), None, None)
        return cls(q, np.array([f.com for f in frames]), np.array([f.seated for f in frames]),
                   [f.markers for f in frames], dt, v, a)


class WholeRiseProblem:
    """The whole-rise problem for one robot model (with its ``sole_*``, ``seat`` and marker frames)."""

    def __init__(self, model: pin.Model, config: WholeRiseConfig | None = None) -> None:
        self.cfg = config or WholeRiseConfig()
        self.model = pin.Model(model)
        if self.model.names[1] != ROOT_JOINT:
            self.model.names[1] = ROOT_JOINT
        self.profile = profile_of(model)
        sole = self.profile.sole
        self.sole_ids = [self._sole_centre(s, sole.centre_x_m) for s in SIDES]
        if not self.model.existFrame("seat"):
            raise WholeRiseError("the robot model has no 'seat' frame (robot.model.add_seat_frame)")
        self.seat_id = self.model.getFrameId("seat")
        self.data = self.model.createData()
        self.cop_box = 2.0 * np.array([sole.half_size_m[0] - self.cfg.cop_margin_m,
                                       sole.half_size_m[1] - self.cfg.cop_side_margin_m])
        self.state = crocoddyl.StateMultibody(self.model)
        self.actuation = crocoddyl.ActuationModelFloatingBase(self.state)
        self.nu = self.actuation.nu
        self.limit = self.cfg.torque_share * self.model.effortLimit[6:]
        self.cop_load_n = COP_LOAD_SHARE * float(pin.computeTotalMass(self.model)) * G
        self.posture_w = self._posture_weights()

    def _posture_weights(self) -> np.ndarray:
        """(nv - 6,) the posture cost's weight per joint velocity coordinate: ``lateral_weight`` on the lateral
        joints, ``posture_weight`` on the rest."""
        w = np.full(self.model.nv - 6, self.cfg.posture_weight)
        for name in self.profile.lateral_joints():
            if self.model.existJointName(name):
                w[self.model.joints[self.model.getJointId(name)].idx_v - 6] = self.cfg.lateral_weight
        return w

    def _sole_centre(self, side: str, centre_x_m: float) -> int:
        """A frame at the middle of a sole (the wrench cone's centre of pressure box is centred on its frame)."""
        f = self.model.frames[self.model.getFrameId(f"sole_{side}")]
        at = f.placement * pin.SE3(np.eye(3), np.array([centre_x_m, 0.0, 0.0]))
        return self.model.addFrame(pin.Frame(f"sole_centre_{side}", f.parentJoint, at, pin.FrameType.OP_FRAME))

    # -- the problem -------------------------------------------------------------------------------------------
    def solve(self, plan: RisePlan, first_scale: float = 1.0, progress: Progress | None = None,
              max_time_scale: float | None = None) -> WholeRise:
        """The rise at the human's timing (``first_scale`` x slower) when it has a solution there, else at the least
        slower scale that has one (see the module docstring); the last tried when none up to ``max_time_scale``
        (default and at most the config's; the first scale is always tried) has. ``progress``: told each try and,
        during it, the cost (:class:`SolveEnd`). Where no try has a solution, the first whose COM stays within
        ``com_relaxed_tolerance_m`` of the plan's, and passes the other checks, is the result (``com_relaxed``): the
        plan's COM path is then one the robot cannot follow at the scales tried, and the optimised rise, dynamically
        consistent, is the nearest to it the model has."""
        cfg, tries, spent, iters, relaxed = self.cfg, [], 0.0, 0, None
        scale, knots = float(first_scale), self.knots(plan)
        last = min(cfg.max_time_scale, max_time_scale or np.inf)
        while True:
            if progress is not None:
                progress(f"whole-rise optimisation: {len(knots)} knots at time scale {scale:.2f}")
            solver, t = self._solve_at(plan, knots, scale, progress)
            spent += t
            iters += solver.iter
            result = self._result(plan, solver, knots, scale)
            tries.append((scale, result.feasible))
            if progress is not None:
                progress(f"  {solver.iter} iterations, {t:.1f} s: {'a' if result.feasible else 'no'} solution")
            if relaxed is None and result.com_relaxed:
                relaxed = result
            if result.feasible or scale + cfg.scale_step > last + 1e-9:
                if not result.feasible and relaxed is not None:
                    if progress is not None:
                        progress(f"  taken: the solution at {relaxed.time_scale:.2f}, its COM within "
                                 f"{cfg.com_relaxed_tolerance_m * 100:.0f} cm of the plan's")
                    result = dataclasses.replace(relaxed, feasible=True)
                return dataclasses.replace(result, iterations=iters, solve_s=spent, tries=tries, threads=cfg.threads)
            del solver           # its problem's data (~8 MB a knot) before the next try's
            scale = round(scale + cfg.scale_step, 6)

    def moving(self, plan: RisePlan) -> tuple[int, int]:
        """The first and last plan frames the problem spans: ``still_margin_s`` before the first frame with a joint
        ``still_joint_rad`` off the pose ``still_margin_s`` in, to ``still_end_s`` after the last with one that far off
        the pose ``still_margin_s`` before the end (the last knot is at rest). Before and after, the plan is still
        (seated, or standing at the end), its poses statically feasible as they are: of the shipped natural rise's
        3.9 s, 0.74 s seated and 0.7 s standing; of the elderly's 5.4 s, 0.87 s and 0.1 s. The poses nearer the ends
        than the margin are the player's smoothing settling (2.5 deg in its first 5 frames)."""
        n, margin = len(plan.q), int(round(self.cfg.still_margin_s / plan.dt))
        if n <= 4 * margin + 2:
            return 0, n - 1

        def off(ref: np.ndarray, frames: range) -> np.ndarray:
            return np.array([np.abs(pin.difference(self.model, ref, plan.q[k])[6:]).max() for k in frames])
        left = np.flatnonzero(off(plan.q[margin], range(margin, n)) > self.cfg.still_joint_rad)
        right = np.flatnonzero(off(plan.q[n - 1 - margin], range(n - margin)) > self.cfg.still_joint_rad)
        lo = int(left[0]) if len(left) else 0        # margin + left[0] is the first frame off; lo a margin before
        hi = int(right[-1]) + int(round(self.cfg.still_end_s / plan.dt)) if len(right) else n - 1
        return (max(0, lo), min(n - 1, hi)) if hi - lo >= 2 else (0, n - 1)

    def knots(self, plan: RisePlan) -> list[int]:
        """The plan frames the problem has a knot at (see :meth:`moving`)."""
        lo, hi = self.moving(plan)
        return [lo + k for k in knot_frames(hi - lo + 1, self.cfg.frames_per_knot(plan.dt))]

    def _solve_at(self, plan: RisePlan, knots: list[int], scale: float, progress: Progress | None = None):
        cr = crocoddyl
        hold_openmp_threads(1)
        v = self._velocities(plan, knots, scale)
        pin.framesForwardKinematics(self.model, self.data, plan.q[knots[0]])
        feet = [self.data.oMf[i].copy() for i in self.sole_ids]
        damping = self.cfg.redundant_damping if self.profile.redundant_sole_contacts else 0.0
        running = [self._knot(plan, knots[i], v[i], feet, (knots[i + 1] - knots[i]) * plan.dt * scale, damping)
                   for i in range(len(knots) - 1)]
        terminal = self._knot(plan, knots[-1], np.zeros(self.model.nv), feet, 0.0, damping, end=True)
        x0 = np.concatenate([plan.q[knots[0]], np.zeros(self.model.nv)])
        problem = cr.ShootingProblem(x0, running, terminal)
        problem.nthreads = self.cfg.threads
        xs = [np.concatenate([plan.q[k], v[i]]) for i, k in enumerate(knots)]
        xs[0] = x0
        us = self._warm_torques(plan, knots, v, scale) if plan.a is not None else list(problem.quasiStatic(xs[:-1]))
        solver = self._solver(problem, progress, lambda s: self.passes(plan, s, knots))
        t0 = time.perf_counter()
        solver.solve(xs, us, self.cfg.iterations, False, self.cfg.regularisation)
        return solver, time.perf_counter() - t0

    def _solver(self, problem, progress: Progress | None = None, passes: Callable[[object], bool] | None = None):
        cfg, solver = self.cfg, crocoddyl.SolverBoxFDDP(problem)
        solver.th_stop = 1e-6
        solver.setCallbacks([SolveEnd(cfg.plateau_iterations, cfg.plateau_cost_share, progress, passes,
                                      cfg.passed_iterations, cfg.passed_cost_share)])
        return solver

    def _warm_torques(self, plan: RisePlan, knots: list[int], v: np.ndarray, scale: float) -> list[np.ndarray]:
        """Each knot's joint torques for the plan's own motion, the contacts taking the base's wrench in the
        least-squares sense (:func:`~sit2stand.robot.plant.contact_joint_torques`), inside the limits: the gaps
        between the knots start small, where static torques leave the rise's accelerations, and the seat-off's
        jump, to be closed."""
        out = []
        for i, k in enumerate(knots[:-1]):
            tau = pin.rnea(self.model, self.data, plan.q[k], v[i], plan.a[k] / scale ** 2)
            joints = contact_joint_torques(self.model, self.data, plan.q[k], tau, bool(plan.seated[k]))[0]
            out.append(np.clip(joints, -self.limit, self.limit))
        return out

    def _velocities(self, plan: RisePlan, knots: list[int], scale: float) -> np.ndarray:
        """The plan's velocities at the knots (its own, or central differences over the frames), played ``scale`` x
        slower."""
        if plan.v is not None:
            return plan.v[knots] / scale
        n, out = len(plan.q), np.zeros((len(knots), self.model.nv))
        for i, k in enumerate(knots):
            a, b = max(0, k - 1), min(n - 1, k + 1)
            if b > a:
                out[i] = pin.difference(self.model, plan.q[a], plan.q[b]) / ((b - a) * plan.dt * scale)
        return out

    def _knot(self, plan: RisePlan, k: int, v: np.ndarray, feet: list[pin.SE3], period_s: float, damping: float,
              end: bool = False):
        cr, cfg, state, nu = crocoddyl, self.cfg, self.state, self.nu
        contacts, costs = cr.ContactModelMultiple(state, nu), cr.CostModelSum(state, nu)
        for side, fid, placement in zip(SIDES, self.sole_ids, feet):
            contacts.addContact(f"sole_{side}", cr.ContactModel6D(state, fid, placement, pin.LOCAL, nu,
                                                                  np.array([0.0, 50.0])))
            cone = cr.WrenchCone(np.eye(3), FRICTION, self.cop_box, 4, True, 0.0, 1e4)
            costs.addCost(f"cone_{side}", self._barrier(cr.ResidualModelContactWrenchCone(state, fid, cone, nu),
                                                        cone.lb, cone.ub), cfg.cone_weight)
        if plan.seated[k]:
            pin.framesForwardKinematics(self.model, self.data, plan.q[k])
            contacts.addContact("seat", cr.ContactModel3D(state, self.seat_id, self.data.oMf[self.seat_id].translation,
                                                          pin.LOCAL_WORLD_ALIGNED, nu, np.array([0.0, 50.0])))
            cone = cr.FrictionCone(np.eye(3), cfg.seat_friction, 4, True)
            costs.addCost("cone_seat", self._barrier(cr.ResidualModelContactFrictionCone(state, self.seat_id, cone, nu),
                                                     cone.lb, cone.ub), cfg.cone_weight)
        self._tracking_costs(costs, plan, k, v, end)
        dam = cr.DifferentialActionModelContactFwdDynamics(state, self.actuation, contacts, costs, damping, True)
        dam.u_lb, dam.u_ub = -self.limit, self.limit
        return cr.IntegratedActionModelEuler(dam, period_s)

    def _tracking_costs(self, costs, plan: RisePlan, k: int, v: np.ndarray, end: bool) -> None:
        cr, cfg, state, nu, nv = crocoddyl, self.cfg, self.state, self.nu, self.model.nv
        scale = 10.0 if end else 1.0
        costs.addCost("com", cr.CostModelResidual(state, cr.ResidualModelCoMPosition(state, plan.com[k], nu)),
                      cfg.com_weight * scale)
        for fid, target, weight in plan.markers[k]:
            costs.addCost(f"marker_{fid}", cr.CostModelResidual(
                state, cr.ResidualModelFrameTranslation(state, fid, np.asarray(target, float), nu)),
                cfg.marker_weight * float(weight))
        w = np.concatenate([np.zeros(6), self.posture_w, np.zeros(6), np.full(nv - 6, cfg.velocity_weight)])
        if end:
            w = np.concatenate([np.zeros(6), self.posture_w, np.ones(nv)]) * cfg.end_weight
        x_ref = np.concatenate([plan.q[k], v])
        costs.addCost("posture", cr.CostModelResidual(state, cr.ActivationModelWeightedQuad(w ** 2),
                                                      cr.ResidualModelState(state, x_ref, nu)), 1.0)
        if end:
            return
        costs.addCost("torque", cr.CostModelResidual(state, cr.ActivationModelWeightedQuad(1.0 / self.limit ** 2),
                                                     cr.ResidualModelControl(state, nu)), cfg.torque_weight)
        big = np.full(nv, 1e9)
        lb = np.concatenate([-big, -big[:6], np.full(nv - 6, -cfg.max_joint_speed)])
        costs.addCost("joint_speed", self._barrier(cr.ResidualModelState(state, state.zero(), nu), lb, -lb),
                      cfg.cone_weight)

    def _barrier(self, residual, lb: np.ndarray, ub: np.ndarray):
        cr = crocoddyl
        return cr.CostModelResidual(self.state, cr.ActivationModelQuadraticBarrier(cr.ActivationBounds(lb, ub)),
                                    residual)

    # -- the outcome -------------------------------------------------------------------------------------------
    def _com_errors(self, plan: RisePlan, solver, knots: list[int]) -> np.ndarray:
        """Each knot's COM distance to the plan's [m]."""
        nq = self.model.nq
        com = np.array([pin.centerOfMass(self.model, self.data, x[:nq]) for x in solver.xs])
        return np.linalg.norm(com - plan.com[knots], axis=1)

    def _passed(self, solver, com_errors: np.ndarray, margins: float, violation: float, relaxed: bool = False) -> bool:
        """The checks of :meth:`passes`; ``relaxed``: the COM within ``com_relaxed_tolerance_m``."""
        cfg = self.cfg
        tolerance = cfg.com_relaxed_tolerance_m if relaxed else cfg.com_tolerance_m
        return bool(solver.ffeas <= 1e-5 and violation <= cfg.force_tolerance_n
                    and margins >= 0.5 * cfg.cop_side_margin_m and float(com_errors.max()) <= tolerance)

    def passes(self, plan: RisePlan, solver, knots: list[int]) -> bool:
        """Whether the solver's current solution is one: no gaps, every knot's COM within ``com_tolerance_m`` of the
        plan's, the contact forces in their cones within ``force_tolerance_n``, the soles' centres of pressure at
        least half ``cop_side_margin_m`` inside them."""
        return self._passed(solver, self._com_errors(plan, solver, knots), *self._contact_figures(solver))

    def _result(self, plan: RisePlan, solver, knots: list[int], scale: float) -> WholeRise:
        nq = self.model.nq
        xs, us, err = np.array(solver.xs), np.array(solver.us), self._com_errors(plan, solver, knots)
        margins, violation = self._contact_figures(solver)
        feasible = self._passed(solver, err, margins, violation)
        return WholeRise(self._resampled(xs[:, :nq], knots, plan.q), us, (np.array(knots) - knots[0]) * plan.dt * scale,
                         scale, bool(solver.isFeasible and solver.stop <= solver.th_stop),
                         feasible, solver.iter, 0.0, len(knots), float(np.sqrt(np.mean(err ** 2))), float(err.max()),
                         float(np.mean(np.any(np.abs(us) >= 0.999 * self.limit, axis=1))), margins,
                         (knots[0], knots[-1]),
                         com_relaxed=not feasible and self._passed(solver, err, margins, violation, relaxed=True))

    def _contact_figures(self, solver) -> tuple[float, float]:
        """(the smallest centre-of-pressure margin inside a sole that carries load (:data:`COP_LOAD_SHARE`) over
        the knots [m], the largest force outside its friction cone or pulling [N])."""
        half = self.profile.sole.half_size_m
        margin, violation = np.inf, 0.0
        for d in solver.problem.runningDatas:
            for name, c in d.differential.multibody.contacts.contacts.todict().items():
                f, fz = c.f.linear, float(c.f.linear[2])
                mu = self.cfg.seat_friction if name == "seat" else FRICTION
                violation = max(violation, -fz, float(np.hypot(f[0], f[1])) - mu * max(fz, 0.0))
                if name != "seat" and fz > self.cop_load_n:
                    cop = np.array([-c.f.angular[1], c.f.angular[0]]) / fz
                    margin = min(margin, float(min(half[0] - abs(cop[0]), half[1] - abs(cop[1]))))
        return margin, violation

    def _resampled(self, qs: np.ndarray, knots: list[int], plan_q: np.ndarray) -> np.ndarray:
        """The knots' poses at every plan frame (interpolated on the configuration space); before the first knot the
        plan's own poses (the first knot is the plan's pose there), after the last the plan's motion from there
        added to the last knot's pose."""
        out = plan_q.copy()
        for i in range(len(knots) - 1):
            lo, hi = knots[i], knots[i + 1]
            for k in range(lo, hi):
                out[k] = pin.interpolate(self.model, qs[i], qs[i + 1], (k - lo) / (hi - lo))
        for k in range(knots[-1], len(plan_q)):
            out[k] = pin.integrate(self.model, qs[-1], pin.difference(self.model, plan_q[knots[-1]], plan_q[k]))
        return out


def optimised_player(model: pin.Model, frames, player: PlanPlayer, *, config: WholeRiseConfig | None = None,
                     first_scale: float = 1.0, identified: bool = False, progress: Progress | None = None
                     ) -> tuple[WholeRise | None, PlanPlayer, dict]:
    """The whole rise of ``frames`` (:class:`~sit2stand.retarget.stream.RetargetFrame` s, the retargeter's
    ``model``) optimised, and the player to play: one of the optimised poses at their time scale, made like
    ``player`` (which has had all the frames pushed and is closed), or ``player`` itself, the per-frame plan, where the
    problem has no solution up to ``max_time_scale``, the per-frame plan plays shorter, or the plan is longer than
    ``max_knots`` (then not optimised: None). Slower tries stop at the per-frame plan's played ratio: an optimised
    plan plays at least at its own scale, so one found slower would not be played (TALOS's identified digital humans
    spent up to 320 s on tries past it). Both are checked by the player's own criteria (ZMP margin, joint speeds,
    torques: :meth:`PlanPlayer.frame_scale`). The optimised torques are in their limits by construction; the
    player's torque criterion (the contact wrench split by least squares, not the optimisation's split) checks them
    again unless ``model`` is ``identified``: with CAD parameters the robot carries what the model does not know, and
    without the criterion G1 fell on 13 of the 14 digital humans it then played optimised (6.6 kg hidden: plans at
    the limits leave its controller nothing). With identified parameters the optimisation's model is the robot's as
    far as anyone knows, and the criterion stretched plans the robot stands at the human's timing (TALOS, 30 digital
    humans: see docs/method.md). Returns (the optimisation's result, the player, ``plan``, each plan's played ratio
    and ``whole_rise_torque_check`` for the summary)."""
    cfg = config or WholeRiseConfig()
    figures = {"plan_ratio_frames": player.played_ratio()}
    problem, plan = WholeRiseProblem(model, cfg), RisePlan.of_frames(frames, player.dt, player.smoothed())
    knots = len(problem.knots(plan))
    if knots > cfg.max_knots:
        return None, player, {"plan": "frames", **figures, "whole_rise_skipped":
                              f"{knots} knots, over the {cfg.max_knots} the optimisation is given (max_knots)"}
    result = problem.solve(plan, first_scale, progress, max_time_scale=figures["plan_ratio_frames"])
    if not result.feasible:
        return result, player, {"plan": "frames", **figures}
    figures["whole_rise_torque_check"] = "optimisation" if identified else "player"
    played = player.like(planned_time_scale=result.time_scale, torque_limited=not identified)
    for q, f in zip(result.q, frames):
        played.push(q, not f.seated)
    played.close()
    figures["plan_ratio_whole"] = played.played_ratio()
    if figures["plan_ratio_whole"] > figures["plan_ratio_frames"]:
        return result, player, {"plan": "frames", **figures}
    return result, played, {"plan": "whole", **figures}
