"""The model-gap workflow: find where a nominal model disagrees with measured robot data, name the missing physical
effect(s), add them to the model, and show the gap shrink.

1. **Compare**: the nominal model (CAD, or identified parameters) is evaluated along each measured recording
   (:mod:`sit2stand.gap.residuals`): one residual per channel (the whole body's external wrench, each joint's torque).
2. **Find**: each channel's residual is measured against its noise floor (robust scale of the residual's fast part:
   what no slowly varying physical effect can produce; for static postures, what is left after fitting every
   candidate at once), per phase of the motion (seated, seat-off, rising, standing; for runs without a chair,
   moving and still). A ranked table says where the model is wrong.
3. **Name**: every candidate effect of the library (extra mass on each rigid group of links, viscous and Coulomb
   friction, encoder offset, torque-sensor bias and gain per joint, F/T bias per foot) is offered to a sparse
   selection (:mod:`sit2stand.gap.select`); the chosen effects come with 95 % confidence intervals. With none chosen
   and no channel above its floor, the answer is "no significant discrepancy"; channels still above their floor
   after the chosen effects are reported as a residual that no candidate explains.
4. **Add**: the effects are written to an augmented model file: the nominal links with the extra masses merged
   (``links``: the driver's ``controller_params`` and the analysis read it), the joint and sensor effects, and the
   same effects as a plant file's ``unmodeled`` section (to re-simulate the nominal model with them).
5. **Show**: residuals per channel before and after (the augmented model evaluated along the same data), as a JSON
   summary, a Markdown report and figures.

The workflow reads only the bags and the nominal model: never the plant's ``unmodeled`` section.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml

from ..robot.identify import IdentificationError, read_link_parameters
from ..robot.model import PlantConfig, controller_model
from .dataset import Dataset, GapError, fast_part_floor, load_dataset
from .recording import RecordingError
from .effects import FT_AXES, ft_location, unmodeled_dict, unmodeled_from
from .residuals import body_link_names, joint_columns
from .select import Candidate, Selection, select

MOVED_RAD = 0.1              # a joint whose range in the data is below this did not move: its links are one body
MOVING_RADPS = 0.05          # RMS speed above which a joint's friction can be seen
MIN_DELAY_S = 0.001          # one control step of the simulated robot
MASS_REACH_M = 0.6           # an extra mass further than this from its link's origin is not a mass on that link
MASS_MAX_KG = 40.0           # an extra mass above this on one link of a 90 kg robot is not a missing part
SIGNIFICANT_Z = 3.0          # a channel's RMS residual this many times its floor is a disagreement
UNITS = {"extra_mass": ("kg", "m"), "viscous_friction": "N m s/rad", "coulomb_friction": "N m",
         "torque_bias": "N m", "torque_gain": "1", "joint_offset": "rad", "actuator_delay": "s",
         "mass_scale": "true / model"}


# -- nominal model --------------------------------------------------------------------------------------------------
def load_nominal(path: str | Path | None) -> tuple[pin.Model, str, list[dict]]:
    """The nominal model: CAD (None or "cad"), identified parameters (``sit2stand identify`` YAML) or an augmented
    model written by this workflow (its ``links``, and its joint and sensor ``effects``, returned third)."""
    if path is None or str(path) == "cad":
        return controller_model(PlantConfig()), "cad", []
    try:
        model = controller_model(PlantConfig(), read_link_parameters(path))
        doc = yaml.safe_load(Path(path).read_text())
    except (IdentificationError, OSError, KeyError, ValueError, yaml.YAMLError) as err:
        raise GapError(f"{path}: not a usable model file: {err}") from None
    known = [e for e in doc.get("effects", []) or [] if e.get("kind") != "extra_mass"]
    return model, str(path), known


# -- candidates --------------------------------------------------------------------------------------------------------
def moved_joints(ds: Dataset) -> np.ndarray:
    """(n,) joints whose range over the data exceeds MOVED_RAD."""
    return np.max([np.ptp(r.q, axis=0) for r in ds.recordings], axis=0) > MOVED_RAD


def rigid_groups(model: pin.Model, ds: Dataset) -> dict[int, list[int]]:
    """Pinocchio body index (0-based: joint i+1) of each group's root -> member bodies: links joined by joints that
    did not move are one rigid body in these data. The feet (below the F/T sensors) are left out."""
    moved = moved_joints(ds)
    by_name = {n: moved[i] for i, n in enumerate(ds.joint_names)}
    groups: dict[int, list[int]] = {}
    for jid in range(1, model.njoints):
        name = model.names[jid]
        if name.startswith("leg_") and name.endswith("_6_joint"):
            continue
        root = jid
        while root > 1 and not by_name.get(model.names[root], True):
            root = model.parents[root]
        groups.setdefault(root - 1, []).append(jid - 1)
    return groups


def _mass_within_reach(theta: np.ndarray) -> bool:
    """An extra point mass is plausible within MASS_REACH_M of its link's origin, not vanishingly small, and under
    MASS_MAX_KG (larger ones are two candidates trading off along a direction the data do not see)."""
    m = float(theta[0])
    return 1e-3 < abs(m) <= MASS_MAX_KG and float(np.linalg.norm(theta[1:] / m)) <= MASS_REACH_M


def _stack(ds: Dataset, cols: list[np.ndarray]) -> np.ndarray:
    """Rows of every recording's valid samples (channel-major, time order within a channel), weighted by the floor;
    ``cols`` per recording: (N, C, p)."""
    out = []
    for ev, X, floor in zip(ds.evaluations, cols, ds.floors):
        Xw = X / floor[None, :, None]
        out.append(np.concatenate([Xw[ev.valid[:, c], c, :] for c in range(X.shape[1])], axis=0))
    return np.concatenate(out, axis=0)


def _series_id(ds: Dataset) -> np.ndarray:
    """Per stacked residual row, the id of its (recording, channel) series (time order within a series)."""
    ids = []
    for r, ev in enumerate(ds.evaluations):
        C = ev.e.shape[1]
        for c in range(C):
            ids.append(np.full(int(ev.valid[:, c].sum()), r * 1000 + c))
    return np.concatenate(ids)


def build_candidates(model: pin.Model, ds: Dataset) -> list[Candidate]:
    """Every effect of the library that these data can show (see the module docstring), with its signature rows."""
    links = body_link_names(model)
    names = ds.joint_names
    static = all(r.static for r in ds.recordings)
    cands: list[Candidate] = []
    for root, members in rigid_groups(model, ds).items():
        cands.append(Candidate("extra_mass", links[root], ["mass [kg]", "mass*com_x [kg m]", "mass*com_y [kg m]",
                                                           "mass*com_z [kg m]"],
                               _stack(ds, [ev.mass_cols[:, :, root, :] for ev in ds.evaluations]),
                               members=[links[m] for m in members], plausible=_mass_within_reach))
    speed = np.sqrt(np.mean(np.concatenate([r.qd for r in ds.recordings]) ** 2, axis=0))
    tau_sd = np.std(np.concatenate([ev.tau_model for ev in ds.evaluations]), axis=0)
    for j, name in enumerate(names):
        kinds = ["torque_bias", "joint_offset"]
        if tau_sd[j] > 1.0:
            kinds.append("torque_gain")
        if not static and speed[j] > MOVING_RADPS:
            kinds += ["viscous_friction", "coulomb_friction"]
        for kind in kinds:
            X = _stack(ds, [joint_columns(r, ev, kind, j) for r, ev in zip(ds.recordings, ds.evaluations)])
            if np.linalg.norm(X) < 1e-6:
                continue
            cands.append(Candidate(kind, name, [f"{kind} [{UNITS[kind]}]"], X))
    if any(ev.ctrl_delay is not None for ev in ds.evaluations):
        # a delay is causal and, to matter, at least one control step (1 ms): below that it is the residue of
        # re-evaluating the law from 50 Hz samples
        cands.append(Candidate("actuator_delay", "all joints", ["delay [s]"],
                               _stack(ds, [joint_columns(r, ev, "actuator_delay", 0)
                                           for r, ev in zip(ds.recordings, ds.evaluations)]),
                               plausible=lambda theta: float(theta[0]) >= MIN_DELAY_S))
    for side in ("left", "right"):          # one candidate per sensor axis: a bias is per channel
        for a, axis in enumerate(FT_AXES):
            cands.append(Candidate("ft_bias", f"ft_{side}/{axis}", [f"{axis} [{'N' if a < 3 else 'N m'}]"],
                                   _stack(ds, [ev.ft_cols[side][:, :, a:a + 1] for ev in ds.evaluations])))
    return cands


# -- the whole workflow ------------------------------------------------------------------------------------------
@dataclass
class GapResult:
    """What the workflow found: floors, residual RMS before and after, the disagreements, the named effects."""

    model_source: str
    bags: list[str]
    channels: list[str]
    floors: np.ndarray                     # (R, C)
    rms_before: np.ndarray                 # (R, C) over valid samples
    rms_after: np.ndarray
    table: list[dict]                      # ranked disagreements (channel x phase)
    selection: Selection
    effects: list[dict]
    verdict: str
    unexplained: list[dict]
    gap_before: float                      # gap_size over the (channel, phase) pairs >= SIGNIFICANT_Z floors before
    gap_after: float
    notes: list[str]
    dataset: Dataset
    after: list[np.ndarray]                # per recording: (N, C) residual of the augmented model
    known: list[dict] = field(default_factory=list)   # joint/sensor effects the nominal model file already had
    replay: list[dict] = field(default_factory=list)  # re-simulation figures (report.replay_all)

    @property
    def shrink(self) -> float:
        """Share of the gap the named effects removed (1 - after / before)."""
        return 1.0 - self.gap_after / self.gap_before if self.gap_before > 0 else 0.0


def _rms(e: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(C,) RMS of each channel over its valid samples (NaN: none)."""
    return np.array([np.sqrt(np.mean(e[valid[:, c], c] ** 2)) if valid[:, c].any() else np.nan
                     for c in range(e.shape[1])])


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


