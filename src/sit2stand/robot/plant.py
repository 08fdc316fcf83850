"""The simulated robot (a profile's humanoid) in MuJoCo under joint PD with a torque-controlled robot's feed-forward.

:class:`Plant` is pure Python (no ROS): ``command()`` sets the reference (positions, optional velocities and
accelerations), ``step()`` advances the physics under

    tau = kp (q_ref - q) + kd (qd_ref - qd) + tau_ff,     tau_ff = contact-consistent gravity or inverse dynamics

computed with the **controller's** model (CAD, or identified parameters loaded from YAML; never the plant's truth),
clipped to the URDF effort limits. ``sensors()`` returns what a real robot measures: joint positions and
velocities, joint torques (actuator torque + noise + the unmodeled bias), the two ankle force/torque sensors (plus
noise and bias) and the COP computed from them. ``status()`` reports a fall (pelvis too low, base tilted).

Gains follow the measured recipe in ``../shared/notes/robot-talos.md`` (kp = effort limit / 0.1 rad, kd = 0.05 kp),
but the PD runs as MuJoCo position servos whose damping is integrated implicitly: no kd cap is needed against the
explicit-PD ankle instability, and the whole-body sway on the feet is well damped. The feed-forward is a second
(motor) actuator per joint; the joint's actuator force range (the URDF effort) clamps their sum.
"""

from __future__ import annotations

import fnmatch
import math
from collections import deque
from dataclasses import dataclass, field

import mujoco
import numpy as np
import pinocchio as pin

from ..dynamics import G
from ..errors import InputError
from ..forceplate import DEFAULT_COP_THRESHOLD_N
from ..vectors import xyzw_from_wxyz
from .actuation import JointFaults, JointMap, JointReference
from .feet_sensing import FeetSensing
from .torque_control import WholeBodyController
from .model import (SEAT_CLEARANCE_BELOW_M, SIDES, PlantConfig, PlantConfigError, add_chair, add_seat_frame, build_spec,
                    compiled_robot, controller_model, expand)

CONTROLLERS = ("inverse_dynamics", "wbc")
"""The simulated robot's on-board controllers (``Plant.command``'s ``feedforward`` for a planned motion): joint PD
with an inverse-dynamics feed-forward along the plan, or whole-body torque control
(:mod:`sit2stand.robot.torque_control`)."""
DEFAULT_CONTROLLER = "wbc"
"""The controller a stand-up is simulated with unless told otherwise (``sit2stand retarget --simulate``,
``make bench-standup``, the stand-up and live graphs): whole-body torque control. With the plan's hips lifted clear of
the seat at its seat-off (``RetargetConfig.seat_clearance_m``), joint PD, which had leaned on the seat it still
touched, tracks the population about twice as far from the plan and asks several times its torque limits
(docs/results.md). The driver and retargeter nodes' own defaults stay joint PD: the identification and
replay graphs pose the robot with it."""
WBC_RATE_HZ = 500.0          # the whole-body torque controller's rate (tsid's TALOS examples run at 1 kHz)
STALE = 10**9                 # a feed-forward's age [steps] that forces its refresh


@dataclass
class Sensors:
    """One sample of the robot's own sensors (lab frame = MuJoCo world, REP-103)."""

    t_s: float
    q: np.ndarray                  # (n,) joint positions [rad]
    qd: np.ndarray                 # (n,) joint velocities [rad/s]
    tau: np.ndarray                # (n,) measured joint torques [N m]
    ft: dict[str, np.ndarray]      # side -> (6,) force [N] and torque [N m] in the sensor frame
    wrench_world: dict[str, np.ndarray]   # side -> (6,) ground reaction on the foot: force, torque about the sole
    cop_m: np.ndarray              # (3,) COP of both feet on the floor, NaN when unloaded
    cop_valid: bool
    base_pose: np.ndarray          # (7,) MuJoCo free joint: position, quaternion w x y z (what a state estimator gives)


