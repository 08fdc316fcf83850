"""The model-gap report: Markdown, JSON and figures of a :class:`sit2stand.gap.workflow.GapResult`.

``sit2stand gap BAG [BAG ...] [--model M] --out DIR`` writes

* ``report.md``: the verdict, the effects named with their parameters and 95 % intervals, the ranked table of where
  the nominal model was wrong, and the gap per channel before and after;
* ``gap.json``: the same, machine-readable (``sit2stand.gap.report.summary``);
* ``augmented_model.yaml``: the nominal model plus the effects (the driver's ``controller_params`` reads its
  ``links``; its ``unmodeled`` section re-simulates the effects);
* ``gap_channels.png``: RMS residual / noise floor per channel, before and after;
* ``gap_residuals.png``: the most disagreeing channels against time, before and after, phases shaded;
* ``gap_cop.png``: the measured centre of pressure against the one each model predicts from the measured motion;
* ``gap_replay.png``: for runs that carry their commands, the commands replayed in simulation in the nominal model
  and with the named effects added (COP and feet force against the measured ones).

Also the augmented model file (:func:`write_augmented`).
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import pinocchio as pin
import yaml

from ..forceplate import DEFAULT_COP_THRESHOLD_N
from .candidates import describe
from .effects import unmodeled_dict, unmodeled_from
from .resimulate import compare
from .validate import merged_model
from .workflow import GapResult, load_nominal, run

PHASE_COLOURS = {"seated": "#dde8f5", "seat-off": "#f5dcc8", "rising": "#f7f0c8", "standing": "#ddf2dd",
                 "moving": "#f2f2f2", "still": "#ffffff", "static": "#ffffff"}


def _plt():

    matplotlib.use("Agg")

    return plt


def channels_figure(result: GapResult, png: Path, top: int = 24) -> None:
    plt = _plt()
    z_b = np.nan_to_num(result.rms_before / result.floors).max(axis=0)
    z_a = np.nan_to_num(result.rms_after / result.floors).max(axis=0)
    order = np.argsort(-z_b)[:top]
    fig, ax = plt.subplots(figsize=(10, 0.28 * len(order) + 1.6))
    y = np.arange(len(order))
    ax.barh(y + 0.2, z_b[order], 0.4, label="nominal model", color="#c0504d")
    ax.barh(y - 0.2, z_a[order], 0.4, label="with the named effects", color="#4f81bd")
    ax.axvline(3.0, color="k", lw=0.8, ls="--", label="3 x noise floor")
    ax.set_yticks(y, [result.channels[c] for c in order], fontsize=8)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("RMS residual / noise floor")
    ax.set_title("Where the model disagrees with the measurements (largest first)")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def _shade(ax, t: np.ndarray, labels: np.ndarray) -> None:
    start = 0
    for k in range(1, len(t) + 1):
        if k == len(t) or labels[k] != labels[start]:
            ax.axvspan(t[start], t[min(k, len(t) - 1)], color=PHASE_COLOURS.get(str(labels[start]), "#ffffff"),
                       lw=0, zorder=0)
            start = k


def residuals_figure(result: GapResult, png: Path, n: int = 4) -> None:
    plt = _plt()
    ds = result.dataset
    seen, picks = set(), []
    for row in result.table:
        key = (row["recording"], row["channel"])
        if key not in seen:
            seen.add(key)
            picks.append(key)
        if len(picks) == n:
            break
    fig, axes = plt.subplots(max(len(picks), 1), 1, figsize=(10, 2.2 * max(len(picks), 1) + 0.5), squeeze=False)
    for ax, (r, ch) in zip(axes[:, 0], picks):
        rec, ev, lab = ds.recordings[r], ds.evaluations[r], ds.labels[r]
        c = ev.channels.index(ch)
        t = rec.t_s if not rec.static else np.arange(len(rec), dtype=float)
        _shade(ax, t, lab)
        m = ev.valid[:, c]
        unit = "N" if "force" in ch else "N m"
        ax.plot(t[m], ev.e[m, c], ".-" if rec.static else "-", color="#c0504d", lw=1, ms=3, label="nominal model")
        ax.plot(t[m], result.after[r][m, c], ".-" if rec.static else "-", color="#4f81bd", lw=1, ms=3,
                label="with the named effects")
        f = result.floors[r, c]
        ax.axhspan(-3 * f, 3 * f, color="k", alpha=0.08, lw=0)
        ax.set_ylabel(f"{ch}\n[{unit}]", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="upper right")
    axes[0, 0].set_title("Residual (measured - model) of the most disagreeing channels; grey band: 3 x noise floor; "
                         "background: phases", fontsize=9)
    axes[-1, 0].set_xlabel("time [s]" if not all(r.static for r in ds.recordings) else "posture")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def model_cop_x(result: GapResult, r: int, after: bool) -> tuple[np.ndarray, np.ndarray]:
    """Measured COP x and the COP x the model predicts from the measured motion [m] (recording ``r``): the measured
    external wrench minus the residual of the base rows (world axes, about the mid-soles on the floor). NaN where
    the feet (measured, or in the model) carry less than a plate's COP threshold: no load, no COP."""
    ds = result.dataset
    rec, ev = ds.recordings[r], ds.evaluations[r]
    e = result.after[r] if after else ev.e
    fz = sum(w[:, 2] for w in rec.wrench.values())
    fz_model = fz - e[:, 2]
    my = _moment_about_centre(rec, ev)[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        cop_meas = np.where(fz > DEFAULT_COP_THRESHOLD_N, ev.centre_m[:, 0] - my / fz, np.nan)
        cop_model = np.where(fz_model > DEFAULT_COP_THRESHOLD_N, ev.centre_m[:, 0] - (my - e[:, 4]) / fz_model,
                             np.nan)
    return cop_meas, cop_model


def _cop_rms(meas: np.ndarray, model: np.ndarray, valid: np.ndarray) -> float:
    """RMS [m] of model - measured COP over the valid rows where both are defined (NaN: no such row)."""
    ok = valid & np.isfinite(meas) & np.isfinite(model)
    return float(np.sqrt(np.mean((model - meas)[ok] ** 2))) if ok.any() else float("nan")


def _moment_about_centre(rec, ev) -> np.ndarray:
    """Moment [N m] of the measured ground reactions about the mid-soles point, world axes (from the sole points
    the evaluation found)."""
    out = np.zeros((len(rec), 3))
    for s, w in rec.wrench.items():
        sole = ev.sole_m[s]
        out += w[:, 3:] + np.cross(sole - ev.centre_m, w[:, :3])
    return out


def cop_figure(result: GapResult, png: Path) -> None:
    plt = _plt()
    ds = result.dataset
    fig, axes = plt.subplots(len(ds.recordings), 1, figsize=(10, 2.6 * len(ds.recordings) + 0.4), squeeze=False)
    for r, ax in enumerate(axes[:, 0]):
        rec, ev = ds.recordings[r], ds.evaluations[r]
        t = rec.t_s if not rec.static else np.arange(len(rec), dtype=float)
        ok = ev.valid[:, 4]
        meas, before = model_cop_x(result, r, after=False)
        _, after = model_cop_x(result, r, after=True)
        rms_b, rms_a = 100 * _cop_rms(meas, before, ok), 100 * _cop_rms(meas, after, ok)
        _shade(ax, t, ds.labels[r])
        style = ".-" if rec.static else "-"
        ax.plot(t[ok], 100 * meas[ok], style, color="k", lw=1.2, ms=3, label="measured (feet F/T)")
        ax.plot(t[ok], 100 * before[ok], style, color="#c0504d", lw=1, ms=3, label="nominal model")
        ax.plot(t[ok], 100 * after[ok], style, color="#4f81bd", lw=1, ms=3, label="with the named effects")
        ax.set_ylabel("COP x [cm]")
        error = f"{rms_b:.2f} cm -> {rms_a:.2f} cm" if np.isfinite(rms_b) else "none (the model's feet carry no load)"
        ax.set_title(f"{Path(rec.source).name}: model COP error RMS {error}", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def cop_rms(result: GapResult) -> list[tuple[float, float]]:
    """(before, after) RMS [m] of the model COP x against the measured one, per recording (valid base rows where both
    carry load; NaN: none does)."""
    out = []
    for r, ev in enumerate(result.dataset.evaluations):
        ok = ev.valid[:, 4]
        meas, before = model_cop_x(result, r, after=False)
        _, after = model_cop_x(result, r, after=True)
        out.append((_cop_rms(meas, before, ok), _cop_rms(meas, after, ok)))
    return out


def cop_lines(result: GapResult) -> list[str]:
    """Per recording, the model COP error before and after the named effects, or why there is none (a figure that
    cannot be computed says so: no row where the model's feet carry load)."""
    return [f"model COP error, {result.bags[r]}: {100 * b:.2f} cm -> {100 * a:.2f} cm RMS" if np.isfinite(b) else
            f"model COP error, {result.bags[r]}: none (no row where the model's feet carry load)"
            for r, (b, a) in enumerate(cop_rms(result))]


def markdown(result: GapResult) -> str:
    lines = ["# Model gap report", "",
             f"- nominal model: `{result.model_source}`",
             f"- measured: {', '.join(f'`{b}`' for b in result.bags)}",
             f"- gap above the noise on the channels that disagreed, the named effects applied for real: "
             f"**{result.gap_before:.2f} -> {result.gap_after:.2f}** (shrink {100 * result.shrink:.0f} %; to first "
             f"order {result.gap_after_first_order:.2f}, {100 * result.shrink_first_order:.0f} %)",
             f"- the re-simulation's gap on its channels that disagreed (COP x, feet force, joint positions): "
             f"{result.replay_gap_before:.2f} -> {result.replay_gap_after:.2f}", ""]
    lines[-1:-1] = [f"- {line}" for line in cop_lines(result)]
    lines += ["", "## Verdict", ""]
    if result.effects:
        lines += [f"{len(result.effects)} effect(s) named:", ""]
        lines += [f"{i + 1}. {describe(e)} ({100 * e.share_of_gap:.1f} % of the residual when chosen, "
                  f"dBIC {e.delta_bic:.0f})" + (f"; equally good here: {', '.join(e.alternatives[:3])}"
                                                   if e.alternatives else "")
                  for i, e in enumerate(result.effects)]
    else:
        lines.append(f"**{result.verdict}**")
    lines += [""]
    lines += _unexplained_lines(result)
    if result.replay:
        lines += ["", "## The recorded commands replayed in simulation", "",
                  "| recording | model | COP x RMS vs measured | feet vertical force RMS | worst joint position RMS "
                  "| fell |", "| --- | --- | --- | --- | --- | --- |"]
        for rp in result.replay:
            for name, v in rp.items():
                if name == "recording":
                    continue
                cop = f"{100 * v['cop_x_rms_m']:.2f} cm" if v["cop_x_rms_m"] is not None else "n/a"
                lines.append(f"| {rp['recording']} | {name} | {cop} | {v['feet_fz_rms_n']:.1f} N | "
                             f"{1000 * v['q_rms_max_rad']:.2f} mrad | {v['fell']} |")
    lines += ["", "## Where the nominal model was wrong (ranked)", "",
              "| # | recording | channel | phase | RMS | floor | ratio | worst at [s] |",
              "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    lines += [f"| {i + 1} | {d['recording']} | {d['channel']} | {d['phase']} | {d['rms']:.3g} {d['unit']} | "
              f"{d['floor']:.3g} | {d['z']:.1f} | {d['worst_t_s']:.2f} |" for i, d in enumerate(result.table[:20])]
    lines += ["", "## Gap per channel (recording 0): RMS before -> after", "",
              "| channel | floor | before | after |", "| --- | --- | --- | --- |"]
    order = np.argsort(-np.nan_to_num(result.rms_before[0] / result.floors[0]))
    for c in order[:20]:
        lines.append(f"| {result.channels[c]} | {result.floors[0, c]:.3g} | {result.rms_before[0, c]:.3g} | "
                     f"{result.rms_after[0, c]:.3g} |")
    lines += ["", "## Selection steps", ""]
    lines += [f"- {s}" for s in result.selection.steps]
    if result.notes:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in result.notes]
    lines += ["", "Figures: `gap_channels.png`, `gap_residuals.png`, `gap_cop.png`, `gap_replay.png`. Model with the "
              "effects: "
              "`augmented_model.yaml`.", ""]
    return "\n".join(lines)


def _unexplained_lines(result: GapResult) -> list[str]:
    """The report's lines on the refused candidates and the residual no candidate explains."""
    lines = []
    if result.refused:
        lines += ["Refused (the residual they would have absorbed is left unexplained):", ""]
        lines += [f"- {d['effect']}: {d['why']}" for d in result.refused[:15]] + [""]
    if result.unexplained:
        lines += ["**A residual is left that no candidate explains:**", "",
                  "| recording | channel | RMS after | floor | ratio | above 3 floors [s] | shape |",
                  "| --- | --- | --- | --- | --- | --- | --- |"]
        lines += [f"| {u['recording']} | {u['channel']} | {u['rms']:.3g} | {u['floor']:.3g} | {u['z']:.1f} | "
                  f"{_span(u['above_s'])} | {u['shape']} |" for u in result.unexplained[:15]]
    elif result.effects:
        lines.append("Nothing is left above 3 x the noise floor on any channel.")
    return lines


def _span(above: list[float] | None) -> str:
    """A time span [s] as text."""
    return f"{above[0]:.1f}-{above[1]:.1f}" if above else "-"


def replay_all(result: GapResult) -> list[dict]:
    """The workflow's re-simulations (nominal model and with the named effects; see :mod:`sit2stand.gap.validate`)
    per recording, with their RMS against the measurements."""
    out = []
    sims = result.sims
    for r in sims.get("nominal model", {}):
        rec = result.dataset.recordings[r]
        pair = {name: sims[name][r] for name in sims}
        out.append({"recording": r, "sims": pair, "rms": compare(rec, pair)})
    return out


def replay_figure(result: GapResult, replays: list[dict], png: Path) -> None:
    plt = _plt()
    ds = result.dataset
    fig, axes = plt.subplots(len(replays), 2, figsize=(12, 2.8 * len(replays) + 0.4), squeeze=False)
    for row, rp in zip(axes, replays):
        rec = ds.recordings[rp["recording"]]
        t = rec.t_s
        for ax in row:
            _shade(ax, t, ds.labels[rp["recording"]])
        row[0].plot(t, 100 * rec.cop[:, 0], color="k", lw=1.2, label="measured")
        row[1].plot(t, rec.feet_force_z_n, color="k", lw=1.2, label="measured")
        for (name, sim), colour in zip(rp["sims"].items(), ("#c0504d", "#4f81bd")):
            rms = rp["rms"][name]
            cop_txt = f"{100 * rms['cop_x_rms_m']:.2f} cm" if rms["cop_x_rms_m"] is not None else "n/a"
            row[0].plot(t, 100 * sim["cop_x"], color=colour, lw=1, label=f"simulated, {name} (RMS {cop_txt})")
            row[1].plot(t, sim["feet_fz"], color=colour, lw=1,
                        label=f"simulated, {name} (RMS {rms['feet_fz_rms_n']:.1f} N)")
        row[0].set_ylabel("COP x [cm]")
        row[1].set_ylabel("feet vertical force [N]")
        row[0].set_title(f"{Path(rec.source).name}: the recorded commands replayed in each model", fontsize=9)
        for ax in row:
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7)
            ax.set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def write_report(result: GapResult, out: str | Path, progress=None) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    replays = replay_all(result)
    if replays:
        replay_figure(result, replays, out / "gap_replay.png")
    nominal, _, _ = load_nominal(None if result.model_source == "cad" else result.model_source,
                                 result.dataset.robot)
    doc = write_augmented(result, nominal, out / "augmented_model.yaml")
    write_json(result, out / "gap.json")
    (out / "report.md").write_text(markdown(result))
    channels_figure(result, out / "gap_channels.png")
    residuals_figure(result, out / "gap_residuals.png")
    cop_figure(result, out / "gap_cop.png")
    return doc