def ranked_table(ds: Dataset) -> list[dict]:
    """Where the model is wrong: per channel and phase, the RMS residual, its ratio to the floor, and when the
    largest disagreement happened; sorted by the ratio."""
    rows = []
    for r, (rec, ev, lab, floor) in enumerate(zip(ds.recordings, ds.evaluations, ds.labels, ds.floors)):
        for c, ch in enumerate(ev.channels):
            for phase in dict.fromkeys(lab):
                m = (lab == phase) & ev.valid[:, c]
                if m.sum() < 3:
                    continue
                x = ev.e[m, c]
                k = int(np.argmax(np.abs(x)))
                rms = float(np.sqrt(np.mean(x ** 2)))
                rows.append({"recording": r, "channel": ch, "phase": str(phase), "rms": rms,
                             "floor": float(floor[c]), "z": rms / float(floor[c]),
                             "worst_t_s": float(rec.t_s[m][k]), "worst": float(x[k]),
                             "unit": "N" if "force" in ch else "N m"})
    rows.sort(key=lambda d: -d["z"])
    return rows


def effect_summary(sel: Selection) -> list[dict]:
    """The chosen effects in physical terms with 95 % intervals (1.96 standard errors; position by the delta
    method from the mass and first moment)."""
    out = []
    for s in sel.effects:
        c = s.candidate
        d = {"kind": c.kind, "location": c.location, "share_of_gap": s.gain, "delta_bic": s.delta_bic,
             "alternatives": s.alternatives}
        se = np.sqrt(np.clip(np.diag(s.cov), 0, None))
        if c.kind == "extra_mass":
            m, mc = float(s.theta[0]), s.theta[1:]
            pos = mc / m if abs(m) > 1e-6 else np.full(3, np.nan)
            J = np.zeros((3, 4))           # d(mc/m) / d(m, mc)
            J[:, 0] = -mc / m ** 2
            J[:, 1:] = np.eye(3) / m
            pos_se = np.sqrt(np.clip(np.diag(J @ s.cov @ J.T), 0, None))
            d.update({"members": c.members, "mass_kg": m, "mass_ci95_kg": 1.96 * float(se[0]),
                      "pos_m": pos.tolist(), "pos_ci95_m": (1.96 * pos_se).tolist()})
        else:
            v = float(s.theta[0])
            if c.kind in ("torque_gain", "mass_scale"):   # fitted as the departure from 1
                d.update({"value": 1.0 + v, "ci95": 1.96 * float(se[0]),
                          "unit": "measured / true" if c.kind == "torque_gain" else UNITS[c.kind]})
            elif c.kind == "ft_bias":
                d.update({"value": v, "ci95": 1.96 * float(se[0]),
                          "unit": "N" if c.location.endswith(("fx", "fy", "fz")) else "N m"})
            else:
                d.update({"value": v, "ci95": 1.96 * float(se[0]), "unit": UNITS[c.kind]})
        out.append(d)
    return out


