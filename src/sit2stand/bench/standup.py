"""Benchmark (not a test): a population of digital humans stood up by a simulated robot (TALOS, or ``--robot``).

    python -m sit2stand.bench.standup [--cases 30] [--seed 0] [--jobs 1] [--address RAY] [--only-style S]
                                      [--marker-rate 100] [--controller wbc|inverse_dynamics] [--robot g1] [--out DIR]
                                                                                           (make bench-standup)

Each case is a digital human of :func:`sit2stand.batch.standup.sample_population` (stature, mass, BMI, sex, seat,
three styles in turn; one seed fixes the whole population; a body the synthesiser refuses is redrawn with the next
seeds and marked ``*`` in the table), run as a batch (:mod:`sit2stand.batch.engine`: ``--jobs`` Ray workers, or
the cluster at ``--address``; 1: this process).

Each demonstration is written to a temporary bag and run through :func:`sit2stand.retarget.offline.run` on the
default plant with the identified parameters, its other options at their defaults (what ``sit2stand retarget BAG
--params P --simulate`` does: whole-body torque control unless ``--controller inverse_dynamics``). Per case: stood
up, ``time_scale`` and ``duration_ratio`` (robot / human duration) from the summary, COM tracking RMS (robot's true
COM against the plan), the plan's forward COM deviation from the mapped human COM (the retargeter's COM target,
compared at the human time each command plays), the peak joint torque the controller asks for (PD + feed-forward;
the QP's torques) over the URDF effort limit, the share of commands with some joint clamped at its limit, the share
of off-chair commands whose own ZMP leaves the feet, all from ``run``'s summary, and wall time.

Writes ``DIR/bench_standup.json`` (cases and aggregate), the batch's table (``DIR/results.parquet``, ``.csv``) and each
case's retarget folder under ``DIR/cases/``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from . import project_folder, write_result
from ..batch.engine import run_jobs
from ..batch.standup import RISE_S, STYLES, Case, Setting, sample_population, standup_jobs, synthesise  # noqa: F401
from ..demo import demo_params, robot_identification
from ..robot.model import DEFAULT_ROBOT
from ..retarget.offline import DEFAULT_PLAN, PLANS
from ..retarget.report import KNEE_TOLERANCE_DEG
from ..robot.plant import CONTROLLERS, DEFAULT_CONTROLLER

DEFAULT_OUT = Path("bench") / "results" / "standup"
"""Under the project folder (:func:`~sit2stand.bench.project_folder`)."""
TARGET_TIME_SCALE = 1.5         # the target: at least 90 % stand with time_scale at most 1.5
QP_TARGET_MS = 1.0              # the target: the torque controller's QP p99 at most 1 ms per step
CASE_FIELDS = tuple(f.name for f in dataclasses.fields(Case))


def bench_row(row: dict) -> dict:
    """A batch table row as this benchmark's row: the body under ``case``, a failed case's ``stage``."""
    out = {k: v for k, v in row.items() if k not in CASE_FIELDS}
    out["case"] = {k: row[k] for k in CASE_FIELDS}
    if row.get("stage") == "synthesis":
        out["error"] = row.get("synthesis_error")
    elif row["status"] == "failed":
        out.update(stood_up=False, stage="robot")
    return out


def _pct(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


def _spread(values: list[float]) -> dict:
    """Median, p90 and max of a list (None when empty)."""
    return {"median": _pct(values, 50), "p90": _pct(values, 90), "max": max(values) if values else None}


def aggregate(rows: list[dict]) -> dict:
    """The population's figures: success rate, time-scale and duration-ratio spread, COM figures, torque, wall."""
    def col(key, only=None):
        return [r[key] for r in rows if r.get(key) is not None and (only is None or only(r))]
    stood = [r for r in rows if r.get("stood_up")]
    refused = sum(r.get("stage") == "synthesis" for r in rows)
    n = len(rows) - refused                       # the cases with a demonstration: the robot's population
    fast_enough = [r for r in stood if r.get("time_scale") is not None and r["time_scale"] <= TARGET_TIME_SCALE]
    ratio_ok = [r for r in stood if r.get("duration_ratio") is not None and r["duration_ratio"] <= TARGET_TIME_SCALE]
    return {
        "cases": len(rows), "not_synthesised": refused, "synthesised": n, "stood_up": len(stood),
        "success_rate": len(stood) / n if n else None, "errors": sum(r.get("stage") == "robot" for r in rows),
        "bodies_redrawn": sum(r.get("synth_seed") not in (None, r["case"]["seed"]) for r in rows),
        "by_style": {s: f"{sum(r['stood_up'] for r in rows if r['case']['style'] == s)}/"
                        f"{sum(r['case']['style'] == s and r.get('stage') != 'synthesis' for r in rows)}"
                     for s in STYLES
                     if any(r["case"]["style"] == s for r in rows)},
        "time_scale": _spread(col("time_scale")), "duration_ratio": _spread(col("duration_ratio")),
        "share_stood_time_scale_le_1_5": len(fast_enough) / n if n else None,
        "share_stood_duration_ratio_le_1_5": len(ratio_ok) / n if n else None,
        "com_tracking_rms_m": _spread(col("com_tracking_rms_m", lambda r: r.get("stood_up"))),
        # the end posture: the robot's pelvis over its straight stance; its knees against the human's [deg]
        "final_pelvis_height_ratio": _spread(col("final_pelvis_height_ratio")),
        "share_pelvis_ge_95": _share_ge(col("final_pelvis_height_ratio"), 0.95),
        "final_knee_gap_deg": _spread([abs(r["final_knee_flexion_deg_robot"] - r["final_knee_flexion_deg_human"])
                                       for r in rows if r.get("final_knee_flexion_deg_human") is not None
                                       and r.get("final_knee_flexion_deg_robot") is not None]),
        "share_knees_match": _share_ge([float(v) for v in col("standing_knees_match")], 1.0),
        "posture_rms_deg": {j: _spread(v) for j, v in _posture(rows).items()},
        "marker_rms_mm": _spread(col("marker_rms_mm")),
        "com_deviation_rms_m": _spread(col("com_deviation_rms_m")),
        "com_deviation_max_m": _spread(col("com_deviation_max_m")),
        "torque_demand_peak_ratio": _spread(col("torque_demand_peak_ratio")),
        "torque_saturated_cases": sum((r.get("torque_saturated_share") or 0) > 0 for r in rows),
        "torque_saturated_share": _spread(col("torque_saturated_share")),
        "wall_s": {**_spread(col("wall_s")), "total": float(sum(col("wall_s")))},
        # torque control's QP time per step, each case's p99 (wall; CPU, a shared host's steal left out) [ms]
        "controller_qp_ms_p99": _spread(col("controller_qp_ms_p99")),
        "controller_qp_cpu_ms_p99": _spread(col("controller_qp_cpu_ms_p99")),
        "share_qp_p99_le_1_ms": _share(col("controller_qp_ms_p99"), QP_TARGET_MS),
        # the whole-rise optimisation: the plans played, its wall time a case [s] and per second of the human's rise
        "optimised_plans_played": sum(r.get("plan") == "whole" for r in rows),
        # ... of which a solution only within its relaxed COM tolerance (WholeRiseConfig.com_relaxed_tolerance_m)
        "optimised_plans_relaxed": sum(r.get("plan") == "whole" and r.get("whole_rise_com_relaxed") in (True, 1)
                                       for r in rows),
        "whole_rise_solve_s": _spread(col("whole_rise_solve_s")),
        "whole_rise_solve_per_rise": _spread([r["whole_rise_solve_s"] / r["human_rise_s"] for r in rows
                                              if r.get("whole_rise_solve_s") is not None and r.get("human_rise_s")]),
    }