def gap_command(bags: list[str | Path], out: str | Path, model: str | None = None, rate_hz: float = 50.0,
                progress=None, controller: str | None = None, robot: str | None = None) -> GapResult:
    """``sit2stand gap``: run the workflow on ``robot``'s bags (a profile; None: TALOS) and write the report."""
    result = run(bags, model, rate_hz=rate_hz, progress=progress, controller=controller, robot=robot)
    write_report(result, out, progress)
    return result


def summary(result: GapResult) -> dict:
    """The result as plain data (``gap.json``)."""
    return plain_data({
        "model": result.model_source, "bags": result.bags, "verdict": result.verdict,
        "effects": [e.as_dict() for e in result.effects], "gap_before": result.gap_before,
        "gap_after": result.gap_after,
        "gap_shrink": result.shrink, "gap_after_first_order": result.gap_after_first_order,
        "gap_shrink_first_order": result.shrink_first_order, "replay_gap_before": result.replay_gap_before,
        "replay_gap_after": result.replay_gap_after, "refused": result.refused,
        "unexplained": result.unexplained[:20], "ranked": result.table[:30],
        "channels": {ch: {"floor": result.floors[:, c].tolist(), "rms_before": result.rms_before[:, c].tolist(),
                          "rms_after": result.rms_after[:, c].tolist()} for c, ch in enumerate(result.channels)},
        "replay": result.replay, "selection_steps": result.selection.steps, "n_rows": result.selection.n_rows,
        "n_eff": result.selection.n_eff, "events": result.dataset.events, "notes": result.notes})