def describe(effect: dict) -> str:
    """One line naming an effect for a person."""
    k = effect["kind"]
    if k == "extra_mass":
        p = effect["pos_m"]
        members = [m for m in effect["members"] if m != effect["location"]]
        group = f" (rigid in these data with {', '.join(members)})" if members else ""
        return (f"extra mass on {effect['location']}{group}: {effect['mass_kg']:.2f} +- {effect['mass_ci95_kg']:.2f} "
                f"kg at ({p[0]:+.3f}, {p[1]:+.3f}, {p[2]:+.3f}) m in the link frame")
    label = {"viscous_friction": "viscous friction", "coulomb_friction": "Coulomb friction",
             "torque_bias": "torque-sensor bias", "torque_gain": "torque-sensor gain",
             "joint_offset": "encoder offset", "ft_bias": "force/torque sensor bias (sensor axes)",
             "actuator_delay": "actuator delay"}[k]
    return f"{label} at {effect['location']}: {effect['value']:.4g} +- {effect['ci95']:.2g} {effect['unit']}"


def _after(ds: Dataset, sel: Selection, cands_unweighted) -> list[np.ndarray]:
    """Residual of the augmented model along each recording: the nominal residual minus each effect's signature
    times its estimate (exact for masses without their rotational inertia, friction, biases and gains; first order
    for encoder offsets)."""
    out = []
    for r, ev in enumerate(ds.evaluations):
        e = ev.e.copy()
        for s in sel.effects:
            e -= np.tensordot(cands_unweighted(r, s.candidate), s.theta, axes=(2, 0))
        out.append(e)
    return out


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


