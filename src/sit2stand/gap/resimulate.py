"""Replay a recording's commands in a simulated robot built from a model: the "simulate and compare" half of the
model-gap workflow, and the re-simulation with the named effects added.

The robot of the model under test (the nominal model: CAD; or CAD plus the effects the workflow named, written as a
plant file's ``unmodeled`` section) is started in the recording's first measured state (seated on the chair when the
recording begins seated), driven by the recorded joint commands (each applied at its stamp, followed along its
velocity in between, as the driver does) under the same PD + inverse-dynamics feed-forward with the CAD controller
model, and sampled at the recording's times. What differs from the measurements is what the model gets wrong.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import InputError
from ..robot.model import DEFAULT_ROBOT, SIDES, PlantConfig
from ..robot.plant import Plant
from .effects import Effect, alter_model, unmodeled_from
from .recording import Recording

SETTLE_S = 1.0               # the replay holds the first command this long before t = 0 (as `excite` does)


def plant_from_effects(effects: list[Effect], robot: str = DEFAULT_ROBOT) -> PlantConfig:
    """``robot``'s CAD plus the named effects (the workflow's effect dicts) as a plant configuration."""
    cfg = PlantConfig(name="augmented", robot=robot)
    cfg.unmodeled = unmodeled_from(effects)
    return cfg


def simulate(cfg: PlantConfig, rec: Recording, seated: bool, alterations: list[Effect] | None = None
             ) -> dict[str, np.ndarray]:
    """Replay ``rec``'s commands in the plant ``cfg`` (with ``alterations``: effects applied to the compiled model,
    ``gap.effects.alter_model``); returns the simulated measured torque (N, n), joint positions (N, n), feet
    vertical force (N,), COP x (N,) and whether the simulated robot fell, at ``rec.t_s``."""
    if rec.commands is None:
        raise InputError(f"{rec.source}: no /robot/joint_command to replay")
    plant = Plant(replace(cfg, fall_tilt_rad=np.pi), with_chair=seated)
    if alterations:
        alter_model(plant.model, alterations)
    if seated:
        plant.reset()
    else:
        q = plant.data.qpos.copy()
        q[:7] = rec.base_pose[0]
        q[plant.qadr] = rec.q[0] - plant.faults.q_offset
        plant.reset(q)
    cmd = rec.commands
    # hold the first command, not the measured angles: what the robot was told; an effect that loads a joint (a
    # spring, a mass) makes the measured angle lag the command, and holding the lagged angle would settle elsewhere
    first = cmd.q[0] if np.all(np.isfinite(cmd.q[0])) else rec.q[0]
    plant.command(first, feedforward="inverse_dynamics")
    plant.settle(SETTLE_S)
    dt = plant.cfg.timestep_s
    n = len(rec.t_s)
    tau = np.zeros((n, len(rec.joint_names)))
    q = np.zeros((n, len(rec.joint_names)))
    fz = np.zeros(n)
    cop = np.full(n, np.nan)
    c = -1
    t_end = float(rec.t_s[-1])
    k = 0
    t = 0.0
    while k < n and t <= t_end + dt:
        while c + 1 < len(cmd.t_s) and cmd.t_s[c + 1] <= t + 0.5 * dt:
            c += 1
            if np.all(np.isfinite(cmd.q[c])):
                plant.command(cmd.q[c], cmd.qd[c], cmd.qdd[c], feedforward="inverse_dynamics")
        while k < n and rec.t_s[k] <= t + 0.5 * dt:
            s = plant.sensors()
            tau[k], q[k] = s.tau, s.q
            fz[k] = sum(s.wrench_world[side][2] for side in SIDES)
            cop[k] = s.cop_m[0] if s.cop_valid else np.nan
            k += 1
        plant.step(1)
        t += dt
    return {"tau": tau, "q": q, "feet_fz": fz, "cop_x": cop, "fell": bool(plant.fallen)}


def compare(rec: Recording, sims: dict[str, dict]) -> dict[str, dict]:
    """RMS of each simulation against the measurements: COP x [m], feet vertical force [N], joint torques [N m]."""
    meas_cop = rec.cop[:, 0]
    out = {}
    for name, sim in sims.items():
        ok = np.isfinite(meas_cop) & np.isfinite(sim["cop_x"])
        out[name] = {"cop_x_rms_m": float(np.sqrt(np.mean((sim["cop_x"] - meas_cop)[ok] ** 2))) if ok.any() else None,
                     "feet_fz_rms_n": float(np.sqrt(np.mean((sim["feet_fz"] - rec.feet_force_z_n) ** 2))),
                     "tau_rms_nm": {j: float(np.sqrt(np.mean((sim["tau"][:, i] - rec.tau[:, i]) ** 2)))
                                    for i, j in enumerate(rec.joint_names)},
                     "fell": sim["fell"]}
    return out
