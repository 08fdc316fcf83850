"""sit2stand.human.anthropometry: de Leva's table scaled to a subject, and its trunk split."""

import numpy as np
import pytest

from sit2stand.human.anthropometry import DE_LEVA, ankle_height_m, segment_inertias

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
