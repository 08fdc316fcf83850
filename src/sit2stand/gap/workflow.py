"""The model-gap workflow: find where a nominal model disagrees with measured robot data, name the missing physical
effect(s), add them to the model, and show the gap shrink.

1. **Compare**: the nominal model (CAD, or identified parameters) is evaluated along each measured recording
   (:mod:`sit2stand.gap.residuals`): one residual per channel (the whole body's external wrench, each joint's torque).
2. **Find**: each channel's residual is measured against its noise floor (robust scale of the residual's fast part:
   what no slowly varying physical effect can produce; for static postures, what is left after fitting every
   candidate at once), per phase of the motion (seated, seat-off, rising, standing; for runs without a chair,
   moving and still). A ranked table says where the model is wrong.
   The legs' kinematics come first (:mod:`sit2stand.gap.kinematics`): link lengths and joint axes named from the
   soles' closure (a loaded, flat foot stays put) become part of the model before the dynamics are named.
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

import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import yaml

from ..robot.identify import IdentificationError, read_link_parameters
from ..robot.model import PlantConfig, controller_model
from .candidates import build_candidates, describe, effect_summary, series_ids, stack_rows
from .dataset import Dataset, GapError, evaluate_all, fast_part_floor, load_dataset
from .effects import KINEMATIC_KINDS, REPLAY_ONLY_KINDS, Effect
from .kinematics import corrected, correction_candidates, fit_kinematics, kinematic_model
from .plausibility import RESIDUE, cancelling_offsets, lopsided
from .recording import RecordingError
from .residuals import (
    BACKLASH_GRID_RAD,
    COULOMB_V0_RADPS,
    body_link_names,
    fit_backlash_widths,
    fit_coulomb_widths,
    is_physics_channel,
)
from .select import MIN_SHARE, SIGNIFICANT_Z, Candidate, Selection, contact_note, select, where_and_shape
from .validate import (
    effect_columns,
    effect_theta,
    exact_residuals,
    fit_contact,
    gap_size,
    inconstant,
    replay_effects,
    replay_floor,
    replay_gap,
    replay_residuals,
    replay_z,
)

NO_DISCREPANCY = "no significant discrepancy"
"""The verdict when no channel is above its noise floor (robot and human side)."""
UNEXPLAINED = "disagreement found, but no candidate effect explains it"
"""The verdict's opening when a residual stands that no candidate explains."""
MAX_REFUSAL_ROUNDS = 4      # selection re-run without the refused candidates at most this often


# -- nominal model --------------------------------------------------------------------------------------------------
def load_nominal(path: str | Path | None, robot: str | None = None) -> tuple[pin.Model, str, list[Effect]]:
    """The nominal model of ``robot`` (a profile; None: TALOS): CAD (None or "cad"), identified parameters
    (``sit2stand identify`` YAML) or an augmented model written by this workflow (its ``links``, and its joint and
    sensor ``effects``, returned third)."""
    cfg = PlantConfig.load(None, robot)
    if path is None or str(path) == "cad":
        return controller_model(cfg), "cad", []
    try:
        model = controller_model(cfg, read_link_parameters(path))
        doc = yaml.safe_load(Path(path).read_text())
    except (IdentificationError, OSError, KeyError, ValueError, yaml.YAMLError) as err:
        raise GapError(f"{path}: not a usable model file: {err}") from None
    known = [e for e in (Effect.from_dict(d, f"{path}: effects") for d in doc.get("effects", []) or [])
             if e.kind != "extra_mass" and e.kind not in REPLAY_ONLY_KINDS]
    return model, str(path), known


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
    effects: list[Effect]
    verdict: str
    unexplained: list[dict]
    gap_before: float                      # gap_size over the (channel, phase) pairs >= SIGNIFICANT_Z floors before
    gap_after: float
    notes: list[str]
    dataset: Dataset
    after: list[np.ndarray]                # per recording: (N, C) residual of the augmented model
    known: list[Effect] = field(default_factory=list)   # joint/sensor effects the nominal model file already had
    replay: list[dict] = field(default_factory=list)  # re-simulation figures per recording (RMS per model)
    gap_after_first_order: float = 0.0     # the gap with the effects' linear signatures subtracted (selection's view)
    refused: list[dict] = field(default_factory=list)  # candidates refused (bounds, symmetry, no real improvement)
    replay_gap_before: float = 0.0         # the re-simulation's gap over the replay channels that disagreed
    replay_gap_after: float = 0.0
    sims: dict = field(default_factory=dict)   # "nominal model" / "with the named effects" -> recording -> signals
    closure: dict = field(default_factory=dict)  # the soles' closure: channels, z before / after, unexplained

    @property
    def shrink(self) -> float:
        """Share of the gap the named effects removed, applied for real (1 - after / before)."""
        return 1.0 - self.gap_after / self.gap_before if self.gap_before > 0 else 0.0

    @property
    def shrink_first_order(self) -> float:
        """The share the selection's linear signatures promise (1 - first-order after / before)."""
        return 1.0 - self.gap_after_first_order / self.gap_before if self.gap_before > 0 else 0.0


