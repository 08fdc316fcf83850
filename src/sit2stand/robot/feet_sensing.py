"""The robot's two ankle force/torque sensors as the simulated plant reads them, and the ground reactions a
controller computes from them.

A sensor reads the wrench of the leg on the foot below it in its own axes, turned by its mounting error (the plant's
``ft_rotation_rad``), plus a bias and noise. From the readings the ground reaction on each foot follows as a
controller computes it: the foot below the sensor (the controller model's mass and COM, not the plant's) is static,
so ground + leg + the foot's weight balance. Everything is stacked in ``SIDES`` order: one product per step for
both feet, the few products after it in floats (this runs for every published state, 500 times a second).

Units SI; world frame REP-103 (x forward, y left, z up).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import pinocchio as pin

from ..dynamics import G
from ..errors import InputError
from .model import SIDES, PlantConfig, compiled_robot


def below_sensor(controller: pin.Model, cfg: PlantConfig, side: str) -> tuple[float, np.ndarray]:
    """The mass [kg] hanging below a foot's sensor and its COM in the sensor's frame [m], as the controller models
    it. A sensor at the ankle's last joint (the foot link is that joint's body: TALOS, G1) carries the joint's whole
    body; one on a link welded further down (iCub's sole frame) carries that link and those welded below it (the
    CAD model's: the identification keeps the feet's)."""
    profile = cfg.profile
    foot = controller.frames[controller.getFrameId(profile.foot_links[side], pin.FrameType.BODY)]
    if foot.placement.isIdentity():
        body = controller.inertias[foot.parentJoint]
        return float(body.mass), np.array(body.lever)
    cad, _ = compiled_robot(cfg, plant=False)
    data = mujoco.MjData(cad)
    mujoco.mj_forward(cad, data)
    b = cad.body(profile.foot_links[side]).id
    lever = data.xmat[b].reshape(3, 3).T @ (data.subtree_com[b] - data.xpos[b])
    return float(cad.body_subtreemass[b]), lever


@dataclass(frozen=True)
class FeetSensing:
    """The feet's F/T sensing, stacked in SIDES order."""

    adr: np.ndarray          # (2, 6) sensordata indices: force x y z, torque x y z
    sites: np.ndarray        # (4,) the sensors' sites, then the soles'
    reading: np.ndarray      # (2, 3, 3) raw rows @ reading: what the sensor reads (its mounting's turn, transposed)
    bias: np.ndarray         # (2, 6) [N, N m]
    weight_n: tuple[float, ...]   # (2,) the controller model's foot below the sensor: its weight, the vertical
    #                               force that holds it up [N]
    lever_m: np.ndarray      # (2, 3) its COM in the sensor's frame
    noise_sd: np.ndarray     # (12,) each foot's force and torque noise [N, N m]

    @staticmethod
    def of(model: mujoco.MjModel, controller: pin.Model, cfg: PlantConfig) -> FeetSensing:
        """The sensing of the plant ``model`` (its sensors ``force_<side>``, ``torque_<side>``, sites ``ft_<side>``,
        ``sole_<side>``), with the feet of the ``controller`` model and the sensor errors of ``cfg``.

        Raises:
            InputError: the plant file names a side that is not one of ``SIDES``.
        """
        um = cfg.unmodeled
        for key, values in (("ft_bias", um.ft_bias), ("ft_rotation_rad", um.ft_rotation_rad)):
            if set(values) - set(SIDES):
                raise InputError(f"{cfg.source or 'plant'}: {key} for unknown side(s) "
                                 f"{sorted(set(values) - set(SIDES))} (sides: {SIDES})")
        both = np.concatenate([um.ft_force_bias_n, um.ft_torque_bias_nm])
        adr = [(model.sensor_adr[model.sensor(f"force_{s}").id], model.sensor_adr[model.sensor(f"torque_{s}").id])
               for s in SIDES]
        feet = [below_sensor(controller, cfg, s) for s in SIDES]
        return FeetSensing(
            np.array([[*range(f, f + 3), *range(t, t + 3)] for f, t in adr]),
            np.array([model.site(f"{k}_{s}").id for k in ("ft", "sole") for s in SIDES]),
            # what the sensor reads, from the wrench in its modelled axes: the transpose of its mounting's turn
            np.array([pin.exp3(np.asarray(um.ft_rotation_rad.get(s, np.zeros(3)), float)) for s in SIDES]),
            np.array([both + np.asarray(um.ft_bias.get(s, np.zeros(6)), float) for s in SIDES]),
            tuple(mass * G for mass, _ in feet),
            np.array([lever for _, lever in feet]),
            np.tile([cfg.ft_force_noise_n] * 3 + [cfg.ft_torque_noise_nm] * 3, len(SIDES)))

    @property
    def ft_sites(self) -> np.ndarray:
        return self.sites[:len(SIDES)]

    def readings(self, data: mujoco.MjData, noise: np.ndarray) -> np.ndarray:
        """(2, 6) what the sensors read [N, N m], given standard-normal ``noise`` (12,)."""
        raw = data.sensordata.take(self.adr).reshape(len(SIDES), 2, 3)      # side, (force, torque), xyz
        out = (raw @ self.reading).reshape(len(SIDES), 6)
        out += self.bias
        out += noise.reshape(len(SIDES), 6) * self.noise_sd.reshape(len(SIDES), 6)
        return out

    def ground_reactions(self, data: mujoco.MjData, readings: np.ndarray) -> np.ndarray:
        """(2, 6) the ground reaction on each foot (world axes): force [N], and torque about the sole point [N m],
        from the readings (2, 6). The static foot balances: ground + leg + its weight W = (0, 0, w) at its COM,
        so the force is W - f_leg and the moment about the sole arm x (W - f_leg) + lever x W - t_leg, with arm the
        sensor from the sole and lever the foot's COM from the sensor (world axes). Past the one rotation into world
        axes the two feet's few products run in floats: as arrays of two rows they cost twice as long."""
        R = data.site_xmat.take(self.ft_sites, axis=0).reshape(-1, 3, 3)
        # what the leg exerts on the foot (force, torque) and the foot's COM lever, from sensor to world axes
        rows = np.concatenate((readings.reshape(len(SIDES), 2, 3), self.lever_m[:, None]), axis=1) @ \
            R.transpose(0, 2, 1)
        xpos = data.site_xpos.take(self.sites, axis=0).tolist()          # the sensors' sites, then the soles'
        out = []
        for k, ((fx, fy, fz), (tx, ty, tz), (lx, ly, _)) in enumerate(rows.tolist()):
            w = self.weight_n[k]
            gx, gy, gz = -fx, -fy, w - fz
            (sx, sy, sz), (px, py, pz) = xpos[k], xpos[len(SIDES) + k]
            ax, ay, az = sx - px, sy - py, sz - pz
            out.append((gx, gy, gz, ay * gz - az * gy + w * ly - tx, az * gx - ax * gz - w * lx - ty,
                        ax * gy - ay * gx - tz))
        return np.array(out)

    def vertical_force(self, data: mujoco.MjData) -> float:
        """The feet's summed vertical ground reaction [N] (the z of :meth:`ground_reactions`, without the rest, the
        sensor errors aside): each foot's weight less the world z of what its sensor reads (row-major: the z row is
        xmat[6:9])."""
        z_rows = data.site_xmat.take(self.ft_sites, axis=0)[:, 6:9]
        return float(sum(self.weight_n) - np.vdot(z_rows, data.sensordata.take(self.adr[:, :3])))

    def combined_cop(self, data: mujoco.MjData, ground: np.ndarray, threshold_n: float) -> np.ndarray | None:
        """The centre of pressure of both feet on the floor (3,) [m] from their ground reactions (2, 6) (moments about
        the origin, then the z = 0 plane); None while they carry no more than ``threshold_n``."""
        fz = mx = my = 0.0
        # in floats: two feet's x and y moments are a few products, cheaper than array operations
        for (f_x, f_y, f_z, m_x, m_y, _), (s_x, s_y, s_z) in zip(ground.tolist(),
                                                                  data.site_xpos[self.sites[len(SIDES):]].tolist()):
            fz += f_z
            mx += m_x + s_y * f_z - s_z * f_y
            my += m_y + s_z * f_x - s_x * f_z
        if fz <= threshold_n:
            return None
        return np.array([-my / fz, mx / fz, 0.0])
