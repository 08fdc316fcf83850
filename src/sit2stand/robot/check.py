"""``sit2stand robot check``: does a robot profile make a robot that can sit and stand up?

Loads the profile (its names checked against the URDF), compiles the robot in MuJoCo on its chair, lets it sit for
two seconds under joint PD with gravity feed-forward, and measures what decides a sit-to-stand:

* mass [kg]; standing (straight legs) pelvis and COM heights; seated pelvis height and the chair's top [m];
* the robot seated: whether it stays on the chair (pelvis within 5 cm of where it was put, upright);
* torque headroom at seat-off: the static torques (all the weight on the feet, shared equally) of the seated
  posture's legs with the trunk pitched forward until the COM is 30 % along the feet from the heel, the knee's and
  the trunk pitch's against their effort limits (the sit-to-stand's two bottlenecks, measured on TALOS and G1).

A profile that fails (a name not in the URDF, a posture outside the limits) raises
:class:`~sit2stand.robot.profile.ProfileError` naming the file and the field.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import mujoco
import numpy as np
import pinocchio as pin

from .model import SIDES, PlantConfig
from .plant import Plant
from .postures import standing_qpos
from .profile import load_profile

SEAT_OFF_COM_FRACTION = 0.3
"""At seat-off the COM is this far along the feet, from the heel (the retargeter's ``seat_off_fraction``)."""
SEATED_DRIFT_M = 0.05


@dataclass
class RobotCheck:
    """What :func:`check_robot` measured (SI units)."""

    robot: str
    urdf: str
    mass_kg: float
    actuated_joints: int
    standing_pelvis_m: float
    standing_com_m: float
    seated_pelvis_m: float
    seat_height_m: float
    sits: bool
    seated_drift_m: float
    knee_torque_nm: float
    knee_limit_nm: float
    trunk_torque_nm: float
    trunk_limit_nm: float
    conventions: list[str] = field(default_factory=list)   # how the URDF was brought to REP-103 (robot.conventions)

    @property
    def knee_share(self) -> float:
        return self.knee_torque_nm / self.knee_limit_nm

    @property
    def trunk_share(self) -> float:
        return self.trunk_torque_nm / self.trunk_limit_nm

    @property
    def ok(self) -> bool:
        """Sits on its chair, and the seat-off's static torques leave headroom (under 80 % of the limits)."""
        return self.sits and self.knee_share < 0.8 and self.trunk_share < 0.8

    def lines(self) -> list[str]:
        return [f"robot {self.robot} ({self.urdf}): {self.mass_kg:.1f} kg, {self.actuated_joints} actuated joints",
                *(f"URDF brought to sit2stand's conventions: {line}" for line in self.conventions),
                f"standing (straight legs): pelvis {self.standing_pelvis_m:.3f} m, COM {self.standing_com_m:.3f} m",
                f"seated: pelvis {self.seated_pelvis_m:.3f} m on a {self.seat_height_m:.3f} m chair; "
                + ("stays seated" if self.sits else f"does not stay seated (moved {self.seated_drift_m:.3f} m)"),
                f"seat-off (COM {100 * SEAT_OFF_COM_FRACTION:.0f} % along the feet), static torques: knee "
                f"{self.knee_torque_nm:.0f} of {self.knee_limit_nm:.0f} N m ({100 * self.knee_share:.0f} %), "
                + (f"trunk pitch {self.trunk_torque_nm:.0f} of {self.trunk_limit_nm:.0f} N m "
                   f"({100 * self.trunk_share:.0f} %)" if np.isfinite(self.trunk_limit_nm) else
                   "no trunk pitch joint (the hips lean the trunk)"),
                "ok: it can sit on its chair and has torque to rise" if self.ok else
                "not ok: see the lines above"]

    def as_dict(self) -> dict:
        """The figures for JSON (a robot without a trunk pitch joint: its limit None)."""
        out = {**asdict(self), "ok": self.ok}
        if not np.isfinite(self.trunk_limit_nm):
            out["trunk_limit_nm"] = None
        return out


def check_robot(robot: str, plant: str | None = None) -> RobotCheck:
    """Check ``robot`` (a profile's name or file) on ``plant`` (None: no unmodeled effects); see the module
    docstring."""
    profile = load_profile(robot)
    cfg = PlantConfig.load(plant, robot)
    sim = Plant(cfg)
    put = sim.data.qpos[:3].copy()
    sim.settle(2.0)
    drift = float(np.linalg.norm(sim.data.qpos[:3] - put))
    model, data = sim.ctrl, sim.onboard.data
    standing = standing_qpos(sim, 0.0, 0.0, 0.0, 0.0)
    com = pin.centerOfMass(model, data, sim.pin_configuration(standing))
    tau = seat_off_torques(sim)
    names = sim.joint_names
    knee = max(abs(tau[names.index(profile.leg(s, "knee"))]) for s in SIDES)
    trunk = abs(tau[names.index(profile.trunk_pitch)]) if profile.trunk_pitch else 0.0
    return RobotCheck(profile.name, str(profile.urdf), float(pin.computeTotalMass(model)), sim.n,
                      float(standing[2]), float(com[2]), float(sim.q_seated[2]), sim.seat_height_m,
                      drift < SEATED_DRIFT_M and not sim.fallen, drift, float(knee),
                      float(sim.joints.effort[names.index(profile.leg("left", "knee"))]), float(trunk),
                      float(sim.joints.effort[names.index(profile.trunk_pitch)]) if profile.trunk_pitch else np.inf,
                      profile.conventions.lines())


def seat_off_torques(sim: Plant) -> np.ndarray:
    """(n,) static joint torques [N m] at seat-off: the seated legs, the trunk pitched until the COM is
    ``SEAT_OFF_COM_FRACTION`` along the feet, the whole weight on the two soles (equal shares)."""
    profile = sim.cfg.profile
    names = sim.joint_names
    q = sim.q_seated.copy()
    d = mujoco.MjData(sim.model)
    d.qpos[:] = q
    mujoco.mj_kinematics(sim.model, d)
    sole = profile.sole
    heel = np.mean([d.site(f"sole_{s}").xpos[0] for s in SIDES]) + sole.centre_x_m - sole.half_size_m[0]
    target = heel + SEAT_OFF_COM_FRACTION * 2 * sole.half_size_m[0]
    hips = [sim.qadr[names.index(profile.leg(s, "hip_pitch"))] for s in SIDES]
    hip_at = np.mean([d.joint(profile.leg(s, "hip_pitch")).xanchor for s in SIDES], axis=0)
    model, data = sim.ctrl, sim.onboard.data

    def leaned(lean: float) -> np.ndarray:      # the pelvis and trunk turn forward about the hips, the legs stay
        qq = q.copy()
        c, s = np.cos(lean), np.sin(lean)
        qq[:3] = hip_at + np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]) @ (q[:3] - hip_at)
        qq[3:7] = _pitched(q[3:7], lean)
        qq[hips] = q[hips] - lean
        return qq

    lo, hi = 0.0, 1.5
    for _ in range(40):           # the COM moves forward as the trunk leans: bisection
        mid = 0.5 * (lo + hi)
        forward = pin.centerOfMass(model, data, sim.pin_configuration(leaned(mid)))[0] < target
        lo, hi = (mid, hi) if forward else (lo, mid)
    qq = leaned(0.5 * (lo + hi))
    x = sim.pin_configuration(qq)
    pin.computeGeneralizedGravity(model, data, x)
    g = data.g.copy()
    pin.computeJointJacobians(model, data, x)
    pin.framesForwardKinematics(model, data, x)
    J = np.vstack([pin.getFrameJacobian(model, data, model.getFrameId(f"sole_{s}"), pin.LOCAL_WORLD_ALIGNED)
                   for s in SIDES])
    # the wrench at each sole that holds the base: least norm, the feet sharing it
    f = np.linalg.lstsq(J[:, :6].T, g[:6], rcond=None)[0]
    tau_pin = g[6:] - J[:, 6:].T @ f
    order = [model.names[2:].index(n) for n in names] if list(model.names[2:]) != names else slice(None)
    return np.asarray(tau_pin)[order]


def _pitched(quat_wxyz: np.ndarray, angle: float) -> np.ndarray:
    """``quat_wxyz`` turned forward (about +y, world) by ``angle`` [rad]."""
    turn = np.array([np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0])
    out = np.empty(4)
    mujoco.mju_mulQuat(out, turn, np.asarray(quat_wxyz, float))
    return out


def check_command(robot: str, plant: str | None = None) -> int:
    """``sit2stand robot check``: print the check; 0 when it passes, 1 when not."""
    result = check_robot(robot, plant)
    for line in result.lines():
        print(line)
    return 0 if result.ok else 1
