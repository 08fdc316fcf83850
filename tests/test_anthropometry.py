"""sit2stand.human.anthropometry: de Leva's table scaled to a subject, and its trunk split; the children's set and
its choice by stature; fitted factors at their bounds named (mass_scaling), offline, streaming and on a real child."""

import inspect

import numpy as np
import pytest

from conftest import real_file
from sit2stand.human import anthropometry
from sit2stand.human.anthropometry import (DE_LEVA, anthropometric_set, ankle_height_m, jensen_mass_pct,
                                           segment_inertias)
from sit2stand.human.calibration import StreamCalibration, calibrate_lengths
from sit2stand.human.com import estimate_com
from sit2stand.human.com_stream import StreamingComEstimator
from sit2stand.human.mass_scaling import (LENGTH_FACTOR_BOUNDS, MASS_GROUPS, SEGMENTS, FrameRows, RowPool, ScalingRows,
                                          assemble_rows, fit_mass_scaling, group_of, lengths_at_bounds, prior_scaling,
                                          reweigh_by_residual, scaling_at_bounds, solve_mass_scaling)
from sit2stand.human.skeleton import PLUG_IN_GAIT, Subject, build_human
from sit2stand.io.c3d import read_c3d

BILATERAL = ("upper_arm", "forearm", "hand", "thigh", "shank", "foot")


@pytest.mark.parametrize("sex", ["male", "female"])
def test_masses_add_up_to_the_body_mass(sex):
    seg = segment_inertias(1.70, 68.0, sex)
    total = sum(s.mass_kg * (2 if name in BILATERAL else 1) for name, s in seg.items())
    assert total == pytest.approx(68.0, rel=2e-3)   # de Leva's percentages sum to 100 within rounding


@pytest.mark.parametrize("sex", ["male", "female"])
def test_pelvis_plus_torso_reproduce_the_whole_trunk(sex):
    seg = segment_inertias(1.80, 80.0, sex)
    pct, com_pct, _radii, length_mm = DE_LEVA[sex]["trunk"]
    pel, tor = seg["pelvis"], seg["torso"]
    trunk_len = pel.length_m + tor.length_m
    # heights above mid-hip: pelvis COM, torso COM (from its lower end at the top of the pelvis)
    z = (pel.mass_kg * pel.com_from_proximal_m + tor.mass_kg * (pel.length_m + tor.com_from_proximal_m)) / \
        (pel.mass_kg + tor.mass_kg)
    assert pel.mass_kg + tor.mass_kg == pytest.approx(pct / 100 * 80.0)
    assert z == pytest.approx(trunk_len * (1 - com_pct / 100))   # de Leva: trunk COM measured from C7
    assert all(v > 0 for v in tor.inertia_kgm2)


@pytest.mark.parametrize("sex", ["male", "female"])
def test_vertical_chain_is_the_stature(sex):
    h = 1.62
    seg = segment_inertias(h, 60.0, sex)
    chain = ankle_height_m(h, sex) + sum(seg[s].length_m for s in ("shank", "thigh", "pelvis", "torso", "head"))
    assert chain == pytest.approx(h)


def test_lengths_scale_with_stature_and_inertia_with_mass_and_length_squared():
    a, b = segment_inertias(1.5, 50.0), segment_inertias(1.8, 75.0)
    assert b["thigh"].length_m / a["thigh"].length_m == pytest.approx(1.2)
    ratio = np.array(b["thigh"].inertia_kgm2) / np.array(a["thigh"].inertia_kgm2)
    assert ratio == pytest.approx(np.full(3, 1.5 * 1.2**2))


@pytest.mark.parametrize("args, match", [((1.7, 70.0, "x"), "sex"), ((3.0, 70.0, "male"), "height"),
                                         ((1.7, 5.0, "male"), "body mass")])
def test_out_of_range_subjects_are_named(args, match):
    with pytest.raises(ValueError, match=match):
        segment_inertias(*args)


def mass_share(seg: dict, name: str, mass_kg: float) -> float:
    return seg[name].mass_kg / mass_kg