def _posture(rows: list[dict]) -> dict[str, list[float]]:
    """Each joint's posture RMS [deg] over the cases that have one (a table read back holds it as JSON text)."""
    out: dict[str, list[float]] = {}
    for r in rows:
        rms = r.get("posture_rms_deg")
        for joint, value in (json.loads(rms) if isinstance(rms, str) else rms or {}).items():
            out.setdefault(joint, []).append(value)
    return out


def _share_ge(values: list[float], bound: float) -> float | None:
    """The share of ``values`` at or above ``bound`` (None without any)."""
    return float(np.mean(np.asarray(values) >= bound)) if values else None


def _share(values: list[float], bound: float) -> float | None:
    return sum(v <= bound for v in values) / len(values) if values else None


def _fmt(v, scale: float = 1.0, spec: str = ".2f") -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v * scale, spec)


def case_line(r: dict) -> str:
    """One table row: the body, the outcome, the figures."""
    c = r["case"]
    outcome = ("NOSYN" if r.get("stage") == "synthesis" else "ERROR") if r.get("error") else \
        ("stood" if r["stood_up"] else "FELL")
    redrawn = "*" if r.get("synth_seed") not in (None, c["seed"]) else " "
    return (f"{c['index']:>3} {c['style']:<7}{redrawn} {c['height_m']:5.2f} {c['mass_kg']:5.1f} {c['sex'][0]} "
            f"{c['seat_height_m']:5.3f} {c['rise_s']:4.2f} | {outcome:<5} {_fmt(r.get('time_scale')):>5} "
            f"{_fmt(r.get('duration_ratio')):>5} {_fmt(r.get('com_deviation_rms_m'), 100, '.1f'):>5} "
            f"{_fmt(r.get('com_deviation_max_m'), 100, '.1f'):>5} {_fmt(r.get('com_tracking_rms_m'), 100, '.2f'):>5} "
            f"{_fmt(r.get('torque_demand_peak_ratio')):>5} {_fmt(r.get('torque_saturated_share'), 100, '.0f'):>5} "
            f"{_fmt(r.get('final_pelvis_height_ratio'), 100, '.0f'):>4} "
            f"{_fmt(r.get('final_knee_flexion_deg_robot'), 1, '.0f'):>4}/"
            f"{_fmt(r.get('final_knee_flexion_deg_human'), 1, '.0f'):<3} {r['wall_s']:6.1f}"
            + (f"  {r['error'][:80]}" if r.get("error") else ""))


