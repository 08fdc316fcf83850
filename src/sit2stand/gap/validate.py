"""Validation of the named effects by applying them for real, not to first order.

Selection works on linear signatures: an encoder offset to first order, a point mass without its rotational inertia.
Two candidates can cancel along a direction the signatures do not see (an offset of 102 rad and a mass), and the
first-order residual then looks perfect while the model with the effects is not. Two checks apply the effects:

* **the nonlinear residuals**: the nominal model with the named masses merged into its links, evaluated again along
  the recordings with the named encoder offsets taken out of the joint readings; the joint and sensor effects
  (exactly linear) subtracted. The gap over the disagreeing (channel, phase) pairs is recomputed from these: the
  shrink the workflow reports.
* **the re-simulation**: the recorded commands replayed in the plant with the named effects
  (:mod:`sit2stand.gap.resimulate`), and its COP x [m], feet vertical force [N] and joint positions [rad] compared
  with the measured ones against floors measured on plants with nothing hidden (``REPLAY_FLOORS``). These channels
  see what the inverse dynamics cannot: the contact.

An effect whose removal leaves the nonlinear gap no larger, or the re-simulation closer to the measurements, does not
improve the model and is not named.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin

from ..robot.model import PlantConfig
from .dataset import Dataset, GapError
from .effects import ft_location
from .kinematics import KINEMATIC_KINDS, kinematic_model
from .resimulate import plant_from_effects, simulate
from .residuals import body_link_names, evaluate, joint_columns

# the replay of a plant with nothing hidden differs from its measurements by sensor noise and the start state only:
# at most 0.04 cm COP x, 0.84 N feet force and 0.1 mrad joint position RMS (measured on excitation runs, seeds 1-2;
# soles 2.5 x softer: 0.25 cm COP x, 0.5 mrad at an ankle; a 40 N m/rad knee spring: 0.4 cm, 10 N, 9 mrad)
REPLAY_FLOORS = {"cop_x": 0.0005, "feet_fz": 1.5, "q": 0.0003}
REPLAY_UNITS = {"cop_x": "m", "feet_fz": "N", "q": "rad"}
# faults of the joint-torque sensors alone: the robot moves the same and the replay's channels (COP, feet force,
# joint angles) read the same, so its replay is the nominal one (an F/T bias shows in the COP and force: not here)
SENSOR_KINDS = ("torque_bias", "torque_gain")
REPLAY_ONLY_KINDS = ("contact_softness",)      # no inverse-dynamics signature: the measured forces carry it
# applied to the model or the joint readings and the dynamics evaluated again (no linear signature)
REEVALUATED_KINDS = ("extra_mass", "joint_offset") + KINEMATIC_KINDS


def gap_size(es: list[np.ndarray], ds: Dataset, pairs: list[tuple[int, int, str]]) -> float:
    """The gap above the noise over ``pairs`` (recording, channel, phase): sqrt(mean of max((rms / floor)^2 - 1, 0))
    with each pair's RMS of the residuals ``es``; 0 when no pair is given."""
    if not pairs:
        return 0.0
    z2 = []
    for r, c, phase in pairs:
        m = (ds.labels[r] == phase) & ds.evaluations[r].valid[:, c]
        z2.append(np.mean(es[r][m, c] ** 2) / ds.floors[r][c] ** 2)
    return float(np.sqrt(np.mean(np.maximum(np.array(z2) - 1.0, 0.0))))


def effect_columns(ds: Dataset, links: list[str], r: int, kind: str, location: str) -> np.ndarray:
    """(N, C, p) signature of effect ``kind`` at ``location`` along recording ``r`` (physical units)."""
    ev, rec = ds.evaluations[r], ds.recordings[r]
    if kind == "extra_mass":
        return ev.mass_cols[:, :, links.index(location), :]
    if kind == "ft_bias":
        side, a = ft_location(location)
        return ev.ft_cols[side][:, :, a:a + 1]
    if kind == "actuator_delay":
        return joint_columns(rec, ev, kind, 0)
    if location not in rec.joint_names:
        raise GapError(f"effect {kind} at unknown joint {location!r}")
    return joint_columns(rec, ev, kind, rec.joint_names.index(location))


def effect_theta(effect: dict) -> np.ndarray:
    """An effect's parameters in its signature's terms (a gain: its departure from 1; a spring: k, -k q_rest)."""
    k = effect["kind"]
    if k == "extra_mass":
        return float(effect["mass_kg"]) * np.concatenate([[1.0], np.asarray(effect["pos_m"], float)])
    if k == "torque_gain":
        return np.array([effect["value"] - 1.0])
    if k == "joint_spring":
        return np.array([effect["value"], -effect["value"] * effect.get("rest_rad", 0.0)])
    return np.array([float(effect["value"])])