@pytest.mark.parametrize("sex", ["male", "female"])
def test_a_child_of_1_03_m_has_a_heavier_head_and_lighter_legs_than_de_levas_adult(sex):
    child, adult = segment_inertias(1.03, 14.5, sex), DE_LEVA[sex]
    assert 0.18 < mass_share(child, "head", 14.5) < 0.22          # Jensen 1989 at 4 years: 20 %; de Leva: ~7 %
    assert mass_share(child, "head", 14.5) > 2.5 * adult["head"][0] / 100
    assert mass_share(child, "thigh", 14.5) < 0.8 * adult["thigh"][0] / 100
    total = sum(s.mass_kg * (2 if name in BILATERAL else 1) for name, s in child.items())
    assert total == pytest.approx(14.5 * sum(v[0] * (2 if n in BILATERAL else 1) for n, v in adult.items()
                                             if n != "lpt") / 100)
    # the head is longer relative to the stature, the legs shorter; the chain is still the stature
    assert child["head"].length_m / 1.03 > 1.3 * segment_inertias(1.75, 70.0, sex)["head"].length_m / 1.75
    chain = ankle_height_m(1.03, sex) + sum(child[s].length_m for s in ("shank", "thigh", "pelvis", "torso", "head"))
    assert chain == pytest.approx(1.03)
    assert all(v > 0 for s in child.values() for v in s.inertia_kgm2)


def test_jensens_mass_fractions_at_the_tabulated_ages():
    for age in (4.0, 6.0, 12.0, 18.0):
        pct = jensen_mass_pct(age)
        assert pct["head"] + pct["trunk"] + 2 * sum(pct[n] for n in BILATERAL) == pytest.approx(100.0)
    assert jensen_mass_pct(18.0)["head"] == pytest.approx(7.0, abs=0.05)     # the regression at 18: the table's 7.0
    assert jensen_mass_pct(12.0)["head"] == pytest.approx(10.1, abs=0.1)     # and Jensen 1986's 12-year 10.1
    assert jensen_mass_pct(6.0)["thigh"] == pytest.approx(8.5, rel=0.02)     # the 6-year table, rescaled
    assert jensen_mass_pct(2.0) == jensen_mass_pct(4.0)                      # no extrapolation below 4 years


def test_the_set_is_chosen_by_stature_and_blended_through_adolescence():
    for h in (1.45, 1.6, 1.75, 2.0):
        chosen = anthropometric_set(h, "female")
        assert chosen.is_adult and chosen.table is DE_LEVA["female"] and set(chosen.length_factors.values()) == {1.0}
    small = anthropometric_set(1.03)
    assert small.child_weight == 1.0 and small.age_years == pytest.approx(4.0, abs=0.1)
    assert "children's" in small.describe() and "4.0 years" in small.describe()
    mid = anthropometric_set(1.38)
    assert 0 < mid.child_weight < 1 and "blended" in mid.describe()
    heads = [mass_share(segment_inertias(h, 30.0), "head", 30.0) for h in np.arange(1.0, 1.5, 0.02)]
    assert np.all(np.diff(heads) <= 1e-12)                                  # lighter head share as the stature grows
    assert abs(mass_share(segment_inertias(1.4499, 40.0), "head", 40.0)
               - mass_share(segment_inertias(1.45, 40.0), "head", 40.0)) < 1e-3   # continuous at the adult stature
    # an age, when given, decides alone
    assert anthropometric_set(1.2, age_years=25.0).is_adult
    assert anthropometric_set(1.6, age_years=6.0).child_weight == 1.0
    with pytest.raises(ValueError, match="age"):
        anthropometric_set(1.2, age_years=float("nan"))


def test_adults_keep_de_levas_table_bit_for_bit():
    seg = segment_inertias(1.75, 75.0, "male")
    pct, _com, _radii, _length = DE_LEVA["male"]["head"]
    assert seg["head"].mass_kg == pct / 100.0 * 75.0
    assert ankle_height_m(1.75) == anthropometry.ANKLE_HEIGHT * 1.75 * anthropometry.vertical_length_factor("male")


