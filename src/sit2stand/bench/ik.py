"""`make bench-ik`: the per-frame IK against mink and pink on identical problems, in a venv of their own.

    python -m sit2stand.bench.ik [--bag bags/natural] [--robot talos] [--rounds 1] [--out bench/results/ik.json]

The problems come from a retargeting run of ``--bag`` (CAD parameters): every frame's call of the COM-hard IK
(:class:`~sit2stand.retarget.ik.ComIk`) is recorded, its start pose, marker targets and weights, COM target and
axes, posture reference. The three solvers then solve the same problem from the same start: markers soft, the
posture prior and the Levenberg-Marquardt damping of the retargeter; the COM on the frame's axes and both soles
(6-D) as equalities; the joint limits intersected with the speed limits from the previous frame as a box. The
retargeter's own extra rules (stops that hold, trunk lift-off, base holds, knee targets, angular momentum) are left
out: mink and pink have no counterpart.

mink and pin-pink (DAQP, and ProxQP through qpsolvers), pinned in sit2stand's ``bench-ik`` extra, go into
``.venv-ik/`` beside ``.venv/`` the first time, with the same pin, mujoco, proxsuite, daqp and numpy as sit2stand's.
:mod:`sit2stand.bench.ik_rivals` runs there, frame by frame, the solvers interleaved in a rotating order so that
the machine's state weighs on all alike, and writes its figures back; this module turns them into
``bench/results/ik.json``: per solver ``ms_p50``, ``ms_p99`` and their ratios to ours (``ratio_p50``,
``ratio_p99``: theirs over ours), for 2 Gauss-Newton iterations (what the retargeter runs per frame) and converged
(up to 20 iterations, step below 1e-6), with the agreement of the answers (marker cost, COM and sole residuals,
evaluated alike for all). BLAS runs on one thread there (:data:`ONE_BLAS_THREAD`).
"""

from __future__ import annotations

import argparse
import importlib.metadata as metadata
import json
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin

from . import own_venv, project_folder, write_result
from ..human.offline import read_trial
from ..retarget.robot import robot_setup
from ..retarget.stream import Retargeter
from ..robot.model import DEFAULT_ROBOT, PlantConfig, compiled_robot
from ..vectors import wxyz_from_xyzw

RIVALS_EXTRA = "bench-ik"
"""sit2stand's optional dependencies that name the rivals and their pins (``src/pyproject.toml``)."""
SHARED = ("pin", "mujoco", "proxsuite", "daqp", "numpy", "pyyaml")
"""Installed in ``.venv-ik`` at sit2stand's own versions: the same Pinocchio, MuJoCo and QP binaries on both sides."""
ONE_BLAS_THREAD = {"OPENBLAS_NUM_THREADS": "1"}
"""The solvers' process runs BLAS on one thread: their products are small, and OpenBLAS's threads, woken by one
solver's larger product, spin on the host's other core and slow the next solver (mink's p99 in its own pass was
5 ms against 1.3 ms with one thread, on 2 cores)."""
TARGET_RATIO_P50 = 10.0     # mink (DAQP) p50 over ours: the target (floor 5)
TARGET_RATIO_P99 = 5.0


def ik_python() -> tuple[Path | None, str]:
    """The Python of ``.venv-ik`` with mink and pink importable, made on demand; or None and why not."""
    rivals = [r.split(";")[0].strip() for r in metadata.requires("sit2stand") or ()
              if f'extra == "{RIVALS_EXTRA}"' in r]
    if not rivals:
        return None, f"sit2stand's metadata has no {RIVALS_EXTRA!r} extra: reinstall it (make setup)"
    return own_venv(project_folder() / ".venv-ik",
                    [*rivals, *(f"{name}=={metadata.version(name)}" for name in SHARED)])


def _see_sit2stand(python: Path) -> None:
    """Make this sit2stand importable in the venv of ``python`` (a path file after its own site-packages)."""
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    (Path(site) / "sit2stand-bench.pth").write_text(str(Path(__file__).resolve().parents[2]) + "\n")


