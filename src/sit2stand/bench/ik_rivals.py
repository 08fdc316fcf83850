"""The rivals' side of `make bench-ik` (:mod:`sit2stand.bench.ik`): runs in ``.venv-ik``, where mink and pink are.

    python -m sit2stand.bench.ik_rivals PROBLEMS.pkl FIGURES.json [--rounds 1]

Each recorded frame is solved by every solver from the same start, in a rotating order, and timed from taking the
frame's targets to the answer (targets and costs set, kinematics updated, QPs built and solved, the configuration
integrated). Each answer is then scored alike with Pinocchio: the marker cost sum w |p - t|^2 [m^2] relative to
ours, the COM residual on the frame's axes and the soles' (6-D log) residual. Imports nothing of sit2stand but the
IK it measures.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import logging
import pickle
import sys
import time
from importlib.metadata import version

import mink
import mujoco
import numpy as np
import pink
import pinocchio as pin
from pink.limits import ConfigurationLimit as PinkConfigurationLimit

from sit2stand.retarget.ik import ComIk, MarkerTargets
from sit2stand.vectors import wxyz_from_xyzw, xyzw_from_wxyz

MODES = {"two_iterations": (2, 0.0), "converged": (20, 1e-6)}
"""Gauss-Newton iterations and the step norm that stops them: the retargeter's per-frame setting, and a
converged answer."""


def box(problem: dict, lo: np.ndarray, hi: np.ndarray, v_max: np.ndarray, dt: float) -> tuple[np.ndarray, ...]:
    """The joint limits intersected with the speed limits from the frame's start (the retargeter's ``q_prev``),
    over the joints' coordinates (nq - 7) [rad]."""
    q0 = problem["q0"][7:]
    return np.maximum(lo, q0 - v_max * dt), np.minimum(hi, q0 + v_max * dt)


class Ours:
    """sit2stand's :class:`ComIk` without its own extra rules (the problem the rivals can state too)."""

    name = "sit2stand"

    def __init__(self, s: dict) -> None:
        self.model = s["model"]
        self.ik = ComIk(self.model, [self.model.getFrameId(n) for n in s["soles"]], s["v_max"], s["dt"],
                        posture_weight=s["mu"], damping=s["damping"])
        self.fids = np.array([self.model.getFrameId(n) for n in s["markers"]])
        self.soles = [pin.SE3(X) for X in s["sole_targets"]]

    def solve(self, p: dict, iterations: int, tol: float) -> np.ndarray:
        use = p["weights"] > 0
        markers = MarkerTargets(self.fids[use], p["targets"][use], p["weights"][use])
        return self.ik.solve(p["q0"], markers, p["com"], self.soles, q_ref=p["q_ref"], com_axes=p["axes"],
                             q_prev=p["q0"], max_iterations=iterations, tol=tol).q


class _MinkCom(mink.ComTask):
    """mink's COM task on some axes only (the retargeter holds only x while seated)."""

    axes: list[int] = [0, 1, 2]

    def compute_error(self, configuration):
        return super().compute_error(configuration)[self.axes]

    def compute_jacobian(self, configuration):
        return super().compute_jacobian(configuration)[self.axes]


class _PinkCom(pink.tasks.ComTask):
    """pink's COM task on some axes only."""

    axes: list[int] = [0, 1, 2]

    def compute_error(self, configuration):
        return super().compute_error(configuration)[self.axes]

    def compute_jacobian(self, configuration):
        return super().compute_jacobian(configuration)[self.axes]


def _qpos(q: np.ndarray) -> np.ndarray:
    """Pinocchio's configuration as MuJoCo's qpos (the free joint's quaternion w first)."""
    return np.concatenate([q[:3], wxyz_from_xyzw(q[3:7]), q[7:]])


def _q(qpos: np.ndarray) -> np.ndarray:
    return np.concatenate([qpos[:3], xyzw_from_wxyz(qpos[3:7]), qpos[7:]])