def test_the_skeleton_of_a_child_has_the_childrens_masses_and_a_larger_head():
    child, adult = build_human(Subject(1.03, 16.0)), build_human(Subject(1.75, 70.0))
    assert child.segment_mass["head"] / 16.0 > 0.18 > 0.08 > adult.segment_mass["head"] / 70.0
    assert child.total_mass == pytest.approx(16.0)

    def head_marker_height(human, stature):
        return human.model.frames[human.marker_frames["LFHD"]].placement.translation[2] / stature

    assert head_marker_height(child, 1.03) / head_marker_height(adult, 1.75) == pytest.approx(
        anthropometric_set(1.03).length_factors["head"])


def pelvis_to_zero_scaling(human):
    """A scaling whose rows ask for no pelvis at all: its factor must stop at the lower bound."""
    A = np.zeros((1, len(MASS_GROUPS) + 2))
    A[0, MASS_GROUPS.index("pelvis")] = 1.0
    return solve_mass_scaling(human, A, np.zeros(1), human.total_mass, weights=np.array([1e3]))


def test_a_mass_factor_at_its_bound_is_named():
    human = build_human()
    scaling = pelvis_to_zero_scaling(human)
    assert scaling.factors()["pelvis"] == pytest.approx(0.5, abs=1e-3)
    (hit,) = scaling_at_bounds(scaling)
    assert (hit.kind, hit.group, hit.bound, hit.side) == ("mass", "pelvis", 0.5, "lower")
    assert "pelvis mass factor 0.500" in hit.note() and "lower bound 0.5" in hit.note()
    assert not scaling_at_bounds(solve_mass_scaling(human, np.zeros((0, len(MASS_GROUPS) + 2)), np.zeros(0),
                                                    human.total_mass, weights=np.zeros(0)))


def smooth_noise(rng, n, rho, sd):
    """An AR(1) series: lag-1 autocorrelation ``rho``, standard deviation ``sd``."""
    e = np.zeros(n)
    e[0] = rng.normal(0, sd)
    for k in range(1, n):
        e[k] = rho * e[k - 1] + rng.normal(0, sd * np.sqrt(1 - rho**2))
    return e


def test_rows_that_miss_smoothly_count_at_their_worth_against_the_prior():
    """Rows whose error is 10x the nominal noise and smooth over frames (rho 0.9): reweighed to 1 / (10 x sqrt of
    (1 + rho) / (1 - rho)) of their nominal weight, and the refit stays nearer the table than the nominal fit."""
    human, rng = build_human(), np.random.default_rng(4)
    count = {g: sum(group_of(seg) == g for seg in SEGMENTS) for g in MASS_GROUPS}
    table = prior_scaling(human).masses
    theta_table = np.array([table[g] / count[g] for g in MASS_GROUPS] + [0.0, 0.0])
    frames, channels = 300, 6
    scale = np.tile(np.linspace(0.5, 5, channels), frames)[:, None]
    A = rng.normal(0, 1, (frames * channels, len(theta_table))) * scale
    channel = np.tile(np.arange(channels), frames)
    error = np.zeros(len(channel))
    for c in range(channels):
        error[channel == c] = smooth_noise(rng, frames, 0.9, 50.0)      # 10x the nominal 5 N
    rows = ScalingRows(A, A @ theta_table + error, np.full(len(channel), 1 / 5.0), channel)
    weights = reweigh_by_residual(rows, theta_table)
    assert np.median(weights / rows.weights) == pytest.approx(1 / (10 * np.sqrt(1.9 / 0.1)), rel=0.25)
    nominal = solve_mass_scaling(human, rows.A, rows.b, human.total_mass, weights=rows.weights)
    refit = fit_mass_scaling(human, rows, human.total_mass)
    departure = {name: max(abs(f - 1) for f in s.factors().values()) for name, s in (("nominal", nominal),
                                                                                      ("refit", refit))}
    assert refit.noise_passes == 3 and departure["refit"] < departure["nominal"] / 2, departure