TABLE_HEAD = ("  # style    H [m] m[kg] s seat  rise | out   scale ratio dvRMS dvMax trkRMS tauPk  sat% pel% knees   "
              "wall_s\n                                      | COM in cm (dv: plan vs mapped human, forward); tauPk: "
              "demand / limit; sat%: commands clamped; pel%: final pelvis / straight stance; knees: robot/human [deg]")


def summary_text(agg: dict) -> str:
    """The aggregate in a few lines."""
    def s(d, scale=1.0, spec=".2f"):
        return f"median {_fmt(d['median'], scale, spec)}, p90 {_fmt(d['p90'], scale, spec)}, " \
               f"max {_fmt(d['max'], scale, spec)}"
    return "\n".join([
        f"stood up {agg['stood_up']}/{agg['synthesised']} ({_fmt(agg['success_rate'], 100, '.0f')} %); by style "
        + ", ".join(f"{k} {v}" for k, v in agg["by_style"].items()) + f"; robot-side errors {agg['errors']}",
        f"of {agg['cases']} bodies drawn: {agg['not_synthesised']} refused by the synthesiser at every seed, "
        f"{agg['bodies_redrawn']} redrawn (the first seed refused)",
        f"time_scale      {s(agg['time_scale'])}",
        f"duration_ratio  {s(agg['duration_ratio'])}",
        f"stood with time_scale <= 1.5: {_fmt(agg['share_stood_time_scale_le_1_5'], 100, '.0f')} %; with "
        f"duration_ratio <= 1.5: {_fmt(agg['share_stood_duration_ratio_le_1_5'], 100, '.0f')} % (target 90 %)",
        f"COM tracking RMS (stood) [cm]  {s(agg['com_tracking_rms_m'], 100)}",
        f"end posture: pelvis / straight stance [%]  {s(agg['final_pelvis_height_ratio'], 100, '.0f')} (at >= 95 %: "
        f"{_fmt(agg['share_pelvis_ge_95'], 100, '.0f')} % of cases); |robot - human knee| [deg]  "
        f"{s(agg['final_knee_gap_deg'], 1, '.0f')}",
        f"knees within {KNEE_TOLERANCE_DEG:g} deg of the human's at the end: "
        f"{_fmt(agg['share_knees_match'], 100, '.0f')} % of cases",
        "posture RMS over the rise, robot - human [deg]: " + "; ".join(
            f"{j} {s(v, 1, '.0f')}" for j, v in agg["posture_rms_deg"].items()),
        f"marker RMS, plan vs mapped human [mm]  {s(agg['marker_rms_mm'], 1, '.0f')}",
        f"COM plan vs mapped human, RMS [cm]  {s(agg['com_deviation_rms_m'], 100)}",
        f"peak torque demand / limit  {s(agg['torque_demand_peak_ratio'])}; a joint clamped at its limit in "
        f"{agg['torque_saturated_cases']} cases; share of commands clamped "
        f"{s(agg['torque_saturated_share'], 100, '.0f')} %",
        f"wall per case [s]  {s(agg['wall_s'], 1, '.0f')}; total {agg['wall_s']['total']:.0f} s"]
        + ([f"optimised plan played in {agg['optimised_plans_played']} cases ({agg['optimised_plans_relaxed']} "
            f"within the relaxed COM tolerance); optimisation a case [s] "
            f"{s(agg['whole_rise_solve_s'], 1, '.1f')}, per second of the human's rise "
            f"{s(agg['whole_rise_solve_per_rise'], 1, '.1f')} (real time: 1)"]
           if agg.get("whole_rise_solve_s", {}).get("median") is not None else [])
        + ([f"whole-body QP p99 per step, per case [ms]: wall {s(agg['controller_qp_ms_p99'])} (at <= {QP_TARGET_MS:g} "
            f"ms: {_fmt(agg['share_qp_p99_le_1_ms'], 100, '.0f')} %); CPU {s(agg['controller_qp_cpu_ms_p99'])}"]
           if agg.get("controller_qp_ms_p99", {}).get("median") is not None else []))


