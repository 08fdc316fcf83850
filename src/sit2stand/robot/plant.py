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
from dataclasses import dataclass

import mujoco
import numpy as np
import pinocchio as pin

from ..dynamics import G
from ..errors import InputError
from ..forceplate import DEFAULT_COP_THRESHOLD_N
from ..vectors import xyzw_from_wxyz
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
EXTRAPOLATE_MAX_S = 0.05      # a reference is followed along its velocity for at most this long after its message


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
        self.joint_names = [self.model.joint(i).name for i in range(1, self.model.njnt)]
        self.n = len(self.joint_names)
        self.qadr = np.array([self.model.joint(n).qposadr[0] for n in self.joint_names])
        self.vadr = np.array([self.model.joint(n).dofadr[0] for n in self.joint_names])
        self.effort = np.array([self.model.jnt_actfrcrange[self.model.joint(n).id][1] for n in self.joint_names])
        self.pd_ids = np.array([self.model.actuator(n).id for n in self.joint_names])
        self.ff_ids = np.array([self.model.actuator(f"ff_{n}").id for n in self.joint_names])
        self._gains = (self.model.actuator_gainprm[self.pd_ids].copy(), self.model.actuator_biasprm[self.pd_ids].copy())
        self.rng = np.random.default_rng(cfg.seed)
        um = cfg.unmodeled
        self.tau_bias = np.zeros(self.n)
        for name, value in expand(um.torque_bias_nm, self.joint_names).items():
            self.tau_bias[self.joint_names.index(name)] = value
        self.tau_gain = np.ones(self.n)
        for name, value in expand(um.torque_gain, self.joint_names).items():
            self.tau_gain[self.joint_names.index(name)] = value
        self.q_offset = np.zeros(self.n)      # encoder reading - true angle; the servo tracks the reading
        for name, value in expand(um.joint_offset_rad, self.joint_names).items():
            self.q_offset[self.joint_names.index(name)] = value
        self.backlash = np.zeros(self.n)       # half the gear's play [rad] (see _dead_zone)
        for name, value in expand(um.backlash_rad, self.joint_names).items():
            self.backlash[self.joint_names.index(name)] = value
        self.has_backlash = bool(self.backlash.any())    # checked at every physics step
        self.delay_steps = int(round(um.actuator_delay_s / cfg.timestep_s))
        self._tau_queue: deque[np.ndarray] = deque()
        # the controller's model (CAD unless identified parameters are given)
        self.ctrl = controller_model(cfg, controller_params)
        self.seat_frame = add_seat_frame(self.ctrl, self.seat_height_m, float(self.q_seated[2]))
        self.ctrl_data = self.ctrl.createData()
        self.ctrl_mass = float(pin.computeTotalMass(self.ctrl))
        self.kp = self.model.actuator_gainprm[self.pd_ids, 0].copy()
        self.kd = -self.model.actuator_biasprm[self.pd_ids, 2].copy()
        self.seated_base_z = float(self.q_seated[2])
        # addresses resolved once: MuJoCo's by-name accessors cost ~15 us each
        m = self.model
        self.tau_adr = np.array([m.sensor_adr[m.sensor(f"tau_{n}").id] for n in self.joint_names])
        self.feet = FeetSensing.of(m, self.ctrl, cfg)
        self.ff_every = max(1, int(round(1.0 / (cfg.feedforward_rate_hz * cfg.timestep_s))))
        self.wbc_every = max(1, int(round(1.0 / (WBC_RATE_HZ * cfg.timestep_s))))
        self.wbc: WholeBodyController | None = None
        self._ff = np.zeros(self.n)
        self._ff_age = 10**9
        self.reset()
        self.status_text = "ok"

    # -- state ------------------------------------------------------------------------------------------------
    def reset(self, q: np.ndarray | None = None) -> None:
        """Back to the seated posture (or ``q``), at rest, holding it."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:] = self.q_seated if q is None else q
        mujoco.mj_forward(self.model, self.data)
        self.q_ref = self.data.qpos[self.qadr] + self.q_offset     # what the encoders read: hold it
        self.qd_ref = np.zeros(self.n)
        self.qdd_ref = np.zeros(self.n)
        self.feedforward = "gravity"
        self.wbc = None
        self._t_ref = float(self.data.time)
        self._ff_age = 10**9
        self.set_limp(False)
        self._tau_queue.clear()
        self.fallen = False
        self.status_text = "ok"

    def settle(self, seconds: float = 2.0) -> None:
        """Let the robot come to rest holding its reference (on the chair: it sinks ~1 cm into its seat posture),
        then start the clock at 0."""
        self.step(int(round(seconds / self.cfg.timestep_s)))
        self.data.time = 0.0
        self._t_ref = 0.0

    def set_limp(self, limp: bool) -> None:
        """Go limp (zero joint torque, e.g. after a fall) or back to PD control."""
        self.limp = limp
        self._servos(not limp and self.feedforward != "wbc")

    @property
    def t_s(self) -> float:
        return float(self.data.time)

    def command(self, q: np.ndarray, qd: np.ndarray | None = None, qdd: np.ndarray | None = None,
                feedforward: str | None = None, refresh: bool = True) -> None:
        """Set the joint reference; ``feedforward``: "none", "gravity" or "inverse_dynamics" (joint PD with that
        feed-forward), or "wbc" (whole-body torque control, the servos off); ``refresh=False``
        keeps the feed-forward's own refresh rate (for references interpolated at every physics step)."""
        q = np.asarray(q, float)
        if q.shape != (self.n,):
            raise InputError(f"joint command has {q.shape} positions, the robot has {self.n} joints")
        self.q_ref = q.copy()
        self.qd_ref = np.zeros(self.n) if qd is None else np.asarray(qd, float).copy()
        self.qdd_ref = np.zeros(self.n) if qdd is None else np.asarray(qdd, float).copy()
        self._t_ref = float(self.data.time)
        if feedforward is not None:
            if (feedforward == "wbc") != (self.feedforward == "wbc") and not self.limp:
                self._servos(feedforward != "wbc")
            self.feedforward = feedforward
        if refresh:
            self._ff_age = 10**9

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
        q[7:] = self.q_ref
        feet_fz = self.feet.vertical_force(self.data)
        seated = feedforward_seated(self.data.qpos[2], self.seated_base_z, feet_fz, self.ctrl_mass)
        return contact_feedforward(self.ctrl, self.ctrl_data, q, self.qd_ref, self.qdd_ref,
                                   self.feedforward == "inverse_dynamics", seated)

    def _torque_control(self) -> tuple[np.ndarray, np.ndarray]:
        """Whole-body torque control (:mod:`sit2stand.robot.torque_control`) at its rate; the servos off."""
        if self._ff_age >= self.wbc_every:
            if self.wbc is None:
                self.wbc = WholeBodyController(self.ctrl, self.seat_frame,
                                               period_s=self.wbc_every * self.model.opt.timestep)
            s = self.data
            q = self.pin_configuration(s.qpos)
            q[7:] += self.q_offset                     # what the encoders read
            v = s.qvel.copy()
            world_to_base = np.empty(4)                # the base's linear velocity in its own axes (Pinocchio's)
            mujoco.mju_negQuat(world_to_base, s.qpos[3:7])
            mujoco.mju_rotVecQuat(v[:3], s.qvel[:3], world_to_base)
            q_t, qd_t = reference_at(self.q_ref, self.qd_ref, self.qdd_ref, float(s.time) - self._t_ref)
            feet_fz = self.feet.vertical_force(self.data)
            seat = 0.0
            if feedforward_seated(s.qpos[2], self.seated_base_z, feet_fz, self.ctrl_mass):
                seat = max(0.0, self.ctrl_mass * G - feet_fz)
            self._ff, self._ff_age = self._within_effort(self.wbc.torques(q, v, q_t, qd_t, self.qdd_ref, seat)), 0
        self._ff_age += 1
        return self.data.qpos.take(self.qadr), self._ff

    def _within_effort(self, tau: np.ndarray) -> np.ndarray:
        """``tau`` [N m] clipped to the actuators' effort limits (once per controller update, not per step)."""
        return np.minimum(np.maximum(tau, -self.effort), self.effort)

    def _servos(self, on: bool) -> None:
        """Joint position servos on (PD) or off (torque control)."""
        gain, bias = self._gains
        self.model.actuator_gainprm[self.pd_ids] = gain if on else 0.0
        self.model.actuator_biasprm[self.pd_ids] = bias if on else 0.0

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps under the PD + feed-forward law (limp: zero torque)."""
        for _ in range(n):
            if self.limp:
                ctrl_pd, ctrl_ff = self.data.qpos[self.qadr].copy(), np.zeros(self.n)
            elif self.feedforward == "wbc":
                ctrl_pd, ctrl_ff = self._torque_control()
            else:
                if self._ff_age >= self.ff_every:          # the feed-forward changes slowly: refresh at its rate
                    self._ff, self._ff_age = self._within_effort(self._feedforward()), 0
                self._ff_age += 1
                # PD (implicit, in the servo actuator) + feed-forward (motor); the joint clamps their sum
                # between commands the joint controller follows the reference's own velocity and acceleration
                # (as a real one interpolates a trajectory point): a reference held still until the next message
                # would make the torques jump at every update
                q_t, qd_t = reference_at(self.q_ref, self.qd_ref, self.qdd_ref, float(self.data.time) - self._t_ref)
                ctrl_pd = q_t - self.q_offset + self.kd / self.kp * qd_t
                ctrl_ff = self._ff
            if self.delay_steps:
                self._tau_queue.append((ctrl_pd, ctrl_ff))
                if len(self._tau_queue) > self.delay_steps:
                    ctrl_pd, ctrl_ff = self._tau_queue.popleft()
                else:
                    ctrl_pd, ctrl_ff = self.data.qpos[self.qadr].copy(), np.zeros(self.n)
            if self.has_backlash and not self.limp and self.feedforward != "wbc":
                ctrl_pd = self._dead_zone(ctrl_pd, ctrl_ff)
            self.data.ctrl[self.pd_ids] = ctrl_pd
            self.data.ctrl[self.ff_ids] = ctrl_ff
            mujoco.mj_step(self.model, self.data)
        self._check_fall()

    def _dead_zone(self, ctrl_pd: np.ndarray, ctrl_ff: np.ndarray) -> np.ndarray:
        """The servo target that makes the joint PD + feed-forward pass through a gear with play: the motor (massless,
        its encoder on the joint side) crosses the play of +-b freely, so the joint feels kp dz(u, b), where u [rad] is
        where the motor would sit to give the law's torque (kp u = the PD + feed-forward torque) and dz takes b off
        |u|: a torque dead zone of +-kp b. Under torque control (wbc) the motor's torque passes the play unchanged."""
        q = self.data.qpos[self.qadr]
        u = ctrl_pd - q + ctrl_ff / self.kp
        return q + (u - np.clip(u, -self.backlash, self.backlash)) - ctrl_ff / self.kp

    def _check_fall(self) -> None:
        z, w0, _, _, w3 = self.data.qpos[2:7].tolist()
        tilt = 2 * math.acos(min(1.0, math.sqrt(w0 * w0 + w3 * w3)))     # angle of the base z axis from vertical
        if z < self.cfg.fall_height_m or tilt > self.cfg.fall_tilt_rad:
            self.fallen = True
            self.status_text = f"fallen: pelvis at {z:.2f} m, base tilted {np.degrees(tilt):.0f} deg"

    # -- sensors ----------------------------------------------------------------------------------------------
    def sensors(self) -> Sensors:
        cfg, d, n = self.cfg, self.data, self.n
        q = d.qpos.take(self.qadr) + self.q_offset
        if cfg.encoder_noise_rad:
            q = q + self.rng.normal(0, cfg.encoder_noise_rad, self.n)
        # the noise of the torques, then of each foot's force and torque: one draw
        noise = self.rng.standard_normal(n + 6 * len(SIDES))
        tau = self.tau_gain * d.sensordata.take(self.tau_adr) + self.tau_bias + noise[:n] * cfg.joint_torque_noise_nm
        reading = self.feet.readings(d, noise[n:])
        world = self.feet.ground_reactions(d, reading)
        cop = self.feet.combined_cop(d, world, DEFAULT_COP_THRESHOLD_N)
        return Sensors(self.t_s, q, d.qvel.take(self.vadr), tau, dict(zip(SIDES, reading)), dict(zip(SIDES, world)),
                       np.full(3, np.nan) if cop is None else cop, cop is not None, d.qpos[:7].copy())

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