def _rms(e: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(C,) RMS of each channel over its valid samples (NaN: none)."""
    return np.array([np.sqrt(np.mean(e[valid[:, c], c] ** 2)) if valid[:, c].any() else np.nan
                     for c in range(e.shape[1])])


def ranked_table(ds: Dataset, residuals: list[np.ndarray]) -> list[dict]:
    """Where the model is wrong (``residuals``: per recording, (N, C)): per channel and phase, the RMS residual, its
    ratio to the floor, and when the largest disagreement happened; sorted by the ratio."""
    rows = []
    for r, (rec, ev, lab, floor) in enumerate(zip(ds.recordings, ds.evaluations, ds.labels, ds.floors)):
        for c, ch in enumerate(ev.channels):
            for phase in dict.fromkeys(lab):
                m = (lab == phase) & ev.valid[:, c]
                if m.sum() < 3:
                    continue
                x = residuals[r][m, c]
                k = int(np.argmax(np.abs(x)))
                rms = float(np.sqrt(np.mean(x ** 2)))
                rows.append({"recording": r, "channel": ch, "phase": str(phase), "rms": rms,
                             "floor": float(floor[c]), "z": rms / float(floor[c]),
                             "worst_t_s": float(rec.t_s[m][k]), "worst": float(x[k]),
                             "unit": "N" if "force" in ch else "N m"})
    rows.sort(key=lambda d: -d["z"])
    return rows


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


def _quiet(_msg: str) -> None:
    """A progress callback that says nothing."""


def run(bags: list[str | Path], model_path: str | Path | None = None, rate_hz: float = 50.0,
        progress=None, controller: str | Path | None = None, replay: bool = True, robot: str | None = None
        ) -> GapResult:
    """The workflow on ``bags`` against the nominal model (see the module docstring). ``controller``: the link
    parameters the robot's controller ran with when the bags were recorded (the driver's ``controller_params``;
    None: CAD), for the controller channels; it is not the model under test. ``replay``: re-simulate the runs
    that carry their commands (CAD nominal only: an identified model's links are not a plant file). ``robot``: the
    robot profile the bags are of (None: TALOS)."""
    say = progress or _quiet
    model, source, known = load_nominal(model_path, robot)
    if not bags:
        raise GapError("no measured bag given")
    params = _controller_params(controller)
    ds = load_dataset(bags, model, rate_hz=rate_hz, progress=say, controller_params=params)
    links = body_link_names(model)
    _subtract_known(ds, links, known)
    _noise_floors(ds)
    nominal = [ev.e.copy() for ev in ds.evaluations]
    kinematic, closure = _kinematics_first(ds, model, say)
    calibrated = kinematic_model(model, kinematic)
    if kinematic:                 # the dynamics' candidates on the calibrated legs; floors and table stay nominal
        evaluate_all(ds, calibrated, params)
        _subtract_known(ds, links, known)
    fit_coulomb_widths(ds.recordings, ds.evaluations)
    fit_backlash_widths(ds.recordings, ds.evaluations)
    say("  building the candidate effects")
    cands = build_candidates(calibrated, ds)
    if any(r.static for r in ds.recordings):
        _static_floors(ds, cands)
        cands = build_candidates(calibrated, ds)
    cands += correction_candidates(ds, model, kinematic)
    sel, refused = _select_checked(ds, cands, calibrated, say)
    refused += closure["refused"]
    kinematic = corrected(kinematic, [s for s in sel.effects if s.candidate.kind in KINEMATIC_KINDS], say)
    table = ranked_table(ds, nominal)
    pairs = [(d["recording"], ds.channels.index(d["channel"]), d["phase"]) for d in table if d["z"] >= SIGNIFICANT_Z]
    dynamic = replace(sel, effects=[s for s in sel.effects if s.candidate.kind not in KINEMATIC_KINDS])
    effects, exact = _confirm_exact(ds, model, kinematic + _with_widths(ds, effect_summary(dynamic)), known,
                                    refused, say)
    sims = {}
    if replay and source == "cad" and any(r.commands is not None and not r.static for r in ds.recordings):
        effects, exact, sims = _confirm_replay(ds, model, effects, exact, refused, say)
    sel.effects = [s for s in sel.effects if s.candidate.key in {e.key for e in effects}]
    first_order = _after(ds, sel, lambda r, c: _columns(ds, links, r, c))
    rms_b = np.array([_rms(e, ev.valid) for e, ev in zip(nominal, ds.evaluations)])
    rms_a = np.array([_rms(e, ev.valid) for e, ev in zip(exact, ds.evaluations)])
    g0 = gap_size(nominal, ds, pairs)
    res = GapResult(source, [str(b) for b in bags], ds.channels, np.array(ds.floors), rms_b, rms_a, table, sel,
                    effects, "", [], g0, gap_size(exact, ds, pairs), ds.notes, ds, exact, known,
                    gap_after_first_order=gap_size(first_order, ds, pairs), refused=refused, sims=sims,
                    closure=closure)
    _replay_summary(res)
    res.unexplained = _unexplained(res, inconstant(ds, sel.effects, lambda r, s: np.tensordot(
        _columns(ds, links, r, s.candidate), s.theta, axes=(2, 0))))
    res.verdict = _verdict(res)
    return res


def _select_checked(ds: Dataset, cands: list[Candidate], model: pin.Model, say) -> tuple[Selection, list[dict]]:
    """Selection, re-run without each chosen effect whose joint estimate is past its bounds (gap.plausibility), that is
    lopsided where the evidence is symmetric (gap.plausibility) or an encoder offset cancelled along its chain
    (gap.plausibility); the refused, with why."""
    links = body_link_names(model)
    y = stack_rows(ds, [ev.e[:, :, None] for ev in ds.evaluations])[:, 0]
    sid = series_ids(ds)
    exclude: set[str] = set()
    refused: list[dict] = []
    for round_ in range(MAX_REFUSAL_ROUNDS + 1):
        pool = [c for c in cands if c.key not in exclude]
        say(f"  {len(pool)} candidate effects, {len(y)} residual rows: selecting")
        sel = select(y, pool, series_id=sid, noise_rss=float(len(y)), progress=say)
        bad = [(s.candidate.key, why) for s in sel.effects
               if s.candidate.plausible and (why := s.candidate.plausible(s.theta)) is not None]
        bad += lopsided(ds, sel.effects, lambda r, s: np.tensordot(_columns(ds, links, r, s.candidate), s.theta,
                                                                   axes=(2, 0)))
        bad += [(key, why) for key, why in cancelling_offsets(model, sel.effects) if key not in dict(bad)]
        for key, why in bad:
            say(f"  refused {key}: {why}")
            refused.append({"effect": key, "why": why})
            exclude.add(key)
        if not bad or round_ == MAX_REFUSAL_ROUNDS:     # the last round's refused are dropped, not replaced
            sel.effects = [s for s in sel.effects if s.candidate.key not in exclude]
            break
    for step in sel.steps:                  # skipped during the forward pass for implausible estimates
        if "implausible" in step and step["implausible"] not in {r["effect"] for r in refused} \
                and not step.get("why", "").startswith(RESIDUE):
            refused.append({"effect": step["implausible"], "why": step.get("why", "implausible")})
    return sel, refused


def _columns(ds: Dataset, links: list[str], r: int, c: Candidate) -> np.ndarray:
    """(N, C, p) candidate ``c``'s signature along recording ``r``, physical units."""
    return c.columns[r] if c.columns is not None else effect_columns(ds, links, r, c.kind, c.location)


def _weighted_rss(es: list[np.ndarray], ds: Dataset) -> float:
    """Sum over recordings, channels and valid samples of (residual / floor)^2: the selection's objective."""
    return float(sum(np.sum((e / f[None, :])[ev.valid] ** 2) for e, f, ev in zip(es, ds.floors, ds.evaluations)))


def _confirm_exact(ds: Dataset, model: pin.Model, effects: list[Effect], known: list[Effect], refused: list[dict],
                   say) -> tuple[list[Effect], list[np.ndarray]]:
    """Drop, weakest first, each effect that does not lower the nonlinear residual (gap.validate) by the selection's
    practical floor; the kept effects and their nonlinear residuals."""
    n_rows = sum(int(ev.valid.sum()) for ev in ds.evaluations)
    exact = exact_residuals(ds, model, effects, known)
    for e in sorted(effects, key=lambda d: d.share_of_gap):
        if e.kind in KINEMATIC_KINDS:           # the soles' closure confirmed them, not the torques
            continue
        rest = [d for d in effects if d is not e]
        without = exact_residuals(ds, model, rest, known) if e.kind in ("extra_mass", "joint_offset") else \
            [x + np.tensordot(effect_columns(ds, body_link_names(model), r, e.kind, e.location),
                              effect_theta(e), axes=(2, 0)) for r, x in enumerate(exact)]
        gain = _weighted_rss(without, ds) - _weighted_rss(exact, ds)
        if gain < MIN_SHARE * n_rows:
            key = e.key
            say(f"  not confirmed: {key} (applied for real it lowers the residual by {gain:.3g})")
            refused.append({"effect": key, "why": "applied for real (nonlinear residuals) it does not improve the "
                                                 "model"})
            effects, exact = rest, without
    return effects, exact


def _kinematics_first(ds: Dataset, model: pin.Model, say) -> tuple[list[Effect], dict]:
    """The legs' link lengths and joint axes from the soles' closure (gap.kinematics), before the dynamics: a
    kinematic error left in the model would be absorbed by dynamic proxies. Encoder offsets the closure sees are
    left to the dynamics, which name them with the torques' evidence as well."""
    found, report = fit_kinematics(ds, model, say)
    kinematic = [e for e in found if e.kind in KINEMATIC_KINDS]
    for e in kinematic:
        say(f"  named from the soles' closure: {describe(e)}")
    return kinematic, report


def _confirm_replay(ds: Dataset, model: pin.Model, effects: list[Effect], exact: list[np.ndarray],
                    refused: list[dict], say) -> tuple[list[Effect], list[np.ndarray], dict]:
    """Re-simulate with the nominal model and with the effects; while the effects make the re-simulation worse,
    drop the one whose removal improves it most."""
    say("  re-simulating the recorded commands: nominal model, then with the named effects")
    nominal = replay_effects(ds, [])
    z0 = replay_z(replay_residuals(ds, nominal))
    keys = [k for k, z in z0.items() if z >= SIGNIFICANT_Z] or list(z0)
    sims = replay_effects(ds, effects, nominal)
    score = replay_gap(replay_z(replay_residuals(ds, sims)), keys)
    while effects and score > replay_gap(z0, keys):
        trials = [(replay_gap(replay_z(replay_residuals(ds, sim)), keys), i, sim)
                  for i, sim in ((i, replay_effects(ds, effects[:i] + effects[i + 1:], nominal))
                                 for i in range(len(effects)))]
        best, i, sim = min(trials, key=lambda t: t[0])
        if best >= score:
            break
        e = effects[i]
        say(f"  not confirmed: {e.key} (the re-simulation is closer without it)")
        refused.append({"effect": e.key, "why": "the re-simulation is closer without it"})
        effects = effects[:i] + effects[i + 1:]
        score, sims = best, sim
        exact = exact_residuals(ds, model, effects, [])
    # contact only when the inverse dynamics agree: their own residual left means another effect is missing, and a
    # contact change would only hide its replay (seen: a missed rotor inertia named as softer soles). The controller
    # channels (measured torque against our own control law) do not count: no physics is in them (seen: a named
    # actuator delay left 3-4 floors on one joint's while still, and the soft soles beside it went unsearched)
    physics = np.array([is_physics_channel(ch) for ch in ds.channels])
    id_quiet = not any(np.nan_to_num(_rms(e, ev.valid) / f > SIGNIFICANT_Z)[physics].any()
                       for e, ev, f in zip(exact, ds.evaluations, ds.floors))
    found, sims = fit_contact(ds, effects, sims, say) if id_quiet else (None, sims)
    if found is not None:
        effects = effects + [found]
    return effects, exact, {"nominal model": nominal, "with the named effects": sims}


def _replay_summary(res: GapResult) -> None:
    """The re-simulation's RMS per model and recording (``res.replay``) and its gap before and after."""
    if not res.sims:
        return
    ds = res.dataset
    z = {name: replay_z(replay_residuals(ds, sims)) for name, sims in res.sims.items()}
    z0, z1 = z["nominal model"], z["with the named effects"]
    keys = [k for k, v in z0.items() if v >= SIGNIFICANT_Z]
    res.replay_gap_before, res.replay_gap_after = replay_gap(z0, keys), replay_gap(z1, keys)
    res.replay = []
    for r in res.sims["nominal model"]:
        row = {"recording": r}
        for name, zz in z.items():
            q = max(zz[(r, c)] for c in [k for (rr, k) in zz if rr == r and k.startswith("replay/q/")])
            row[name] = {"cop_x_rms_m": zz[(r, "replay/cop_x")] * replay_floor("replay/cop_x"),
                         "feet_fz_rms_n": zz[(r, "replay/feet_fz")] * replay_floor("replay/feet_fz"),
                         "q_rms_max_rad": q * replay_floor("replay/q/x"),
                         "fell": bool(res.sims[name][r]["fell"])}
        res.replay.append(row)


def _controller_params(controller: str | Path | None) -> dict | None:
    """The controller's link parameters (None: CAD); GapError if the file is not usable."""
    try:
        return read_link_parameters(controller) if controller not in (None, "cad") else None
    except (IdentificationError, OSError) as err:
        raise GapError(f"{controller}: not a usable controller model: {err}") from None


def _with_widths(ds: Dataset, effects: list[Effect]) -> list[Effect]:
    """``effects``, each Coulomb friction with the transition speed its signature used (``v0_radps``)."""
    names = ds.recordings[0].joint_names
    for e in effects:
        if e.kind == "coulomb_friction":
            e.v0_radps = float(ds.evaluations[0].coulomb_v0[names.index(e.location)])
    return effects


def _subtract_known(ds: Dataset, links: list[str], known: list[Effect]) -> None:
    """Take the model file's own joint and sensor effects out of the residuals (they are part of the model; a
    Coulomb friction with the transition speed it was named with, a backlash with its own play as the width)."""
    for rec, ev in zip(ds.recordings, ds.evaluations):
        ev.coulomb_v0 = np.full(ev.n_joints, COULOMB_V0_RADPS) if ev.coulomb_v0 is None else ev.coulomb_v0
        ev.backlash_b0 = np.full(ev.n_joints, BACKLASH_GRID_RAD[0]) if ev.backlash_b0 is None else ev.backlash_b0
        for eff in known:
            if eff.location not in rec.joint_names:
                continue
            j = rec.joint_names.index(eff.location)
            if eff.kind == "coulomb_friction" and eff.v0_radps is not None:
                ev.coulomb_v0[j] = float(eff.v0_radps)
            elif eff.kind == "backlash":
                ev.backlash_b0[j] = float(eff.value)
    for r, ev in enumerate(ds.evaluations):
        for eff in known:
            ev.e -= np.tensordot(effect_columns(ds, links, r, eff.kind, eff.location), effect_theta(eff),
                                 axes=(2, 0))


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
    y = stack_rows(ds, [ev.e[:, :, None] for ev in ds.evaluations])[:, 0]
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


def _unexplained(res: GapResult, proxies: list[dict]) -> list[dict]:
    """Channels still above SIGNIFICANT_Z floors with the named effects applied for real, and the re-simulation's,
    each with when and what its shape suggests (gap.select), and the residual ``proxies`` absorb (named
    effects whose size changes along the run: gap.validate); largest first."""
    ds = res.dataset
    out = list(proxies)
    for r, (a, f) in enumerate(zip(res.rms_after, ds.floors)):
        for c, ch in enumerate(ds.channels):
            if np.isfinite(a[c]) and a[c] > SIGNIFICANT_Z * f[c]:
                out.append({"recording": r, "channel": ch, "rms": float(a[c]), "floor": float(f[c]),
                            "z": float(a[c] / f[c]),
                            **where_and_shape(ds, r, ch, res.after[r][:, c], ds.evaluations[r].valid[:, c], f[c])})
    id_quiet = {r: not any(u["recording"] == r and is_physics_channel(u["channel"]) for u in out)
                for r in range(len(ds.recordings))}
    sims = res.sims.get("with the named effects", {})
    for r, chans in replay_residuals(ds, sims).items():
        for ch, x in chans.items():
            ok = np.isfinite(x)
            z = float(np.sqrt(np.mean(x[ok] ** 2)) / replay_floor(ch)) if ok.any() else 0.0
            if z > SIGNIFICANT_Z:
                d = {"recording": r, "channel": ch, "rms": z * replay_floor(ch), "floor": replay_floor(ch), "z": z,
                     **where_and_shape(ds, r, ch, np.nan_to_num(x), ok, replay_floor(ch))}
                d["shape"] = contact_note(id_quiet[r], ch) or d["shape"]
                out.append(d)
    out += res.closure.get("unexplained", [])
    out.sort(key=lambda d: -d["z"])
    return out


def _verdict(res: GapResult) -> str:
    """One line: the named effects and what is left unexplained, or whether there was a disagreement at all."""
    worst = res.table[0]["z"] if res.table else 0.0
    left = ""
    if res.unexplained:
        u = res.unexplained[0]
        left = (f"a residual no candidate explains on {len(res.unexplained)} channel(s), worst {u['channel']} at "
                f"{u['z']:.1f} floors: {u['shape']}")
    if res.effects:
        return "; ".join(describe(e) for e in res.effects) + (f"; unexplained: {left}" if left else "")
    if left:
        return f"{UNEXPLAINED}: {left}"
    return NO_DISCREPANCY if worst < SIGNIFICANT_Z else UNEXPLAINED


def progress_printer(msg: str) -> None:
    """A progress callback printing to stderr."""
    print(msg, file=sys.stderr, flush=True)


__all__ = ["GapError", "RecordingError", "run", "load_nominal", "describe"]
