"""Figures of the robot identification: predicted vs measured COM per posture, and the COM path of a motion with the
CAD and the identified parameters (the paper's Fig. 7 idea)."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import pinocchio as pin

from ..errors import InputError
from .identify import IdentificationResult, PostureData, com_x, controller_model, split, with_parameters
from .model import PlantConfig
from .profile import SAGITTAL_LEG_ROLES
from .plant import Plant
from .postures import standing_qpos


def identified_model(result: IdentificationResult) -> pin.Model:
    """The controller model with identified parameters (full: per link; planar5: not a per-link model -> None)."""
    model = controller_model(PlantConfig.load(None, result.robot))
    if result.model_name == "full":
        return with_parameters(model, result.values)
    raise InputError("only the full model gives per-link parameters for a whole-body COM path")


def posture_figure(result: IdentificationResult, data: PostureData, png: Path, eval_fraction: float = 0.1,
                   seed: int = 0) -> None:
    """Measured COP x against predicted COM x (CAD and identified) for every posture, evaluation ones marked."""

    matplotlib.use("Agg")

    cad = controller_model(PlantConfig.load(None, result.robot))
    train, ev = split(len(data), eval_fraction, seed)
    cop = data.cop[:, 0]
    cad_x = np.array([com_x(cad, data, k) for k in range(len(data))])
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
    ax = axes[0]
    if result.model_name == "full":
        ident = with_parameters(cad, result.values)
        id_x = np.array([com_x(ident, data, k) for k in range(len(data))])
        ax.scatter(cop[train] * 1e3, id_x[train] * 1e3, s=14, c="tab:blue", label="identified (training)")
    else:
        id_x = None
    ev_id = np.array(result.eval_predictions["identified_x"])
    ax.scatter(cop[train] * 1e3, cad_x[train] * 1e3, s=14, c="tab:red", alpha=0.5, label="CAD (training)")
    ax.scatter(cop[ev] * 1e3, cad_x[ev] * 1e3, s=60, marker="s", facecolors="none", edgecolors="tab:red",
               label="CAD (held out)")
    ax.scatter(np.array(result.eval_predictions["cop_x"]) * 1e3, ev_id * 1e3, s=70, marker="*", c="tab:blue",
               label="identified (held out)")
    lim = [min(cop.min(), cad_x.min()) * 1e3 - 10, max(cop.max(), cad_x.max()) * 1e3 + 10]
    ax.plot(lim, lim, "k--", lw=0.8)
    ax.set_xlabel("measured COP x [mm]")
    ax.set_ylabel("predicted COM x [mm]")
    ax.set_title(f"{result.model_name}: held-out RMS {result.eval_rms_m * 1e3:.1f} mm (CAD "
                 f"{result.cad_eval_rms_m * 1e3:.1f} mm)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax = axes[1]
    err_cad = (cad_x - cop) * 1e3
    ax.hist(err_cad, bins=15, alpha=0.6, color="tab:red", label="CAD")
    if id_x is not None:
        ax.hist((id_x - cop) * 1e3, bins=15, alpha=0.6, color="tab:blue", label="identified")
    ax.set_xlabel("predicted COM x - measured COP x [mm] (all postures)")
    ax.set_ylabel("postures")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def com_path_figure(result: IdentificationResult, png: Path, cfg: PlantConfig | None = None) -> None:
    """Sagittal COM path of a sit-to-stand-like joint motion (seated -> standing, feet fixed) with CAD and with the
    identified parameters: as in the paper, the identified COM is lower and further back."""

    matplotlib.use("Agg")


    cfg = cfg or PlantConfig.load(None, result.robot)
    profile = cfg.profile
    plant = Plant(cfg, with_chair=False)
    cad = controller_model(cfg)
    ident = identified_model(result)
    start = plant.q_seated.copy()
    stand = standing_qpos(plant, 0.0, 0.0, 0.0, 0.0)
    paths = {"CAD": [], "identified": []}
    for s in np.linspace(0.0, 1.0, 60):
        legs = [plant.joint_names.index(j) for j in profile.leg_joints(SAGITTAL_LEG_ROLES)]
        q = start.copy()
        q[plant.qadr[legs]] = start[plant.qadr[legs]] + s * (stand[plant.qadr[legs]] - start[plant.qadr[legs]])
        hip, knee, ankle = (q[plant.qadr[plant.joint_names.index(profile.leg("left", r))]] for r in SAGITTAL_LEG_ROLES)
        qq = standing_qpos(plant, hip, knee, ankle, 0.0)
        for name, model in (("CAD", cad), ("identified", ident)):
            pq = plant.pin_configuration(qq)
            paths[name].append(pin.centerOfMass(model, model.createData(), pq).copy())
    fig, ax = plt.subplots(figsize=(6, 5))
    for name, color in (("CAD", "tab:red"), ("identified", "tab:blue")):
        p = np.array(paths[name])
        ax.plot(p[:, 0], p[:, 2], color=color, lw=2, label=f"{name} parameters")
        ax.plot(p[0, 0], p[0, 2], "o", color=color)
    ax.set_xlabel("COM x [m] (feet at 0)")
    ax.set_ylabel("COM z [m]")
    ax.set_title("COM path, seated (dot) to standing, same joint motion")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