def seated_configuration(model: mujoco.MjModel, cfg: PlantConfig) -> np.ndarray:
    """qpos of the seated posture with the soles on the floor, the base upright above the origin."""
    names = [model.joint(i).name for i in range(1, model.njnt)]
    q = model.qpos0.copy()
    q[3:7] = [1, 0, 0, 0]
    for name, value in expand(cfg.seated, names).items():
        q[model.joint(name).qposadr[0]] = value
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    foot_z, _ = lowest_point(model, data, tuple(cfg.profile.foot_links.values()))
    sole_x = np.mean([data.site(f"sole_{s}").xpos[0] for s in SIDES])
    q[2] -= foot_z
    q[0] -= sole_x           # feet (sole centres) at x = 0
    return q


MIN_SEAT_HEIGHT_M = 0.1
SEAT_REACH_M = 0.03
"""A plant's chair may be this much lower or higher than the seated posture's seat links rest (2 mm under them)."""


def seat_top_height(model: mujoco.MjModel, q_seated: np.ndarray, cfg: PlantConfig) -> float:
    """Height [m] of the chair's top: the plant file's, or 2 mm under the seat links of the seated posture
    ``q_seated`` (qpos).

    Raises:
        PlantConfigError: the seated posture puts the seat links less than ``MIN_SEAT_HEIGHT_M`` above the floor,
            or the plant's chair is more than ``SEAT_REACH_M`` from where they rest (the posture cannot reach it).
    """
    data = mujoco.MjData(model)
    data.qpos[:] = q_seated
    mujoco.mj_kinematics(model, data)
    seat_z, _ = lowest_point(model, data, bodies_matching(model, cfg.profile.seat_links))
    natural = seat_z - SEAT_CLEARANCE_BELOW_M
    if natural < MIN_SEAT_HEIGHT_M:
        raise PlantConfigError(f"{cfg.profile.source}: field 'seated_posture': it puts the seat links "
                               f"({', '.join(cfg.profile.seat_links)}) {seat_z:.3f} m above the floor, lower than "
                               f"any chair ({MIN_SEAT_HEIGHT_M} m)")
    if cfg.chair_height_m is None:
        return natural
    if abs(cfg.chair_height_m - natural) > SEAT_REACH_M:
        raise PlantConfigError(f"{cfg.source or 'plant'}: field 'chair_height_m': {cfg.chair_height_m:.3f} m, but "
                               f"the seated posture of {cfg.profile.name} rests its seat links on a seat at "
                               f"{natural:.3f} m (within {SEAT_REACH_M} m it can reach)")
    return float(cfg.chair_height_m)


def bodies_matching(model: mujoco.MjModel, globs: tuple[str, ...]) -> tuple[str, ...]:
    """The names of ``model``'s bodies that match any of the link ``globs``."""
    names = [model.body(i).name for i in range(model.nbody)]
    return tuple(n for n in names if any(fnmatch.fnmatchcase(n, g) for g in globs))


def lowest_point(model: mujoco.MjModel, data: mujoco.MjData, bodies: tuple[str, ...]) -> tuple[float, float]:
    """Lowest z [m] of the collision geometry of ``bodies`` (mesh vertices; other shapes' bounding boxes) and the
    x where it is."""
    best = (np.inf, 0.0)
    for g in range(model.ngeom):
        if model.body(model.geom_bodyid[g]).name not in bodies or model.geom_contype[g] == 0:
            continue
        R = data.geom_xmat[g].reshape(3, 3)
        if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
            mesh = model.geom_dataid[g]
            start, count = model.mesh_vertadr[mesh], model.mesh_vertnum[mesh]
            local = model.mesh_vert[start:start + count]
        else:
            centre, half = model.geom_aabb[g][:3], model.geom_aabb[g][3:]
            local = centre + half * np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        world = data.geom_xpos[g] + local @ R.T
        k = np.argmin(world[:, 2])
        if world[k, 2] < best[0]:
            best = (float(world[k, 2]), float(world[k, 0]))
    return best


@dataclass(frozen=True)
class OnBoardModel:
    """The on-board controller's own model of the robot (CAD, or identified parameters; never the plant's truth):
    Pinocchio's ``model`` and ``data``, its total ``mass_kg``, the ``seat_frame`` (a frame on the pelvis at the seat
    surface) and the base height [m] at which it takes the robot as seated."""

    model: pin.Model
    data: pin.Data
    mass_kg: float
    seat_frame: int
    seated_base_z_m: float

    @classmethod
    def of(cls, cfg: PlantConfig, params: dict | None, seat_height_m: float, seated_base_z_m: float) -> OnBoardModel:
        model = controller_model(cfg, params)
        frame = add_seat_frame(model, seat_height_m, seated_base_z_m)
        return cls(model, model.createData(), float(pin.computeTotalMass(model)), frame, seated_base_z_m)