def merged_model(nominal: pin.Model, effects: list[dict]) -> pin.Model:
    """``nominal`` with the extra masses of ``effects`` merged into their links (a negative one removed at its
    point, the link's rotational inertia kept) and its leg kinematics altered (``gap.kinematics``)."""
    links = body_link_names(nominal)
    model = kinematic_model(nominal, effects)
    for e in effects:
        if e["kind"] != "extra_mass":
            continue
        jid = links.index(e["location"]) + 1
        old, m, p = model.inertias[jid], float(e["mass_kg"]), np.asarray(e["pos_m"], float)
        if m > 0:
            model.inertias[jid] = old + pin.Inertia(m, p, np.eye(3) * 1e-4 * m)
        else:
            total = max(old.mass + m, 1e-6)
            model.inertias[jid] = pin.Inertia(total, (old.mass * old.lever + m * p) / total, old.inertia)
    return model


def exact_residuals(ds: Dataset, nominal: pin.Model, effects: list[dict], known: list[dict]) -> list[np.ndarray]:
    """Per recording, the (N, C) residual of the nominal model with ``effects`` applied for real (see the module
    docstring); ``known``: the nominal model file's own joint and sensor effects (already out of ``ds``)."""
    model = merged_model(nominal, effects)
    links = body_link_names(nominal)
    again = any(e["kind"] in REEVALUATED_KINDS for e in effects)   # else the residual is linear
    effects = [e for e in effects if e["kind"] not in REPLAY_ONLY_KINDS]
    out = []
    for r, (rec, ev, lab) in enumerate(zip(ds.recordings, ds.evaluations, ds.labels)):
        e_r = ev.e.copy()
        for eff in effects:
            if eff["kind"] not in REEVALUATED_KINDS:
                e_r -= _contribution(ds, links, r, eff)
        if not again:
            out.append(e_r)
            continue
        q = rec.q.copy()
        for e in effects:
            if e["kind"] == "joint_offset":       # reading - true angle
                q[:, rec.joint_names.index(e["location"])] -= e["value"]
        dyn = 6 + len(rec.joint_names)
        # the dynamics channels re-evaluated: the nominal residual's share of them replaced
        e_r[:, :dyn] += evaluate(model, replace(rec, q=q), seated=np.isin(lab, ["seated", "seat-off"]),
                                 offsets=False, signatures=False).e - ev.e[:, :dyn]
        for eff in known:                          # the model file's effects, on the re-evaluated channels only
            e_r[:, :dyn] -= _contribution(ds, links, r, eff)[:, :dyn]
        out.append(e_r)
    return out


def _contribution(ds: Dataset, links: list[str], r: int, effect: dict) -> np.ndarray:
    """(N, C) what ``effect`` adds to the residual of recording ``r``."""
    cols = effect_columns(ds, links, r, effect["kind"], effect["location"])
    return np.tensordot(cols, effect_theta(effect), axes=(2, 0))


# -- the re-simulation ------------------------------------------------------------------------------------------------
def replay_effects(ds: Dataset, effects: list[dict], nominal: dict[int, dict] | None = None) -> dict[int, dict]:
    """Recording index -> the simulated signals of its commands replayed in the plant with ``effects`` (runs that
    carry their commands only); ``nominal``: the nominal replay, returned as it is when the effects are all
    sensor faults (``SENSOR_KINDS``)."""
    physical = [e for e in effects if e["kind"] not in SENSOR_KINDS]
    if nominal is not None and not physical:
        return nominal
    cfg = plant_from_effects(effects, ds.robot) if effects else PlantConfig(robot=ds.robot)
    out = {}
    for r, rec in enumerate(ds.recordings):
        if rec.static or rec.commands is None:
            continue
        out[r] = simulate(cfg, rec, bool(ds.events[r]), alterations=effects)
    return out


def replay_residuals(ds: Dataset, sims: dict[int, dict]) -> dict[int, dict[str, np.ndarray]]:
    """Recording -> replay channel (``replay/cop_x``, ``replay/feet_fz``, ``replay/q/<joint>``) -> measured minus
    simulated series (NaN where the COP is undefined)."""
    out = {}
    for r, sim in sims.items():
        rec = ds.recordings[r]
        chans = {"replay/cop_x": rec.cop[:, 0] - sim["cop_x"], "replay/feet_fz": rec.feet_force_z_n - sim["feet_fz"]}
        for j, name in enumerate(rec.joint_names):
            chans[f"replay/q/{name}"] = rec.q[:, j] - sim["q"][:, j]
        out[r] = chans
    return out


def replay_floor(channel: str) -> float:
    """The noise floor of a replay channel (``REPLAY_FLOORS``)."""
    return REPLAY_FLOORS["q" if channel.startswith("replay/q/") else channel.split("/")[1]]


def replay_z(res: dict[int, dict[str, np.ndarray]]) -> dict[tuple[int, str], float]:
    """(recording, replay channel) -> RMS / floor."""
    out = {}
    for r, chans in res.items():
        for ch, x in chans.items():
            ok = np.isfinite(x)
            out[(r, ch)] = float(np.sqrt(np.mean(x[ok] ** 2)) / replay_floor(ch)) if ok.any() else 0.0
    return out


def replay_gap(z: dict[tuple[int, str], float], keys: list[tuple[int, str]]) -> float:
    """The re-simulation's gap above the noise over ``keys``: sqrt(mean of max(z^2 - 1, 0)), as :func:`gap_size`."""
    if not keys:
        return 0.0
    return float(np.sqrt(np.mean([max(z.get(k, 0.0) ** 2 - 1.0, 0.0) for k in keys])))