class Mink:
    """mink 1.3.0 on the MJCF with a site per marker and sole: markers as position-only frame tasks, the soles and
    the COM as equality constraints, the posture task, the box as its configuration limit (gain 1)."""

    def __init__(self, s: dict, solver: str) -> None:
        self.name = f"mink_{solver}"
        self.solver, self.dt, self.damping = solver, s["dt"], s["damping"]
        model = mujoco.MjModel.from_xml_string(s["mjcf"])
        self.config = mink.Configuration(model)
        self.markers = [mink.FrameTask(s["site_prefix"] + n, "site", position_cost=0.0, orientation_cost=0.0)
                        for n in s["markers"]]
        self.com = _MinkCom(cost=1.0)
        self.posture = mink.PostureTask(model, cost=np.sqrt(s["mu"]))
        self.soles = []
        for name, X in zip(s["soles"], s["sole_targets"]):
            task = mink.FrameTask(s["site_prefix"] + name, "site", position_cost=1.0, orientation_cost=1.0)
            task.set_target(mink.SE3.from_matrix(X))
            self.soles.append(task)
        self.limit = mink.ConfigurationLimit(model, gain=1.0)
        self.lo, self.hi = self.limit.lower[7:].copy(), self.limit.upper[7:].copy()
        self.v_max = s["v_max"]

    def solve(self, p: dict, iterations: int, tol: float) -> np.ndarray:
        for task, target, weight in zip(self.markers, p["targets"], p["weights"]):
            task.set_position_cost(np.sqrt(weight))
            task.set_target(mink.SE3.from_translation(target))
        self.com.axes = list(p["axes"])
        self.com.set_target(p["com"])
        self.posture.set_target(_qpos(p["q_ref"]))
        self.limit.lower[7:], self.limit.upper[7:] = box(p, self.lo, self.hi, self.v_max, self.dt)
        self.config.update(_qpos(p["q0"]))
        for _ in range(iterations):
            v = mink.solve_ik(self.config, [*self.markers, self.posture], self.dt, self.solver, self.damping,
                              limits=[self.limit], constraints=[*self.soles, self.com])
            self.config.integrate_inplace(v, self.dt)
            if np.linalg.norm(v) * self.dt < tol:
                break
        return _q(self.config.q)


class Pink:
    """pink 4.4.0 on the Pinocchio model: the same tasks as :class:`Mink`; the box as the model's position limits
    under its configuration limit (gain 1)."""

    def __init__(self, s: dict, solver: str) -> None:
        self.name = f"pink_{solver}"
        self.solver, self.dt, self.damping = solver, s["dt"], s["damping"]
        self.model = s["model"].copy()
        self.model.names[1] = "root_joint"       # pink finds a floating base by this name only
        self.lo, self.hi = self.model.lowerPositionLimit[7:].copy(), self.model.upperPositionLimit[7:].copy()
        self.config = pink.Configuration(self.model, self.model.createData(), pin.neutral(self.model))
        self.markers = [pink.FrameTask(n, position_cost=0.0, orientation_cost=0.0) for n in s["markers"]]
        self.com = _PinkCom(cost=1.0)
        self.posture = pink.PostureTask(cost=np.sqrt(s["mu"][6:]))
        self.soles = []
        for name, X in zip(s["soles"], s["sole_targets"]):
            task = pink.FrameTask(name, position_cost=1.0, orientation_cost=1.0)
            task.set_target(pin.SE3(X))
            self.soles.append(task)
        self.limit = PinkConfigurationLimit(self.model, config_limit_gain=1.0)
        self.v_max = s["v_max"]

    def solve(self, p: dict, iterations: int, tol: float) -> np.ndarray:
        for task, target, weight in zip(self.markers, p["targets"], p["weights"]):
            task.set_position_cost(np.sqrt(weight))
            task.set_target(pin.SE3(np.eye(3), target))
        self.com.axes = list(p["axes"])
        self.com.set_target(p["com"])
        self.posture.set_target(p["q_ref"])
        self.model.lowerPositionLimit[7:], self.model.upperPositionLimit[7:] = box(p, self.lo, self.hi, self.v_max,
                                                                                   self.dt)
        self.config.update(p["q0"])
        for _ in range(iterations):
            v = pink.solve_ik(self.config, [*self.markers, self.posture], self.dt, self.solver, self.damping,
                              safety_break=False, limits=[self.limit], constraints=[*self.soles, self.com])
            self.config.integrate_inplace(v, self.dt)
            if np.linalg.norm(v) * self.dt < tol:
                break
        return self.config.q.copy()