def reference_at(q_ref: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray,
                 age_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The joint controller's reference [rad, rad/s] ``age_s`` after its command: followed along the command's own
    velocity and acceleration, for at most EXTRAPOLATE_MAX_S."""
    age = min(max(age_s, 0.0), EXTRAPOLATE_MAX_S)
    return q_ref + age * qd_ref + 0.5 * age * age * qdd_ref, qd_ref + age * qdd_ref


def feedforward_seated(base_z_m: float, seated_base_z_m: float, feet_fz_n: float, mass_kg: float) -> bool:
    """The controller's contact switch: the seat is taken to carry load while the pelvis is within 3 cm of its seated
    height or the feet carry under 90 % of the (controller model's) weight."""
    return base_z_m < seated_base_z_m + 0.03 or feet_fz_n / (mass_kg * G) < 0.9


def contact_feedforward(model, data, q: np.ndarray, qd_ref: np.ndarray, qdd_ref: np.ndarray, dynamic: bool,
                        seated: bool) -> np.ndarray:
    """The controller's feed-forward joint torques [N m]: gravity (or inverse dynamics along the reference with
    ``dynamic``) of ``model`` at ``q`` (Pinocchio configuration: measured base, reference joints), with the base's
    wrench taken by the soles (and the seat frame when ``seated``) in the least-squares sense."""
    v = np.zeros(model.nv)
    a = np.zeros(model.nv)
    if dynamic:
        v[6:], a[6:] = qd_ref, qdd_ref
    return contact_joint_torques(model, data, q, pin.rnea(model, data, q, v, a)[None], seated)[0]


def contact_joint_torques(model, data, q: np.ndarray, taus: np.ndarray, seated: bool) -> np.ndarray:
    """Joint torques (K, nv - 6) [N m] for generalised forces ``taus`` (K, nv) at ``q`` once the soles (and the
    seat frame when ``seated``) take the base's wrench in the least-squares sense; linear in ``taus``, so one set of
    contact Jacobians serves several."""
    frames = [model.getFrameId(f"sole_{s}") for s in SIDES]
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    J = np.vstack([pin.getFrameJacobian(model, data, f, pin.LOCAL_WORLD_ALIGNED) for f in frames])
    if seated:   # the seat pushes up under the buttocks (a frame on the pelvis at the seat surface)
        J = np.vstack([J, pin.getFrameJacobian(model, data, model.getFrameId("seat"), pin.LOCAL_WORLD_ALIGNED)[:3]])
    taus = np.atleast_2d(taus)
    lam = np.linalg.lstsq(J[:, :6].T, taus[:, :6].T, rcond=None)[0]
    return taus[:, 6:] - (J[:, 6:].T @ lam).T
