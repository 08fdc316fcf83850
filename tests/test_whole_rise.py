"""sit2stand.retarget.whole_rise: the rise optimised as one problem (Crocoddyl: contacts, cones, torque limits), at
the human's timing unless it has no solution there."""

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml

from sit2stand.cli import main as sit2stand
from sit2stand.commands.robot import DEFAULT_PLAN as CLI_DEFAULT_PLAN
from sit2stand.commands.robot import PLAN_CHOICES as CLI_PLANS
from sit2stand.errors import InputError
from sit2stand.io.bag import BagReader
from sit2stand.io.topics import ROBOT_JOINT_COMMAND_TOPIC
from sit2stand.retarget import offline
from sit2stand.robot.model import PlantConfig, controller_model
from sit2stand.retarget.robot import robot_model
from sit2stand.retarget.whole_rise import (RisePlan, SolveEnd, WholeRise, WholeRiseConfig, WholeRiseError,
                                           WholeRiseProblem)

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def natural(tmp_path_factory):
    """``sit2stand retarget bags/natural --plan whole`` (the plan only): its summary and folder."""
    out = tmp_path_factory.mktemp("whole_rise") / "rt"
    return offline.run(ROOT / "bags" / "natural", out, plan="whole"), out


def test_the_natural_rise_has_a_solution_at_the_humans_timing_and_the_shorter_plan_is_played(natural):
    summary, out = natural
    assert summary["whole_rise_tries"] == [[1.0, True]]
    # the optimised rise keeps the mapped human COM (the IK's) within the tolerance, its COP inside the soles
    assert summary["whole_rise_com_error_rms_m"] < 0.01 and summary["whole_rise_com_error_max_m"] <= 0.03
    assert summary["whole_rise_cop_margin_min_m"] >= 0.015
    # the problem spans the rise: the still seated start (0.74 s) and standing end (0.7 s) keep the per-frame poses
    first, last = summary["whole_rise_span_frames"]
    assert 40 < first < summary["human_seat_off_frame"] - 40 and 40 < summary["frames"] - 1 - last
    # both plans checked by the player; the one that plays shorter is played, and its commands are the bag's
    ratios = {"whole": summary["plan_ratio_whole"], "frames": summary["plan_ratio_frames"]}
    assert summary["plan"] == min(ratios, key=lambda p: (ratios[p], p != "whole"))
    assert summary["time_scale"] == pytest.approx(ratios[summary["plan"]], abs=1e-9) and summary["time_scale"] < 1.15
    with BagReader(out / "retarget") as bag:
        commands = bag.read(ROBOT_JOINT_COMMAND_TOPIC)
    assert len(commands) == summary["commands"]


def test_with_identified_parameters_the_optimised_torques_are_the_plans_torque_check(natural, tmp_path, monkeypatch):
    """The optimised torques are in their limits by construction. With CAD parameters the player checks them again
    (the contact wrench split by least squares: a margin for what the model does not know); with identified ones the
    optimisation's model is the robot's, and its torques are the check. A 1.1 s rise of a robot whose trunk was
    identified 30 % heavier than CAD's: the same solution at the human's timing plays slower when the player checks it
    again (1.003 against 1.009 on an AMD EPYC host, 1.01 against 1.04 on an earlier one: the solver's last digits,
    and so the margin, differ between CPUs)."""
    assert natural[0]["whole_rise_torque_check"] == "player"                   # CAD parameters
    bag = tmp_path / "brisk"
    assert sit2stand(["synth-human", "--duration", "1.1", "--out", str(bag)]) == 0
    model, _, _ = robot_model(robot="talos")
    trunk = model.inertias[model.getJointId("torso_2_joint")]
    params = tmp_path / "identified_full.yaml"
    params.write_text(yaml.safe_dump({"robot": "talos", "model": "full", "links": {
        "torso_2_joint": {"mass": 1.3 * float(trunk.mass), "com": [float(c) for c in trunk.lever]}}}))
    trusted = offline.run(bag, tmp_path / "trusted", params=params, plan="whole")
    optimised_player = offline.optimised_player
    monkeypatch.setattr(offline, "optimised_player", lambda *a, **k: optimised_player(*a, **{**k, "identified": False}))
    checked = offline.run(bag, tmp_path / "checked", params=params, plan="whole")
    assert trusted["whole_rise_torque_check"] == "optimisation" and checked["whole_rise_torque_check"] == "player"
    assert trusted["whole_rise_tries"] == checked["whole_rise_tries"] == [[1.0, True]]
    assert trusted["plan"] == "whole" and trusted["time_scale"] < 1.02
    assert checked["plan_ratio_whole"] > trusted["time_scale"]
    assert checked["time_scale_peak"] > trusted["time_scale_peak"] + 0.05     # the torque check stretches its frames