def _quiet(_msg: str) -> None:
    """A progress callback that says nothing."""


def run(bags: list[str | Path], model_path: str | Path | None = None, rate_hz: float = 50.0,
        progress=None, controller: str | Path | None = None) -> GapResult:
    """The workflow on ``bags`` against the nominal model (see the module docstring). ``controller``: the link
    parameters the robot's controller ran with when the bags were recorded (the driver's ``controller_params``;
    None: CAD), for the controller channels; it is not the model under test."""
    say = progress or _quiet
    model, source, known = load_nominal(model_path)
    if not bags:
        raise GapError("no measured bag given")
    ds = load_dataset(bags, model, rate_hz=rate_hz, progress=say, controller_params=_controller_params(controller))
    links = body_link_names(model)
    _subtract_known(ds, links, known)
    _noise_floors(ds)
    say("  building the candidate effects")
    cands = build_candidates(model, ds)
    if any(r.static for r in ds.recordings):
        _static_floors(ds, cands)
        cands = build_candidates(model, ds)
    y = _stack(ds, [ev.e[:, :, None] for ev in ds.evaluations])[:, 0]
    sid = _series_id(ds)
    say(f"  {len(cands)} candidate effects, {len(y)} residual rows: selecting")
    sel = select(y, cands, series_id=sid, noise_rss=float(len(y)), progress=say)

    def unweighted(r: int, cand: Candidate) -> np.ndarray:
        """The candidate's signature on recording r, not divided by the noise floors."""
        return effect_columns(ds, links, r, cand.kind, cand.location)

    after = _after(ds, sel, unweighted)
    rms_b = np.array([_rms(ev.e, ev.valid) for ev in ds.evaluations])
    rms_a = np.array([_rms(e, ev.valid) for e, ev in zip(after, ds.evaluations)])
    effects = effect_summary(sel)
    floors = np.array(ds.floors)
    table = ranked_table(ds)
    pairs = [(d["recording"], ds.channels.index(d["channel"]), d["phase"]) for d in table if d["z"] >= SIGNIFICANT_Z]
    g0 = gap_size([ev.e for ev in ds.evaluations], ds, pairs)
    g1 = gap_size(after, ds, pairs)
    return GapResult(source, [str(b) for b in bags], ds.channels, floors, rms_b, rms_a, table, sel,
                     effects, _verdict(effects, table), _unexplained(ds, rms_a), g0, g1, ds.notes, ds, after, known)