class Score:
    """Every answer scored alike on the Pinocchio model."""

    def __init__(self, s: dict) -> None:
        self.model = s["model"]
        self.data = self.model.createData()
        self.fids = [self.model.getFrameId(n) for n in s["markers"]]
        self.soles = [(self.model.getFrameId(n), pin.SE3(X)) for n, X in zip(s["soles"], s["sole_targets"])]

    def __call__(self, p: dict, q: np.ndarray) -> tuple[float, float, float]:
        """Marker cost [m^2], COM residual on the frame's axes [m], largest sole residual (6-D log)."""
        model, data = self.model, self.data
        pin.framesForwardKinematics(model, data, q)
        P = np.array([data.oMf[f].translation for f in self.fids])
        cost = float(np.sum(p["weights"] * np.sum((P - p["targets"]) ** 2, axis=1)))
        com = pin.centerOfMass(model, data, q, False)
        com_err = float(np.linalg.norm((com - p["com"])[list(p["axes"])]))
        sole = max(float(np.linalg.norm(pin.log6(X.actInv(data.oMf[f])).vector)) for f, X in self.soles)
        return cost, com_err, sole


def measure(s: dict, rounds: int) -> dict:
    """Per mode and solver: time per frame (p50, p99 [ms]) and the agreement of the answers with ours. A first pass,
    untimed, pays every solver's one-off costs (QP workspaces, per-marker-set layouts, first calls); then two orders:
    interleaved (each frame by every solver in turn, the order rotating: caches cold for all alike) and, suffixed
    ``_blocked``, each solver over all frames before the next (its caches warm, as in a loop that only solves)."""
    solvers = [Ours(s), Mink(s, "daqp"), Pink(s, "daqp"), Mink(s, "proxqp"), Pink(s, "proxqp")]
    score = Score(s)
    out = {}
    for mode, (iterations, tol) in MODES.items():
        for blocked in (False, True):
            ms = {x.name: [] for x in solvers}
            scores = {x.name: [] for x in solvers}
            failed = {x.name: 0 for x in solvers}
            for x, _, p in _order(solvers, s["problems"], 0, blocked):     # untimed: each solver's one-off setup
                with contextlib.suppress(mink.NoSolutionFound, pink.exceptions.PinkError):
                    x.solve(p, iterations, tol)
            for r in range(rounds):
                for x, k, p in _order(solvers, s["problems"], r, blocked):
                    t0 = time.perf_counter()
                    try:
                        q = x.solve(p, iterations, tol)
                    except (mink.NoSolutionFound, pink.exceptions.PinkError):   # counted, not timed
                        failed[x.name] += 1
                        continue
                    ms[x.name].append((time.perf_counter() - t0) * 1e3)
                    if r == 0:
                        scores[x.name].append((k, *score(p, q)))
            out[mode + ("_blocked" if blocked else "")] = _figures(ms, scores, failed)
        print(f"  {mode}: done", file=sys.stderr, flush=True)
    return out


def _order(solvers: list, problems: list[dict], round_: int, blocked: bool):
    """(solver, frame index, problem) in the order of one round."""
    if blocked:
        return [(x, k, p) for x in solvers for k, p in enumerate(problems)]
    out = []
    for k, p in enumerate(problems):
        turn = (k + round_) % len(solvers)
        out += [(x, k, p) for x in solvers[turn:] + solvers[:turn]]
    return out


def _figures(ms: dict, scores: dict, failed: dict) -> dict:
    ours = {k: c for k, c, _, _ in scores["sit2stand"]}
    out = {}
    for name, times in ms.items():
        rows = np.array(scores[name]) if scores[name] else np.zeros((0, 4))
        rel = np.array([(c - ours[int(k)]) / max(ours[int(k)], 1e-12) for k, c, _, _ in rows if int(k) in ours])
        out[name] = {"ms_p50": round(float(np.percentile(times, 50)), 4),
                     "ms_p99": round(float(np.percentile(times, 99)), 4),
                     "marker_cost_rel_p50": round(float(np.median(rel)), 5) if len(rel) else None,
                     "marker_cost_rel_max": round(float(np.max(np.abs(rel))), 5) if len(rel) else None,
                     "com_error_max_mm": round(float(rows[:, 2].max()) * 1e3, 4) if len(rows) else None,
                     "sole_error_max": float(rows[:, 3].max()) if len(rows) else None,
                     "failed_frames": failed[name]}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("problems")
    parser.add_argument("figures")
    parser.add_argument("--rounds", type=int, default=1)
    args = parser.parse_args(argv)
    with open(args.problems, "rb") as f:
        s = pickle.load(f)
    logging.disable(logging.WARNING)       # pink's "out of limits" at a start on the speed box's edge
    with contextlib.redirect_stdout(io.StringIO()):
        modes = measure(s, args.rounds)
    versions = {n: version(n) for n in ("mink", "pin-pink", "daqp", "qpsolvers", "pin", "mujoco", "proxsuite")}
    with open(args.figures, "w") as f:
        json.dump({"versions": versions, "modes": modes}, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