def test_each_frame_gives_its_static_or_its_dynamic_rows_in_the_frames_order():
    """Quiet frames with a COP give their three quasi-static rows (channels 6-8), the others their six dynamic rows
    (0-5), each frame's in turn; the same from a list of frames and from the growing pool the live estimator keeps
    (past its first 64 frames)."""
    rng, n_theta = np.random.default_rng(2), len(MASS_GROUPS) + 2
    acc = rng.uniform(0.0, 1.0, 150)
    frames = [FrameRows(float(a), (rng.normal(size=(6, n_theta)), rng.normal(size=6)),
                        None if k % 5 == 0 else (rng.normal(size=(3, n_theta)), rng.normal(size=3)))
              for k, a in enumerate(acc)]
    limit = max(0.15, float(np.quantile(acc, 0.4)))
    static = [r.static is not None and r.acc <= limit for r in frames]
    A = np.vstack([r.static[0] if s else r.dynamic[0] for r, s in zip(frames, static)])
    b = np.concatenate([r.static[1] if s else r.dynamic[1] for r, s in zip(frames, static)])
    channel = np.concatenate([np.arange(6, 9) if s else np.arange(6) for s in static])
    weights = np.concatenate([[1 / 5.0, 1 / 2.0, 1 / 2.0] if s else [1 / 5.0] * 3 + [1 / 2.0] * 3 for s in static])
    assert 20 < sum(static) < 130
    for rows in (assemble_rows(frames), assemble_rows(RowPool.of(frames))):
        np.testing.assert_array_equal(rows.A, A)
        np.testing.assert_array_equal(rows.b, b)
        np.testing.assert_array_equal(rows.channel, channel)
        np.testing.assert_array_equal(rows.weights, weights)
    assert assemble_rows([]).A.shape == (0, n_theta)


def test_a_length_factor_at_its_bound_is_named():
    hits = lengths_at_bounds({"foot": 1.575, "head": 1.1, "thigh": 0.6})
    assert [(h.group, h.side, h.bound) for h in hits] == [("foot", "upper", 1.6), ("thigh", "lower", 0.6)]
    assert "foot length factor 1.575" in hits[0].note() and "upper bound 1.6" in hits[0].note()
    # the bounds named are calibrate_lengths' own
    assert f"bounds={LENGTH_FACTOR_BOUNDS}" in inspect.getsource(calibrate_lengths)


def test_the_streaming_estimator_exposes_factors_at_their_bounds():
    subject = Subject(1.75, 75.0)
    cal = StreamCalibration({"foot": 1.6, "head": 1.0}, {}, 0, float("nan"), float("nan"), 1.75, "male")
    est = StreamingComEstimator(subject, list(PLUG_IN_GAIT), calibration=cal)
    assert [w.split(" ")[0] for w in est.warnings] == ["foot"]
    est.scaling = pelvis_to_zero_scaling(est.human)
    assert [(f.kind, f.group) for f in est.at_bounds] == [("length", "foot"), ("mass", "pelvis")]
    assert "pelvis mass factor" in est.warnings[1]


# -- the real child (1.03 m, 14.5 kg; Vicon Plug-in-Gait; chair not on a plate) --------------------------------------

@pytest.fixture(scope="module")
def child_runs():
    """The offline COM of the real child with de Leva's adult table and with the children's set, and Vicon's COM."""
    trial = read_c3d(real_file("sts_child_vicon_01.c3d"), feet_plate=2)
    m, mp = trial.markers, trial.model_points
    runs = {}
    for name, adult_from in (("adult", 0.5), ("child", anthropometry.ADULT_STATURE_M)):
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(anthropometry, "ADULT_STATURE_M", adult_from)
            patch.setattr(anthropometry, "CHILD_STATURE_M", adult_from - 0.15)
            runs[name] = estimate_com(m.times_s, m.names, m.positions_m, m.valid, trial.plates,
                                      Subject(trial.height_m, trial.body_mass_kg), chair_on_plate=False)
    i = mp.names.index("CentreOfMass")
    ok = mp.valid[:, i]
    t = runs["child"].t_s
    vicon = np.array([np.interp(t, mp.times_s[ok], mp.positions_m[ok, i, k]) for k in range(3)]).T
    return runs, vicon, trial


