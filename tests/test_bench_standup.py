"""sit2stand.bench.standup: the population is drawn in range, reproducibly, and aggregated right (nothing simulated)."""

import dataclasses

import pytest

from sit2stand.bench import standup as B
from sit2stand.human.synth import SynthConfig


@pytest.fixture(scope="module")
def population():
    return B.sample_population(300, seed=0)


def test_bodies_seats_and_rises_are_in_the_issues_ranges(population):
    for c in population:
        assert 1.5 <= c.height_m <= 1.95
        assert 50.0 <= c.mass_kg <= 110.0
        assert 17.0 - 0.1 <= c.mass_kg / c.height_m**2 <= 38.0 + 0.1
        assert abs(c.seat_height_m - 0.26 * c.height_m) <= 0.05 + 1e-3
        lo, hi = B.RISE_S[c.style]
        assert lo <= c.rise_s <= hi
        assert c.sex in ("male", "female")


def test_the_ranges_are_covered_not_just_respected(population):
    heights = [c.height_m for c in population]
    masses = [c.mass_kg for c in population]
    assert min(heights) < 1.55 and max(heights) > 1.9
    assert min(masses) < 55 and max(masses) > 105


def test_styles_take_turns_and_fast_is_natural_rushed(population):
    assert [c.style for c in population[:6]] == ["natural", "elderly", "fast"] * 2
    fast = next(c for c in population if c.style == "fast")
    cfg = fast.config()
    assert isinstance(cfg, SynthConfig)
    assert cfg.style == "natural" and cfg.duration_s == fast.rise_s <= 1.2


def test_the_same_seed_draws_the_same_population_and_another_seed_another():
    assert B.sample_population(30, seed=7) == B.sample_population(30, seed=7)
    assert B.sample_population(30, seed=7) != B.sample_population(30, seed=8)


def test_only_one_style_keeps_the_same_people():
    mixed = B.sample_population(12, seed=3)
    elderly = B.sample_population(12, seed=3, styles=("elderly",))
    assert all(c.style == "elderly" for c in elderly)
    assert [(c.height_m, c.mass_kg, c.seat_height_m, c.seed) for c in mixed] == \
        [(c.height_m, c.mass_kg, c.seat_height_m, c.seed) for c in elderly]


def test_bad_requests_name_the_culprit():
    with pytest.raises(ValueError, match="at least 1 case, not 0"):
        B.sample_population(0)
    with pytest.raises(ValueError, match="not sprint"):
        B.sample_population(3, styles=("sprint",))


def test_aggregate_counts_success_and_the_share_at_human_speed():
    def row(i, style, stood, scale, ratio):
        return {"case": {"index": i, "style": style, "seed": i}, "stood_up": stood, "time_scale": scale,
                "duration_ratio": ratio, "com_tracking_rms_m": 0.004, "wall_s": 10.0, "synth_seed": i}
    rows = [row(0, "natural", True, 1.2, 1.3), row(1, "elderly", True, 4.0, 3.7), row(2, "fast", False, 1.0, 1.0)]
    agg = B.aggregate(rows)
    assert agg["success_rate"] == pytest.approx(2 / 3)
    assert agg["share_stood_time_scale_le_1_5"] == pytest.approx(1 / 3)     # the fallen fast case does not count
    assert agg["time_scale"]["max"] == 4.0 and agg["time_scale"]["median"] == 1.2
    assert agg["by_style"] == {"natural": "1/1", "elderly": "1/1", "fast": "0/1"}
    assert agg["torque_demand_peak_ratio"]["median"] is None      # not measured: reported as such, not as 0


def test_a_body_the_synthesiser_refuses_is_left_out_of_the_robots_rates():
    rows = [{"case": {"index": 0, "style": "natural", "seed": 0}, "stood_up": True, "time_scale": 1.0,
             "duration_ratio": 1.1, "wall_s": 9.0, "synth_seed": 0},
            {"case": {"index": 1, "style": "fast", "seed": 1}, "stood_up": False, "stage": "synthesis",
             "error": "ValueError: no demonstration", "wall_s": 1.0}]
    agg = B.aggregate(rows)
    assert (agg["cases"], agg["synthesised"], agg["not_synthesised"], agg["errors"]) == (2, 1, 1, 0)
    assert agg["success_rate"] == 1.0 and agg["by_style"]["fast"] == "0/0"
    assert "NOSYN" in B.case_line({**rows[1], "case": {**rows[1]["case"], "height_m": 1.6, "mass_kg": 54.0,
                                                       "sex": "female", "seat_height_m": 0.39, "rise_s": 1.1}})


def test_the_torque_controllers_qp_times_are_reported_only_where_it_ran():
    def row(i, qp):
        return {"case": {"index": i, "style": "natural", "seed": i}, "stood_up": True, "time_scale": 1.2,
                "duration_ratio": 1.2, "wall_s": 9.0, "synth_seed": i, **qp}
    timed = [row(0, {"controller_qp_ms_p99": 0.8, "controller_qp_cpu_ms_p99": 0.7}),
             row(1, {"controller_qp_ms_p99": 1.3, "controller_qp_cpu_ms_p99": 0.9})]
    agg = B.aggregate(timed)
    assert agg["share_qp_p99_le_1_ms"] == pytest.approx(0.5) and agg["controller_qp_ms_p99"]["max"] == 1.3
    assert "QP p99 per step" in B.summary_text(agg) and "at <= 1 ms: 50 %" in B.summary_text(agg)
    joint_pd = B.aggregate([row(0, {})])
    assert joint_pd["share_qp_p99_le_1_ms"] is None and "QP" not in B.summary_text(joint_pd)


def test_the_optimisations_time_is_reported_per_case_and_per_second_of_the_humans_rise():
    def row(i, plan, extra):
        return {"case": {"index": i, "style": "natural", "seed": i}, "stood_up": True, "time_scale": 1.0,
                "duration_ratio": 1.0, "wall_s": 9.0, "synth_seed": i, "plan": plan, **extra}
    rows = [row(0, "whole", {"whole_rise_solve_s": 8.0, "human_rise_s": 1.6}),
            row(1, "frames", {"whole_rise_solve_s": 30.0, "human_rise_s": 3.0, "whole_rise_com_relaxed": True}),
            row(2, "frames", {}), row(3, "whole", {"whole_rise_solve_s": 5.0, "human_rise_s": 1.0,
                                                   "whole_rise_com_relaxed": True})]
    agg = B.aggregate(rows)
    assert agg["optimised_plans_played"] == 2 and agg["whole_rise_solve_s"]["max"] == 30.0
    assert agg["optimised_plans_relaxed"] == 1                 # a relaxed solution the per-frame plan beat: not played
    assert agg["whole_rise_solve_per_rise"]["max"] == pytest.approx(10.0)
    assert "optimised plan played in 2 cases (1 within the relaxed COM tolerance)" in B.summary_text(agg)
    assert "optimisation" not in B.summary_text(B.aggregate([row(0, "frames", {})]))


def test_a_population_captured_at_another_rate_is_the_same_people():
    slow, fast = B.sample_population(6, seed=0), B.sample_population(6, seed=0, marker_rate_hz=200.0)
    assert [dataclasses.replace(c, marker_rate_hz=100.0) for c in fast] == slow
    assert all(c.config().marker_rate_hz == 200.0 for c in fast)