def test_a_rise_too_fast_for_the_motors_is_slowed_by_the_least_step_that_has_a_solution(tmp_path, monkeypatch):
    """A 0.8 s rise (the natural style's 1.6 s, twice as fast) has no solution at the human's timing on TALOS: each
    try is a ``scale_step`` slower, and the first with a solution is the result. ``sit2stand retarget`` stops trying
    at the per-frame plan's played ratio (1.15 here): an optimised plan found slower would not be played; the try at
    1.0, its COM within ``com_relaxed_tolerance_m`` of the plan's, is then the result."""
    bag = tmp_path / "fast"
    assert sit2stand(["synth-human", "--duration", "0.8", "--out", str(bag)]) == 0
    config, lines, seen = WholeRiseConfig(scale_step=0.25, max_time_scale=2.0), [], {}
    optimised_player = offline.optimised_player

    def remember(model, frames, player, **kw):
        seen.update(model=model, frames=frames, player=player)
        return optimised_player(model, frames, player, **kw)
    monkeypatch.setattr(offline, "optimised_player", remember)
    summary = offline.run(bag, tmp_path / "rt", plan="whole", whole_rise=config, progress=lines.append)
    assert summary["whole_rise_tries"] == [[1.0, False]]
    assert summary["whole_rise_com_relaxed"] and summary["whole_rise_time_scale"] == 1.0
    assert 1.0 < summary["plan_ratio_frames"] < 1.25
    # the same problem with no such bound: 1.25 has a solution
    lines.clear()
    plan = RisePlan.of_frames(seen["frames"], seen["player"].dt, seen["player"].smoothed())
    result = WholeRiseProblem(seen["model"], config).solve(plan, progress=lines.append)
    tries = result.tries
    assert tries[0] == (1.0, False) and tries[-1][1] and not any(ok for _, ok in tries[:-1])
    # each try is told as it starts and ends, with the cost every 10 iterations between
    starts = [line for line in lines if line.startswith("whole-rise optimisation: ")]
    assert [float(line.rsplit(" ", 1)[1]) for line in starts] == [s for s, _ in tries]
    ends = [line for line in lines if line.endswith(" solution")]
    assert [line.endswith(": a solution") for line in ends] == [ok for _, ok in tries]
    assert any(line.startswith("  iteration 10: cost ") for line in lines)
    assert result.time_scale == tries[-1][0] > summary["plan_ratio_frames"]
    # played no faster than the optimisation found a solution for
    played = seen["player"].like(planned_time_scale=result.time_scale)
    for q, f in zip(result.q, seen["frames"]):
        played.push(q, not f.seated)
    played.close()
    assert played.played_ratio() >= result.time_scale - 0.02