def rms_mm(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))) * 1e3)


def test_real_child_adult_table_stretches_the_head_and_the_plates_keep_the_masses_near_it(child_runs):
    """Adult proportions on a child: the calibration stretches the head 1.5x. The plates' rows, counted at their worth,
    move no mass factor far from the table (fitted as independent samples they put the pelvis at its 0.5 bound)."""
    runs, vicon, _ = child_runs
    adult = runs["adult"]
    assert adult.segment_table.startswith("segment table: de Leva")
    assert adult.subject.lengths["head"] > 1.45                         # adult head proportions on a child
    assert not [f for f in adult.at_bounds if f.kind == "mass"], adult.notes
    assert all(0.8 < f < 1.25 for f in adult.scaling.factors().values()), adult.scaling.factors()
    assert rms_mm(adult.com_m, vicon) < 8.0                             # measured 5.5 mm (6.3 before)


def test_real_child_childrens_table_no_mass_factor_at_a_bound_and_the_plates_agree_better(child_runs):
    runs, vicon, _ = child_runs
    adult, child = runs["adult"], runs["child"]
    assert "children's" in child.segment_table and any("children's" in n for n in child.notes)
    factors = child.scaling.factors()
    assert not [f for f in child.at_bounds if f.kind == "mass"], child.notes
    assert factors["pelvis"] > 0.7
    assert 0.85 < child.subject.lengths["head"] < 1.2                  # the head no longer stretched 1.5x
    # a length factor still at its bound is named (the foot: the markers' heel-to-toe span is 1.6x the table's)
    for f in (f for f in child.at_bounds if f.kind == "length"):
        assert any(n.startswith(f"{f.group} length factor") for n in child.notes)
    # the plates, the physical check: the model COP fits the measured one better, unscaled and scaled
    assert child.scaling.cop_rms_before_m < adult.scaling.cop_rms_before_m
    assert child.scaling.cop_rms_after_m <= adult.scaling.cop_rms_after_m


def test_real_child_vicons_com_is_dempsters_adult_weighting(child_runs):
    """Vicon's CentreOfMass is its segment COMs weighted by Dempster's adult fractions (head 8.1 %): an adult
    reference, so the children's set (head ~18 % after scaling) sits higher than it by design, not by error."""
    runs, vicon, trial = child_runs
    mp = trial.model_points
    names = ["PelvisCOM", "LeftFemurCOM", "RightFemurCOM", "LeftTibiaCOM", "RightTibiaCOM", "LeftFootCOM",
             "RightFootCOM", "ThoraxCOM", "HeadCOM"]
    segs = np.stack([mp.positions_m[:, mp.names.index(n)] for n in names], axis=-1)
    com = mp.positions_m[:, mp.names.index("CentreOfMass")]
    ok = np.all(np.isfinite(segs), axis=(1, 2)) & np.all(np.isfinite(com), axis=1)
    w, *_ = np.linalg.lstsq(segs[ok].reshape(-1, len(names)), com[ok].reshape(-1), rcond=None)
    assert w[names.index("HeadCOM")] == pytest.approx(0.081, abs=1e-3)
    assert w[names.index("ThoraxCOM")] / w[names.index("PelvisCOM")] == pytest.approx(0.355 / 0.142, rel=1e-3)
    child = runs["child"]
    err = child.com_m - vicon
    assert 0.005 < np.mean(err[:, 2]) < 0.060                         # higher than Vicon's adult COM: 41 mm
    assert np.all(np.sqrt(np.mean(err[:, :2] ** 2, axis=0)) < 0.010)  # forward and sideways: 4.9, 1.1 mm