def recorded_problems(bag: Path, robot: str) -> tuple[Retargeter, list[int], list[dict]]:
    """The retargeter after a run of ``bag`` (CAD parameters), its marker frames (ids), and each frame's IK problem:
    start pose ``q0`` (Pinocchio order), marker ``targets`` (M, 3) [m] and ``weights`` (M,) over those frames (0:
    not in that frame), ``com`` target [m] and its ``axes``, posture reference ``q_ref``."""
    setup = robot_setup(robot=robot)
    trial = read_trial(bag)
    t, com = trial.truth
    com_h = np.stack([np.interp(trial.marker_t_s, t, com[:, i]) for i in range(3)], axis=1)
    rt = Retargeter(setup)
    rt.calibrate(trial.marker_names, trial.positions[0], trial.valid[0], com_h[0])
    fids = sorted(set(rt.markers.frames.values()))
    column = {f: i for i, f in enumerate(fids)}
    problems: list[dict] = []
    solve = rt.ik.solve

    def recording_solve(q0, markers, com_target, sole_targets, q_ref=None, com_axes=(0, 1, 2), **kw):
        targets, weights = np.zeros((len(fids), 3)), np.zeros(len(fids))
        for fid, target, weight in markers:
            targets[column[fid]], weights[column[fid]] = target, weight
        problems.append({"q0": q0.copy(), "targets": targets, "weights": weights, "com": np.array(com_target),
                         "axes": tuple(com_axes), "q_ref": (q0 if q_ref is None else q_ref).copy()})
        return solve(q0, markers, com_target, sole_targets, q_ref=q_ref, com_axes=com_axes, **kw)

    rt.ik.solve = recording_solve
    chair = next((p for p in trial.plates if p.name == "chair"), None)
    fz = None if chair is None else np.interp(trial.marker_t_s, chair.t_s, chair.force_n[:, 2])
    for k, tk in enumerate(trial.marker_t_s):
        rt.step(float(tk), trial.positions[k], trial.valid[k], com_h[k], None if fz is None else float(fz[k]))
    rt.ik.solve = solve
    return rt, fids, problems


SITE_PREFIX = "ik_"
"""A frame's site is named after it with this prefix (the MJCF has sites of its own, ``sole_left`` among them)."""


def frame_sites(model: pin.Model, frame_ids: list[int], robot: str) -> str:
    """The robot's MJCF (the one the Pinocchio model is built from) with a site at each of ``frame_ids``, named
    after the frame (:data:`SITE_PREFIX`): mink's tasks act on sites."""
    cfg = PlantConfig(robot=robot)
    _, xml = compiled_robot(cfg, plant=False)
    spec = mujoco.MjSpec.from_string(xml)
    probe = spec.compile()
    mj = mujoco.MjData(probe)
    q = pin.neutral(model)
    mj.qpos[:] = q
    mj.qpos[3:7] = wxyz_from_xyzw(q[3:7])
    mujoco.mj_kinematics(probe, mj)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    for fid in frame_ids:
        frame = model.frames[fid]
        jid = frame.parentJoint
        body = int(probe.joint(model.names[jid]).bodyid[0])
        X_body = pin.SE3(mj.xmat[body].reshape(3, 3), mj.xpos[body].copy())
        local = X_body.actInv(data.oMf[fid])
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, local.rotation.ravel())
        spec.body(probe.body(body).name).add_site(name=SITE_PREFIX + frame.name, pos=local.translation, quat=quat)
    return spec.to_xml()


def picklable(model: pin.Model) -> pin.Model:
    """A copy of ``model`` whose infinite limits are +-1e300: Pinocchio 4.0's text archive writes ``inf`` but cannot
    read it back ("input stream error")."""
    out = pin.Model(model)
    for name in dir(out):
        value = getattr(out, name)
        if name.endswith("Limit") and isinstance(value, np.ndarray) and np.isinf(value).any():
            setattr(out, name, np.nan_to_num(value, posinf=1e300, neginf=-1e300))
    return out