@dataclass
class FeedForward:
    """The on-board controller's last torques [N m] and their age [physics steps]: joint PD's feed-forward is
    refreshed every ``pd_every`` steps, whole-body torque control every ``wbc_every``."""

    pd_every: int
    wbc_every: int
    tau: np.ndarray = field(default_factory=lambda: np.zeros(0))
    age: int = STALE


class Plant:
    """The robot on a chair in MuJoCo under joint PD + feed-forward (see the module docstring)."""

    def __init__(self, cfg: PlantConfig | None = None, controller_params: dict | None = None,
                 with_chair: bool = True) -> None:
        self.cfg = cfg = cfg or PlantConfig()
        probe, _ = compiled_robot(cfg, plant=True)
        self.q_seated = seated_configuration(probe, cfg)
        pd = mujoco.MjData(probe)
        pd.qpos[:] = self.q_seated
        mujoco.mj_kinematics(probe, pd)
        sole = cfg.profile.sole
        heel_x = min(pd.site(f"sole_{s}").xpos[0] for s in SIDES) + sole.centre_x_m - sole.half_size_m[0]
        self.seat_height_m = seat_top_height(probe, self.q_seated, cfg)
        self.chair_front_x = heel_x - cfg.chair("front_gap_m")
        spec = build_spec(cfg, plant=True)
        if with_chair:
            add_chair(spec, cfg, self.seat_height_m, self.chair_front_x)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.joints = JointMap.of(self.model)
        self.faults = JointFaults.of(cfg.unmodeled, self.joints.names, cfg.timestep_s)
        self.rng = np.random.default_rng(cfg.seed)
        self.controller_rng = np.random.default_rng([cfg.seed, 1])   # the torque controller's own sensor reads
        self._tau_queue: deque[tuple[np.ndarray, np.ndarray]] = deque()    # the actuators' delay line
        self.onboard = OnBoardModel.of(cfg, controller_params, self.seat_height_m, float(self.q_seated[2]))
        self.feet = FeetSensing.of(self.model, self.onboard.model, cfg)
        self.ff = FeedForward(max(1, int(round(1.0 / (cfg.feedforward_rate_hz * cfg.timestep_s)))),
                              max(1, int(round(1.0 / (WBC_RATE_HZ * cfg.timestep_s)))), np.zeros(self.n))
        self.wbc: WholeBodyController | None = None
        self._kd_over_kp = self.joints.kd / self.joints.kp
        self.reset()
        self.status_text = "ok"

    @property
    def joint_names(self) -> list[str]:
        return self.joints.names

    @property
    def n(self) -> int:
        return self.joints.n

    @property
    def qadr(self) -> np.ndarray:
        """The actuated joints' addresses in qpos."""
        return self.joints.qadr

    @property
    def q_ref(self) -> np.ndarray:
        """The joint controller's position reference [rad] (encoder readings)."""
        return self.ref.q

    @property
    def ctrl(self) -> pin.Model:
        """The on-board controller's Pinocchio model (:class:`OnBoardModel`)."""
        return self.onboard.model

    # -- state ------------------------------------------------------------------------------------------------
    def reset(self, q: np.ndarray | None = None) -> None:
        """Back to the seated posture (or ``q``), at rest, holding it."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:] = self.q_seated if q is None else q
        mujoco.mj_forward(self.model, self.data)
        # what the encoders read: hold it
        self.ref = JointReference.holding(self.data.qpos[self.qadr] + self.faults.q_offset, float(self.data.time))
        self.feedforward = "gravity"
        self.wbc = None
        self.ff.age = STALE
        self.set_limp(False)
        self._tau_queue.clear()
        self.fallen = False
        self.status_text = "ok"

    def settle(self, seconds: float = 2.0) -> None:
        """Let the robot come to rest holding its reference (on the chair: it sinks ~1 cm into its seat posture),
        then start the clock at 0."""
        self.step(int(round(seconds / self.cfg.timestep_s)))
        self.data.time = 0.0
        self.ref.t_s = 0.0

    def set_limp(self, limp: bool) -> None:
        """Go limp (zero joint torque, e.g. after a fall) or back to PD control."""
        self.limp = limp
        self._servos(not limp and self.feedforward != "wbc")

    @property
    def t_s(self) -> float:
        return float(self.data.time)

    def command(self, q: np.ndarray, qd: np.ndarray | None = None, qdd: np.ndarray | None = None,
                feedforward: str | None = None, refresh: bool = True, tau: np.ndarray | None = None) -> None:
        """Set the joint reference; ``feedforward``: "none", "gravity" or "inverse_dynamics" (joint PD with that
        feed-forward), or "wbc" (whole-body torque control, the servos off); ``refresh=False``
        keeps the feed-forward's own refresh rate (for references interpolated at every physics step); ``tau``: the
        joint torques the plan asks [N m], which whole-body torque control tracks (``WbcGains.torque_weight``)."""
        q = np.asarray(q, float)
        if q.shape != (self.n,):
            raise InputError(f"joint command has {q.shape} positions, the robot has {self.n} joints")
        self.ref = JointReference(q.copy(), np.zeros(self.n) if qd is None else np.asarray(qd, float).copy(),
                                  np.zeros(self.n) if qdd is None else np.asarray(qdd, float).copy(),
                                  float(self.data.time), None if tau is None else np.asarray(tau, float).copy())
        if feedforward is not None:
            if (feedforward == "wbc") != (self.feedforward == "wbc") and not self.limp:
                self._servos(feedforward != "wbc")
            self.feedforward = feedforward
        if refresh:
            self.ff.age = STALE

    # -- control ----------------------------------------------------------------------------------------------
    def pin_configuration(self, qpos: np.ndarray) -> np.ndarray:
        """MuJoCo qpos -> Pinocchio q (quaternion w x y z -> x y z w)."""
        q = qpos.copy()
        q[3:7] = xyzw_from_wxyz(qpos[3:7])
        return q

    def _feedforward(self) -> np.ndarray:
        if self.feedforward == "none":
            return np.zeros(self.n)
        q = self.pin_configuration(self.data.qpos)
        q[7:] = self.ref.q
        ob = self.onboard
        seated = feedforward_seated(self.data.qpos[2], ob.seated_base_z_m, self.feet.vertical_force(self.data),
                                    ob.mass_kg)
        return contact_feedforward(ob.model, ob.data, q, self.ref.qd, self.ref.qdd,
                                   self.feedforward == "inverse_dynamics", seated)

    def _torque_control(self) -> tuple[np.ndarray, np.ndarray]:
        """Whole-body torque control (:mod:`sit2stand.robot.torque_control`) at its rate; the servos off."""
        ff, ob = self.ff, self.onboard
        if ff.age >= ff.wbc_every:
            if self.wbc is None:
                self.wbc = WholeBodyController(ob.model, ob.seat_frame, period_s=ff.wbc_every * self.model.opt.timestep)
            s = self.data
            q = self.pin_configuration(s.qpos)
            q[7:] += self.faults.q_offset                     # what the encoders read
            v = s.qvel.copy()
            world_to_base = np.empty(4)                # the base's linear velocity in its own axes (Pinocchio's)
            mujoco.mju_negQuat(world_to_base, s.qpos[3:7])
            mujoco.mju_rotVecQuat(v[:3], s.qvel[:3], world_to_base)
            q_t, qd_t = self.ref.at(float(s.time))
            feet_fz = self.feet.vertical_force(self.data)
            seat, cop = 0.0, None
            if feedforward_seated(s.qpos[2], ob.seated_base_z_m, feet_fz, ob.mass_kg):
                seat = max(0.0, ob.mass_kg * G - feet_fz)
            else:            # off the seat: the feet's centre of pressure tells the COM's (a seat's share is unknown)
                cop = self._measured_cop()
            ff.tau, ff.age = self._within_effort(self.wbc.torques(q, v, q_t, qd_t, self.ref.qdd, seat,
                                                                  self.ref.tau, cop)), 0
        ff.age += 1
        return self.data.qpos.take(self.qadr), ff.tau

    def _measured_cop(self) -> np.ndarray | None:
        """The feet's centre of pressure [m] (world) as the controller reads it from the ankle sensors (their noise,
        bias and mounting included); None while they carry little."""
        d = self.data
        readings = self.feet.readings(d, self.controller_rng.standard_normal(6 * len(SIDES)))
        return self.feet.combined_cop(d, self.feet.ground_reactions(d, readings), DEFAULT_COP_THRESHOLD_N)

    def _within_effort(self, tau: np.ndarray) -> np.ndarray:
        """``tau`` [N m] clipped to the actuators' effort limits (once per controller update, not per step)."""
        return np.minimum(np.maximum(tau, -self.joints.effort), self.joints.effort)

    def _servos(self, on: bool) -> None:
        """Joint position servos on (PD) or off (torque control)."""
        self.joints.servos(self.model, on)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps under the PD + feed-forward law (limp: zero torque)."""
        jm, faults, ff = self.joints, self.faults, self.ff
        backlash = faults.has_backlash
        for _ in range(n):
            if self.limp:
                ctrl_pd, ctrl_ff = self.data.qpos[self.qadr].copy(), np.zeros(self.n)
            elif self.feedforward == "wbc":
                ctrl_pd, ctrl_ff = self._torque_control()
            else:
                if ff.age >= ff.pd_every:          # the feed-forward changes slowly: refresh at its rate
                    ff.tau, ff.age = self._within_effort(self._feedforward()), 0
                ff.age += 1
                # PD (implicit, in the servo actuator) + feed-forward (motor); the joint clamps their sum
                # between commands the joint controller follows the reference's own velocity and acceleration
                # (as a real one interpolates a trajectory point): a reference held still until the next message
                # would make the torques jump at every update
                ctrl_pd, ctrl_ff = self.ref.servo_target(self.data.time, faults.q_offset, self._kd_over_kp), ff.tau
            if faults.delay_steps:
                self._tau_queue.append((ctrl_pd, ctrl_ff))
                if len(self._tau_queue) > faults.delay_steps:
                    ctrl_pd, ctrl_ff = self._tau_queue.popleft()
                else:
                    ctrl_pd, ctrl_ff = self.data.qpos[self.qadr].copy(), np.zeros(self.n)
            if backlash and not self.limp and self.feedforward != "wbc":
                ctrl_pd = self._dead_zone(ctrl_pd, ctrl_ff)
            self.data.ctrl[jm.pd_ids] = ctrl_pd
            self.data.ctrl[jm.ff_ids] = ctrl_ff
            mujoco.mj_step(self.model, self.data)
        self._check_fall()

    def _dead_zone(self, ctrl_pd: np.ndarray, ctrl_ff: np.ndarray) -> np.ndarray:
        """The servo target that makes the joint PD + feed-forward pass through a gear with play: the motor (massless,
        its encoder on the joint side) crosses the play of +-b freely, so the joint feels kp dz(u, b), where u [rad] is
        where the motor would sit to give the law's torque (kp u = the PD + feed-forward torque) and dz takes b off
        |u|: a torque dead zone of +-kp b. Under torque control (wbc) the motor's torque passes the play unchanged."""
        q, kp, b = self.data.qpos[self.qadr], self.joints.kp, self.faults.backlash
        u = ctrl_pd - q + ctrl_ff / kp
        return q + (u - np.clip(u, -b, b)) - ctrl_ff / kp

    def _check_fall(self) -> None:
        z, w0, _, _, w3 = self.data.qpos[2:7].tolist()
        tilt = 2 * math.acos(min(1.0, math.sqrt(w0 * w0 + w3 * w3)))     # angle of the base z axis from vertical
        if z < self.cfg.fall_height_m or tilt > self.cfg.fall_tilt_rad:
            self.fallen = True
            self.status_text = f"fallen: pelvis at {z:.2f} m, base tilted {np.degrees(tilt):.0f} deg"

    # -- sensors ----------------------------------------------------------------------------------------------
    def sensors(self) -> Sensors:
        cfg, d, n = self.cfg, self.data, self.n
        jm, faults = self.joints, self.faults
        q = d.qpos.take(jm.qadr) + faults.q_offset
        if cfg.encoder_noise_rad:
            q = q + self.rng.normal(0, cfg.encoder_noise_rad, self.n)
        # the noise of the torques, then of each foot's force and torque: one draw
        noise = self.rng.standard_normal(n + 6 * len(SIDES))
        tau = faults.tau_gain * d.sensordata.take(jm.tau_adr) + faults.tau_bias + noise[:n] * cfg.joint_torque_noise_nm
        reading = self.feet.readings(d, noise[n:])
        world = self.feet.ground_reactions(d, reading)
        cop = self.feet.combined_cop(d, world, DEFAULT_COP_THRESHOLD_N)
        return Sensors(self.t_s, q, d.qvel.take(jm.vadr), tau, dict(zip(SIDES, reading)), dict(zip(SIDES, world)),
                       np.full(3, np.nan) if cop is None else cop, cop is not None, d.qpos[:7].copy())

    def model_com(self) -> np.ndarray:
        """The on-board model's COM [m] at the plant's configuration (true base and joints)."""
        ob = self.onboard
        return pin.centerOfMass(ob.model, ob.data, self.pin_configuration(self.data.qpos))

    def true_com(self) -> np.ndarray:
        """The plant's true COM [m] (for tests and figures only; controllers must not use it)."""
        return self.data.subtree_com[1].copy()

    def chair_force_n(self) -> float:
        """Vertical force the chair takes [N] (the plant's truth, from contacts; for tests)."""
        total = 0.0
        chair = self.model.geom("chair_seat").id if "chair_seat" in [self.model.geom(i).name
                                                                       for i in range(self.model.ngeom)] else -1
        f6 = np.zeros(6)
        for i in range(self.data.ncon):
            c = self.data.contact[i]
            if chair in (c.geom1, c.geom2):
                mujoco.mj_contactForce(self.model, self.data, i, f6)
                total += abs((c.frame.reshape(3, 3).T @ f6[:3])[2])
        return total