def _controller_params(controller: str | Path | None) -> dict | None:
    """The controller's link parameters (None: CAD); GapError if the file is not usable."""
    try:
        return read_link_parameters(controller) if controller not in (None, "cad") else None
    except (IdentificationError, OSError) as err:
        raise GapError(f"{controller}: not a usable controller model: {err}") from None


def _subtract_known(ds: Dataset, links: list[str], known: list[dict]) -> None:
    """Take the model file's own joint and sensor effects out of the residuals (they are part of the model)."""
    for r, ev in enumerate(ds.evaluations):
        for eff in known:
            theta = np.array([eff["value"] - 1.0 if eff["kind"] == "torque_gain" else eff["value"]])
            ev.e -= np.tensordot(effect_columns(ds, links, r, eff["kind"], eff["location"]), theta, axes=(2, 0))


def _noise_floors(ds: Dataset) -> None:
    """Per recording, each channel's noise floor: the residual's fast part for runs, 1 (refitted later) for postures."""
    for rec, ev in zip(ds.recordings, ds.evaluations):
        ds.floors.append(np.ones(ev.e.shape[1]) if rec.static else fast_part_floor(ev.e, ev.valid, rec.t_s))
    for r, f in enumerate(ds.floors):
        bad = ~np.isfinite(f) | (f <= 0)
        f[bad] = np.nanmedian(f[~bad]) if (~bad).any() else 1.0
        ds.floors[r] = np.maximum(f, 1e-3)


def _static_floors(ds: Dataset, cands: list[Candidate]) -> None:
    """Static postures' floors: the robust scale per channel of what is left after fitting every candidate at once."""
    X = np.hstack([c.X for c in cands])
    y = _stack(ds, [ev.e[:, :, None] for ev in ds.evaluations])[:, 0]
    theta, *_ = np.linalg.lstsq(X, y, rcond=1e-8)
    res = y - X @ theta
    i = 0
    for r, (rec, ev) in enumerate(zip(ds.recordings, ds.evaluations)):
        nrow = int(ev.valid.sum())
        if rec.static:
            part = res[i:i + nrow]
            # rows are channel-major: rebuild per channel
            k = 0
            f = ds.floors[r].copy()
            for c in range(ev.e.shape[1]):
                m = int(ev.valid[:, c].sum())
                x = part[k:k + m] * ds.floors[r][c]
                k += m
                if m >= 3:
                    f[c] = max(1.4826 * np.median(np.abs(x - np.median(x))), 1e-3)
            ds.floors[r] = f
        i += nrow