def short_plan(n: int = 40) -> tuple[pin.Model, RisePlan]:
    """TALOS and a plan of ``n`` frames 10 ms apart: the seated pose, seated for the first half, then on the feet."""
    model, q_seated, _ = robot_model(robot="talos")
    q = np.repeat(q_seated[None], n, axis=0)
    data = model.createData()
    com = np.array([pin.centerOfMass(model, data, x) for x in q])
    return model, RisePlan(q, com, np.arange(n) < n // 2, [[] for _ in range(n)], 0.01)


def test_the_problem_keeps_torques_in_their_limits_and_ends_at_the_ik_standing_pose(natural):
    """On a short plan (the IK's own poses: seated, then on the feet), every knot's torques inside the URDF limits,
    the last pose the IK's at rest."""
    model, plan = short_plan()
    q, n = plan.q, len(plan.q)
    result = WholeRiseProblem(model, WholeRiseConfig(iterations=30)).solve(plan)
    assert result.feasible and result.time_scale == 1.0
    assert result.knots == 21                                  # a knot per 20 ms
    assert np.all(np.abs(result.tau) <= model.effortLimit[6:] + 1e-9)
    assert np.abs(pin.difference(model, result.q[-1], q[-1])[6:]).max() < 0.02
    assert result.knot_t_s[-1] == pytest.approx((n - 1) * 0.01)


def test_a_solve_ends_once_its_solution_has_passed_its_checks_some_iterations_running():
    """Three passes running, the cost falling under 1 % over them, end it (a pass broken by a fail counts again from
    zero; a cost still falling faster goes on); without checks, a cost flat to 0.1 % over 5 iterations ends it."""
    class Solver:
        cost, isFeasible, th_stop = 10.0, True, 1e-6

    def run(end: SolveEnd, costs: list[float]) -> list[bool]:
        solver, ended = Solver(), []
        for c in costs:
            solver.cost = c
            end(solver)
            ended.append(solver.th_stop == np.inf)
        return ended

    verdicts = iter([True, False, True, True, True])
    assert run(SolveEnd(5, 1e-3, None, lambda s: next(verdicts), 3, 1e-2), [10.0] * 5) == [False] * 4 + [True]
    assert run(SolveEnd(5, 1e-3, None, lambda s: True, 3, 1e-2), [10.0, 9.0, 8.0, 7.9, 7.85]) == [False] * 5
    assert run(SolveEnd(5, 1e-3), [10.0] * 6) == [False] * 5 + [True]


def test_ending_at_the_checks_gives_a_solution_in_fewer_iterations():
    """The short seated-then-standing plan: ended once its solution passed its checks (5 iterations running, the
    cost flat to 1 %), against solved to the cost flat to 0.1 % or 150 iterations: both solutions, the first in less
    than half the iterations."""
    model, plan = short_plan()
    early = WholeRiseProblem(model, WholeRiseConfig()).solve(plan)
    late = WholeRiseProblem(model, WholeRiseConfig(passed_iterations=0)).solve(plan)
    assert early.feasible and late.feasible
    assert early.iterations < 0.5 * late.iterations


def test_where_no_try_keeps_the_plans_com_the_first_within_the_relaxed_tolerance_is_the_result():
    """No try has a solution within ``com_tolerance_m`` (0 here): the first whose COM stays within
    ``com_relaxed_tolerance_m`` and passes the other checks is the result, and says so; with none, none is."""
    model, plan = short_plan()
    strict = WholeRiseConfig(com_tolerance_m=0.0, scale_step=0.5, max_time_scale=1.5)
    result = WholeRiseProblem(model, strict).solve(plan)
    assert result.tries == [(1.0, False), (1.5, False)]
    assert result.feasible and result.com_relaxed and result.time_scale == 1.0 and len(result.tau) == 20
    assert result.summary()["whole_rise_com_relaxed"] is True
    assert result.com_error_max_m <= strict.com_relaxed_tolerance_m
    none = WholeRiseProblem(model, dataclasses.replace(strict, com_relaxed_tolerance_m=0.0)).solve(plan, 1.0, None, 1.0)
    assert none.tries == [(1.0, False)] and not none.feasible and not none.com_relaxed


def test_a_plan_longer_than_the_optimisation_is_given_is_played_frame_by_frame_and_says_so(tmp_path):
    summary = offline.run(ROOT / "bags" / "natural", tmp_path / "rt", plan="whole",
                          whole_rise=WholeRiseConfig(max_knots=50))
    assert summary["plan"] == "frames" and "whole_rise_time_scale" not in summary
    knots, rest = summary["whole_rise_skipped"].split(" knots, ")
    assert int(knots) > 50 and rest == "over the 50 the optimisation is given (max_knots)"
    assert summary["time_scale"] == pytest.approx(summary["plan_ratio_frames"], abs=1e-9)


def test_knots_are_spaced_in_time_whatever_the_capture_rate():
    config = WholeRiseConfig()
    assert [config.frames_per_knot(dt) for dt in (0.01, 0.005, 1 / 60, 0.05)] == [2, 4, 1, 1]


def test_the_cli_offers_the_plans_the_planner_has():
    assert CLI_PLANS == offline.PLANS and CLI_DEFAULT_PLAN == offline.DEFAULT_PLAN


def test_the_knots_solved_on_two_threads_give_the_same_rise(natural, tmp_path, capsys):
    """``retarget --oc-threads 2``: Crocoddyl's knots computed two at a time find the same solution (1.35x faster on
    two idle cores: docs/method.md); the sums' order moves the last digits, and with them the solve's end by an
    iteration or so."""
    one, _ = natural
    bag = str(ROOT / "bags" / "natural")
    assert sit2stand(["retarget", bag, "--oc-threads", "2", "--out", str(tmp_path / "rt")]) == 0
    two = json.loads((tmp_path / "rt" / "summary.json").read_text())
    assert (two["whole_rise_threads"], one["whole_rise_threads"]) == (2, 1)
    assert two["whole_rise_tries"] == one["whole_rise_tries"] == [[1.0, True]]
    assert abs(two["whole_rise_iterations"] - one["whole_rise_iterations"]) <= 5, (two, one)
    assert two["whole_rise_com_error_rms_m"] == pytest.approx(one["whole_rise_com_error_rms_m"], abs=5e-4)
    assert two["plan_ratio_whole"] == pytest.approx(one["plan_ratio_whole"], abs=0.01)
    with pytest.raises(SystemExit):
        sit2stand(["retarget", bag, "--oc-threads", "0", "--out", str(tmp_path / "no")])
    assert "argument --oc-threads: 0: at least 1" in capsys.readouterr().err


def test_retarget_gives_the_optimisation_the_cores_it_may_use_unless_told(monkeypatch):
    """A lone ``retarget`` optimises on every usable core (a batch gives each case one thread)."""
    seen = []
    monkeypatch.setattr(offline, "run", lambda *a, whole_rise=None, **k: seen.append(whole_rise.threads) or {})
    for extra in ([], ["--oc-threads", "3"]):
        assert sit2stand(["retarget", str(ROOT / "bags" / "natural"), "--out", "unused", *extra]) == 0
    assert seen == [len(os.sched_getaffinity(0)), 3]
    assert WholeRiseConfig().threads == 1


def test_the_package_asks_openmp_threads_to_sleep_when_idle_unless_the_environment_says_otherwise():
    """Spinning OpenMP threads slowed two solves side by side by 40 % (``scheduling.OPENMP_WAIT_POLICY``); the runtime
    reads the policy once, when Pinocchio loads it, so importing the package sets it first."""
    code = "import os, sit2stand, pinocchio; print(os.environ['OMP_WAIT_POLICY'])"
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    asked = [subprocess.run([sys.executable, "-c", code], env=e, capture_output=True, text=True, check=True).stdout
             for e in (env, {**env, "OMP_WAIT_POLICY": "ACTIVE"})]
    assert asked == ["PASSIVE\n", "ACTIVE\n"]


def test_bad_plans_and_models_are_refused(tmp_path):
    with pytest.raises(InputError, match="plan 'fast': one of whole, frames"):
        offline.run(ROOT / "bags" / "natural", tmp_path / "rt", plan="fast")
    bare = controller_model(PlantConfig.load(None, "talos"))        # the robot without the retargeter's seat frame
    with pytest.raises(WholeRiseError, match="no 'seat' frame"):
        WholeRiseProblem(bare)


def test_the_optimised_torques_are_given_at_the_human_time_each_command_plays():
    """Knots 10 and 12 frames in (10 ms frames), solved 2x slower: each interval's torques at its middle in human
    time, linear between, none outside the span."""
    result = WholeRise(np.zeros((20, 3)), np.array([[1.0], [3.0]]), np.array([0.0, 0.02, 0.04]), 2.0, True, True,
                       10, 1.0, 3, 0.0, 0.0, 0.0, 0.05, span=(10, 12))
    at = [result.torque_at(t, 0.01) for t in (0.099, 0.1, 0.105, 0.11, 0.115, 0.12, 0.121)]
    assert at[0] is None and at[-1] is None
    np.testing.assert_allclose(np.concatenate(at[1:-1]), [1.0, 1.0, 2.0, 3.0, 3.0])