def feedforward_seated(base_z_m: float, seated_base_z_m: float, feet_fz_n: float, mass_kg: float) -> bool:
    """The controller's contact switch: the seat is taken to carry load while the pelvis is within 3 cm of its seated
    height or the feet carry under 90 % of the (controller model's) weight."""
    return base_z_m < seated_base_z_m + 0.03 or feet_fz_n / (mass_kg * G) < 0.9


def contact_feedforward(model, data, q: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray, dynamic: bool,
                        seated: bool) -> np.ndarray:
    """The controller's feed-forward joint torques [N m]: gravity (or inverse dynamics along the reference with
    ``dynamic``) of ``model`` at ``q`` (Pinocchio configuration: measured base, reference joints), with the base's
    wrench taken by the soles (and the seat frame when ``seated``) in the least-squares sense."""
    if dynamic:
        v, a = np.zeros(model.nv), np.zeros(model.nv)
        v[6:], a[6:] = qd_ref, qdd_ref
        tau = pin.rnea(model, data, q, v, a)
    else:
        tau = pin.computeGeneralizedGravity(model, data, q)
    return contact_joint_torques(model, data, q, tau[None], seated)[0]


def contact_joint_torques(model, data, q: np.ndarray, taus: np.ndarray, seated: bool) -> np.ndarray:
    """Joint torques (K, nv - 6) [N m] for generalised forces ``taus`` (K, nv) at ``q`` once the soles (and the
    seat frame when ``seated``) take the base's wrench in the least-squares sense; linear in ``taus``, so one set of
    contact Jacobians serves several."""
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    blocks = [pin.getFrameJacobian(model, data, model.getFrameId(f"sole_{s}"), pin.LOCAL_WORLD_ALIGNED) for s in SIDES]
    if seated:   # the seat pushes up under the buttocks (the seat frame: model.add_seat_frame)
        blocks.append(pin.getFrameJacobian(model, data, model.getFrameId("seat"), pin.LOCAL_WORLD_ALIGNED)[:3])
    J = np.concatenate(blocks)
    taus = np.atleast_2d(taus)
    base = J[:, :6]        # full column rank (each sole's own 6 x 6 block is): the least-norm forces in closed form
    lam = base @ np.linalg.solve(base.T @ base, taus[:, :6].T)
    return taus[:, 6:] - (J[:, 6:].T @ lam).T