def write_json(result: GapResult, path: str | Path) -> None:
    """Write :func:`summary` as JSON to ``path``."""
    Path(path).write_text(json.dumps(summary(result), indent=1))


# --- The model-gap workflow's augmented model file: the nominal links with the named masses merged, the joint and
# sensor effects, and the same effects as a plant file's ``unmodeled`` section (:mod:`sit2stand.gap.workflow`, step 4).


def augmented_model(result: GapResult, nominal: pin.Model) -> dict:
    """The augmented model file's content (see :mod:`sit2stand.gap.workflow`, step 4)."""
    effects = result.known + result.effects
    model = merged_model(nominal, effects)
    link_params = {model.names[j]: {"mass": float(model.inertias[j].mass),
                                    "com": [float(v) for v in model.inertias[j].lever]}
                   for j in range(1, model.njoints)}
    return {"nominal": result.model_source, "bags": result.bags, "verdict": result.verdict,
            "effects": [e.as_dict() for e in effects], "links": link_params,
            "unmodeled": unmodeled_dict(unmodeled_from(effects))}


def write_augmented(result: GapResult, nominal: pin.Model, path: str | Path) -> dict:
    """Write :func:`augmented_model` as YAML to ``path``; the document written."""
    doc = augmented_model(result, nominal)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("# written by sit2stand gap: the nominal model plus the effects it named\n"
                          + yaml.safe_dump(plain_data(doc), sort_keys=False))
    return doc


def plain_data(x):
    """``x`` with NumPy scalars and arrays as plain Python numbers and lists (for JSON)."""
    if isinstance(x, dict):
        return {str(k): plain_data(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain_data(v) for v in x]
    if isinstance(x, np.ndarray):
        return plain_data(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x)
    if isinstance(x, (np.integer, int)) and not isinstance(x, bool):
        return int(x)
    return x
