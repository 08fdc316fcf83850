"""Benchmark (not a test): the human-side hit rate of the model-gap workflow.

    python -m sit2stand.bench --only gap_human [--gap-human-n 20] [--gap-human-cases hand,none] (make bench-gap-human)

``n`` digital humans per case of the human-side suite (:mod:`sit2stand.batch.gap`: an extra mass on each segment
group, a scale error, nothing hidden), run as a batch and scored by :func:`sit2stand.batch.gap.score_run`; the
figures per case and overall against :data:`TARGETS`.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from ..batch.engine import run_jobs
from ..batch.gap import CASES, FAILED_ROW, GROUPS, draw_cases, gap_human_jobs
from ..human.skeleton import SEGMENTS

TARGETS = {"hit_rate": 0.9, "clean_rate": 0.9, "none_no_alarm_rate": 0.95}
"""Targets: in-library effects named fully right in 90 %, nothing spurious in 90 %; nothing hidden: no alarm 95 %."""


def _hidden_text(h: dict | None) -> str:
    if h is None:
        return "nothing"
    if h["kind"] == "extra_mass":
        return f"extra_mass @ {h['location']} {h['mass_kg']:.2f} kg"
    return f"mass_scale {h['value']:.3f}"


def progress_line(i: int, n: int, row: dict) -> str:
    """``[i/n] hit/MISS case: hidden ... -> named ...`` (``+`` after hit/MISS: something else named too)."""
    mark = ("hit " if row["hit"] else "MISS") + (" " if row["clean"] or row["hidden"] is None else "+")
    size = "" if np.isnan(row["size_error"]) else f" (size off {100 * row['size_error']:.0f} %)"
    err = f"; ERROR {row['error'][:100]}" if row.get("error") else ""
    return (f"  [{i}/{n}] {mark} {row['case']}: hidden {_hidden_text(row['hidden'])} -> named {row['named']}{size}; "
            f"{row['body']['style']} {row['body']['height_m']:.2f} m {row['body']['mass_kg']:.0f} kg; "
            f"{row['wall_s']:.1f} s{err}")


def bench_gap_human(n: int = 20, cases: tuple[str, ...] = CASES, workers: int = 1, seed: int = 0,
                    progress: bool = True, vary_subject: bool = True, out: Path | None = None,
                    address: str | None = None) -> dict:
    """The human-side hit rates (see the module docstring): the rows as a batch (:mod:`sit2stand.batch.engine`:
    ``workers`` Ray workers, or the cluster at ``address``; 1: this process; its table in ``out``, default a
    temporary folder), figures per case and overall against the targets (``vary_subject`` False: bodies of
    de Leva's proportions, a diagnosis)."""
    todo = draw_cases(n, cases, seed, vary_subject)
    t0 = time.perf_counter()
    done = [0]

    def show(row: dict) -> None:
        done[0] += 1
        if progress:
            print(progress_line(done[0], len(todo), row) if row["status"] == "ok" else
                  f"  [{done[0]}/{len(todo)}] FAILED {row['key']}: {row['error']}", flush=True)
    with tempfile.TemporaryDirectory(prefix="sit2stand-gap-human-") as tmp:
        rows = run_jobs(gap_human_jobs(todo), out or Path(tmp), address=address, workers=workers, fresh=True,
                        on_row=show, label="bench-gap-human")
    rows = [r if r["status"] == "ok" else {**r, **FAILED_ROW, "hidden": c.hidden_row(), "wall_s": float("nan")}
            for r, c in zip(rows, todo)]
    out_rates = gap_human_rates(rows)
    out_rates.update({"humans_per_case": n, "workers": workers, "seed": seed, "vary_subject": vary_subject,
                      "wall_s": time.perf_counter() - t0})
    return out_rates


def _median_pct(values: list[float]) -> float:
    vals = [v for v in values if not np.isnan(v)]
    return float(100 * np.median(vals)) if vals else float("nan")


def gap_human_rates(rows: list[dict]) -> dict:
    """The benchmark's figures per case, overall against :data:`TARGETS`, the misses, and every row."""
    out: dict[str, object] = {}
    for name in dict.fromkeys(r["case"] for r in rows):
        rs = [r for r in rows if r["case"] == name]
        if name == "none":
            out["none_no_alarm_rate"] = float(np.mean([r["hit"] for r in rs]))
            out["none_no_effect_rate"] = float(np.mean([r["clean"] for r in rs]))
        else:
            out[f"{name}_hit_rate"] = float(np.mean([r["hit"] for r in rs]))
            out[f"{name}_clean_rate"] = float(np.mean([r["clean"] for r in rs]))
            out[f"{name}_clean_hit_rate"] = float(np.mean([r["hit"] and r["clean"] for r in rs]))
            out[f"{name}_found_rate"] = float(np.mean([r["found"] for r in rs]))
            out[f"{name}_median_size_error_pct"] = _median_pct([r["size_error"] for r in rs])
            if name in GROUPS and name not in SEGMENTS:
                out[f"{name}_wrong_side_rate"] = float(np.mean([r["wrong_side"] for r in rs]))
        out[f"{name}_wall_s"] = float(sum(r["wall_s"] for r in rs))
    effect = [r for r in rows if r["hidden"] is not None]
    if effect:
        out["hit_rate"] = float(np.mean([r["hit"] for r in effect]))
        out["clean_rate"] = float(np.mean([r["clean"] for r in effect]))
        out["clean_hit_rate"] = float(np.mean([r["hit"] and r["clean"] for r in effect]))
        out["median_size_error_pct"] = _median_pct([r["size_error"] for r in effect])
    for key, target in TARGETS.items():
        if key in out:
            out[f"{key}_vs_{100 * target:.0f}pct_target"] = out[key] / target
    out["runs"] = len(rows)
    out["errors"] = sum(bool(r.get("error")) for r in rows)
    out["run_s_median"] = float(np.median([r["wall_s"] for r in rows])) if rows else float("nan")
    out["misses"] = [{k: r.get(k) for k in ("case", "hidden", "named", "size_error", "verdict", "error")}
                     for r in rows if not (r["hit"] and r["clean"])]
    out["rows"] = rows
    return out


def summary_table(out: dict) -> str:
    """Per case: hits, clean, median size error, wall; then the overall rates against the targets."""
    n = out.get("humans_per_case", 0)
    rows = out.get("rows", [])
    lines = [f"  {'case':<10} {'hits':>6} {'clean':>6} {'both':>6} {'size err':>9} {'wall s':>7}"]
    for name in dict.fromkeys(r["case"] for r in rows):
        rs = [r for r in rows if r["case"] == name]
        hits, clean = sum(r["hit"] for r in rs), sum(r["clean"] for r in rs)
        both = sum(r["hit"] and r["clean"] for r in rs)
        err = out.get(f"{name}_median_size_error_pct", float("nan"))
        lines.append(f"  {name:<10} {hits:>3}/{n:<2} {clean:>3}/{n:<2} {both:>3}/{n:<2} "
                     f"{'' if np.isnan(err) else f'{err:.0f} %':>9} {out[f'{name}_wall_s']:>7.0f}")
    for key, target in TARGETS.items():
        if key in out:
            lines.append(f"  {key}: {100 * out[key]:.0f} % (target {100 * target:.0f} %)")
    return "\n".join(lines)