def _unexplained(ds: Dataset, rms_after: np.ndarray) -> list[dict]:
    """Channels still above SIGNIFICANT_Z floors after the chosen effects, largest first."""
    unexplained = []
    for r, (a, f) in enumerate(zip(rms_after, ds.floors)):
        for c, ch in enumerate(ds.channels):
            if np.isfinite(a[c]) and a[c] > SIGNIFICANT_Z * f[c]:
                unexplained.append({"recording": r, "channel": ch, "rms": float(a[c]), "floor": float(f[c]),
                                    "z": float(a[c] / f[c])})
    unexplained.sort(key=lambda d: -d["z"])
    return unexplained


def _verdict(effects: list[dict], table: list[dict]) -> str:
    """One line: the named effects, or whether there was a disagreement at all."""
    if effects:
        return "; ".join(describe(e) for e in effects)
    worst = table[0]["z"] if table else 0.0
    return ("no significant discrepancy" if worst < SIGNIFICANT_Z
            else "disagreement found, but no candidate effect explains it")


# -- augmented model -------------------------------------------------------------------------------------------------
def augmented_model(result: GapResult, nominal: pin.Model) -> dict:
    """The augmented model file's content (see the module docstring)."""
    links = body_link_names(nominal)
    model = nominal.copy()
    effects = result.known + result.effects
    for e in effects:
        if e["kind"] != "extra_mass":
            continue
        jid = links.index(e["location"]) + 1
        old, m, p = model.inertias[jid], e["mass_kg"], np.asarray(e["pos_m"])
        if m > 0:
            model.inertias[jid] = old + pin.Inertia(m, p, np.eye(3) * 1e-4 * m)
        else:   # a lighter link than modelled: remove the mass at that point
            total = max(old.mass + m, 1e-6)
            model.inertias[jid] = pin.Inertia(total, (old.mass * old.lever + m * p) / total, old.inertia)
    link_params = {model.names[j]: {"mass": float(model.inertias[j].mass),
                                    "com": [float(v) for v in model.inertias[j].lever]}
                   for j in range(1, model.njoints)}
    return {"nominal": result.model_source, "bags": result.bags, "verdict": result.verdict,
            "effects": effects, "links": link_params, "unmodeled": unmodeled_dict(unmodeled_from(effects))}


def write_augmented(result: GapResult, nominal: pin.Model, path: str | Path) -> dict:
    """Write :func:`augmented_model` as YAML to ``path``; the document written."""
    doc = augmented_model(result, nominal)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("# written by sit2stand gap: the nominal model plus the effects it named\n"
                          + yaml.safe_dump(_plain(doc), sort_keys=False))
    return doc


def _plain(x):
    """``x`` with NumPy scalars and arrays as plain Python numbers and lists (for JSON)."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x)
    if isinstance(x, (np.integer, int)) and not isinstance(x, bool):
        return int(x)
    return x


def summary(result: GapResult) -> dict:
    """The result as plain data (``gap.json``)."""
    return _plain({
        "model": result.model_source, "bags": result.bags, "verdict": result.verdict,
        "effects": result.effects, "gap_before": result.gap_before, "gap_after": result.gap_after,
        "gap_shrink": result.shrink, "unexplained": result.unexplained[:20], "ranked": result.table[:30],
        "channels": {ch: {"floor": result.floors[:, c].tolist(), "rms_before": result.rms_before[:, c].tolist(),
                          "rms_after": result.rms_after[:, c].tolist()} for c, ch in enumerate(result.channels)},
        "replay": result.replay, "selection_steps": result.selection.steps, "n_rows": result.selection.n_rows,
        "n_eff": result.selection.n_eff, "events": result.dataset.events, "notes": result.notes})


def progress_printer(msg: str) -> None:
    """A progress callback printing to stderr."""
    print(msg, file=sys.stderr, flush=True)


def write_json(result: GapResult, path: str | Path) -> None:
    """Write :func:`summary` as JSON to ``path``."""
    Path(path).write_text(json.dumps(summary(result), indent=1))


__all__ = ["GapError", "RecordingError", "run", "write_augmented", "summary", "load_nominal", "describe"]