def problem_file(rt: Retargeter, fids: list[int], problems: list[dict], robot: str, out: Path) -> None:
    """Everything the rival solvers' process needs, pickled: the model with its marker frames, the MJCF with the
    matching sites, the soles, the retargeter's weights, limits and damping, and the problems."""
    model, ik = rt.model, rt.ik
    soles = [model.frames[f].name for f in rt.robot.sole_frames]
    payload = {"model": picklable(model), "mjcf": frame_sites(model, fids + list(rt.robot.sole_frames), robot),
               "markers": [model.frames[f].name for f in fids], "soles": soles, "site_prefix": SITE_PREFIX,
               "sole_targets": [X.homogeneous for X in rt.robot.sole_targets], "mu": ik.mu, "v_max": ik.box.v_max,
               "dt": ik.dt, "damping": ik.damping, "problems": problems}
    out.write_bytes(pickle.dumps(payload))


def ratios(figures: dict) -> dict:
    """Per mode and solver: ``ms_p50``, ``ms_p99`` and theirs over ours (``ratio_p50``, ``ratio_p99``)."""
    out = {}
    for mode, solvers in figures.items():
        ours = solvers["sit2stand"]
        out[mode] = {name: {**s, "ratio_p50": round(s["ms_p50"] / ours["ms_p50"], 2),
                            "ratio_p99": round(s["ms_p99"] / ours["ms_p99"], 2)} for name, s in solvers.items()}
    return out


def print_table(result: dict) -> None:
    for mode, solvers in result["modes"].items():
        print(f"\n{mode}: {result['frames']} frames")
        print(f"  {'solver':<16} {'p50 ms':>8} {'p99 ms':>8} {'x p50':>6} {'x p99':>6} {'cost rel.':>10} "
              f"{'COM err mm':>10}")
        for name, s in solvers.items():
            print(f"  {name:<16} {s['ms_p50']:>8.3f} {s['ms_p99']:>8.3f} {s['ratio_p50']:>6.2f} "
                  f"{s['ratio_p99']:>6.2f} {s['marker_cost_rel_p50']:>+10.4f} {s['com_error_max_mm']:>10.3f}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bag", type=Path, default=None, help="demonstration (default: bags/natural)")
    parser.add_argument("--robot", default=DEFAULT_ROBOT)
    parser.add_argument("--rounds", type=int, default=1, help="passes over the frames (timings pooled)")
    parser.add_argument("--out", type=Path, default=Path("bench/results/ik.json"))
    args = parser.parse_args(argv)
    bag = args.bag or project_folder() / "bags" / "natural"
    python, why = ik_python()
    if python is None:
        print(f"bench-ik: {why}", file=sys.stderr)
        return 1
    _see_sit2stand(python)
    print(f"recording the IK problems of {bag} ({args.robot}) ...", flush=True)
    rt, fids, problems = recorded_problems(bag, args.robot)
    with tempfile.TemporaryDirectory() as tmp:
        payload, figures = Path(tmp) / "problems.pkl", Path(tmp) / "figures.json"
        problem_file(rt, fids, problems, args.robot, payload)
        done = subprocess.run([str(python), "-m", "sit2stand.bench.ik_rivals", str(payload), str(figures),
                               "--rounds", str(args.rounds)], env={**os.environ, **ONE_BLAS_THREAD})
        if done.returncode != 0 or not figures.is_file():
            print("bench-ik: the rivals' process failed", file=sys.stderr)
            return 1
        measured = json.loads(figures.read_text())
    result = {"bag": str(bag), "robot": args.robot, "frames": len(problems), "rounds": args.rounds,
              "versions": measured["versions"], "modes": ratios(measured["modes"]),
              "targets": {"ratio_p50": TARGET_RATIO_P50, "ratio_p99": TARGET_RATIO_P99}}
    print_table(result)
    write_result(args.out, result, "make bench-ik")
    return 0


if __name__ == "__main__":
    sys.exit(main())