def resolve_params(args: argparse.Namespace) -> tuple[Path | None, str]:
    """The robot parameters to plan and control with, and where they came from."""
    if args.cad:
        return None, "CAD (--cad)"
    if args.params is not None:
        return args.params, f"identified: {args.params}"
    demo = demo_params(args.robot, project_folder())
    if demo.exists():
        return demo, f"identified: {demo.relative_to(project_folder())} (make demo)"
    robot_identification(args.out / "robot", 88, args.robot)        # as make demo does
    return args.out / "robot" / "identified_full.yaml", f"identified here: {args.out / 'robot'}"


def run_population(cases: list[Case], out: Path, params: Path | None, jobs: int,
                   controller: str = DEFAULT_CONTROLLER, robot: str = DEFAULT_ROBOT,
                   address: str | None = None, plan: str = DEFAULT_PLAN) -> list[dict]:
    """Every case as a batch (:mod:`sit2stand.batch.engine`: ``jobs`` Ray workers here, or the cluster at
    ``address``; 1: this process); one line per case as it finishes; rows in case order."""
    setting = Setting(robot, "default", controller, str(params) if params else None, plan)
    print(TABLE_HEAD, flush=True)
    rows = run_jobs(standup_jobs([(c, setting) for c in cases]), out, address=address, workers=jobs, fresh=True,
                    on_row=lambda r: print(case_line(bench_row(r)), flush=True), label="bench-standup")
    return [bench_row(r) for r in rows]


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (see the module docstring); 0 unless a case raised."""
    parser = argparse.ArgumentParser(prog="sit2stand-bench-standup", description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=30, help="digital humans (default 30)")
    parser.add_argument("--seed", type=int, default=0, help="the population's RNG seed")
    parser.add_argument("--jobs", type=int, default=1, help="cases in parallel (Ray workers; 1: this process)")
    parser.add_argument("--address", help="a Ray cluster to run on (ray start --head ...); default: this machine")
    parser.add_argument("--only-style", choices=STYLES, help="every case in this style")
    parser.add_argument("--params", type=Path, help="identified parameters (default: make demo's)")
    parser.add_argument("--cad", action="store_true", help="plan and control with the CAD model")
    parser.add_argument("--controller", choices=CONTROLLERS, default=DEFAULT_CONTROLLER,
                        help="the simulated robot's: whole-body torque control (wbc, default), or joint PD with an "
                        "inverse-dynamics feed-forward (inverse_dynamics)")
    parser.add_argument("--marker-rate", type=float, default=100.0,
                        help="the digital humans' capture rate [Hz] (default 100; divides the plates' 1000 Hz)")
    parser.add_argument("--robot", default=DEFAULT_ROBOT, help="robot profile: talos (default), g1 or a file")
    parser.add_argument("--plan", choices=PLANS, default=DEFAULT_PLAN,
                        help="how each case is planned (sit2stand retarget --plan; default whole)")
    parser.add_argument("--out", type=Path, default=None, help="default: bench/results/standup (G1: standup_g1)")
    args = parser.parse_args(argv)
    args.out = args.out or project_folder() / (DEFAULT_OUT if args.robot == DEFAULT_ROBOT else
                                               DEFAULT_OUT.with_name(f"standup_{args.robot}"))
    cases = sample_population(args.cases, args.seed, (args.only_style,) if args.only_style else STYLES,
                              args.marker_rate)
    params, source = resolve_params(args)
    print(f"bench-standup: {len(cases)} digital humans (seed {args.seed}, captured at {args.marker_rate:g} Hz), "
          f"robot {args.robot}, default plant, parameters {source}, controller {args.controller}, plan {args.plan}",
          flush=True)
    t0 = time.monotonic()
    rows = run_population(cases, args.out, params, args.jobs, args.controller, args.robot, args.address, args.plan)
    agg = aggregate(rows)
    print("\n" + summary_text(agg))
    args.out.mkdir(parents=True, exist_ok=True)
    doc = {"robot": args.robot, "seed": args.seed, "marker_rate_hz": args.marker_rate, "parameters": source,
           "plant": "default", "plan": args.plan,
           "controller": args.controller,
           "jobs": args.jobs, "wall_s": round(time.monotonic() - t0, 1), "aggregate": agg, "cases": rows}
    write_result(args.out / "bench_standup.json", doc, "make bench-standup" + (
        f' BENCH_STANDUP_ARGS="--robot {args.robot}"' if args.robot != DEFAULT_ROBOT else ""))
    return 1 if agg["errors"] else 0


if __name__ == "__main__":
    sys.exit(main())
