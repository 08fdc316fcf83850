"""Several sit-stand-sit cycles from one synthesised rise (`synth-human --cycles`), and the cycles of a trial."""

import json

import numpy as np
import pytest

from sit2stand.cli import main as sit2stand
from sit2stand.errors import InputError
from sit2stand.human.cycles import cycled, find_cycles
from sit2stand.human.offline import read_trial
from sit2stand.human.synth import SynthConfig, synthesize


@pytest.fixture(scope="module")
def rise():
    return synthesize(SynthConfig(style="natural", seed=0))


def test_three_cycles_rise_and_sit_three_times_with_the_dynamics_of_the_rise(rise):
    demo = cycled(rise, 3, seated_s=1.0)
    cycles = find_cycles(demo.t_s, demo.q[:, 2])
    assert len(cycles) == 3 and all(c.seated_s is not None for c in cycles)
    one = find_cycles(rise.t_s, rise.q[:, 2])[0]
    for c in cycles:                                     # each rise and sit-down lasts the rise's own rise
        assert c.rise_s == pytest.approx(one.rise_s, abs=0.002)
        assert c.sit_s == pytest.approx(one.rise_s, abs=0.05)
    # mirrored in time the COM velocity flips and stays the derivative of the COM
    vx = np.gradient(demo.com_m[:, 0], demo.t_s)
    assert np.abs(vx - demo.com_vel[:, 0]).max() < 0.02
    # the plates carry the body the whole time, without a jump where a rise turns into a sit-down
    fz = sum(p.force_n[:, 2] for p in demo.plates)
    weight = rise.human.total_mass * 9.81
    assert np.abs(np.median(fz) - weight) < 0.05 * weight
    assert np.abs(np.diff(fz)).max() < 0.05 * weight
    # markers on their own clock, at the same instants as the body
    assert len(demo.marker_t_s) == (len(demo.t_s) - 1) // 10 + 1
    assert demo.t_s[-1] == pytest.approx(demo.marker_t_s[-1])


def test_a_brief_touch_between_cycles_is_still_a_cycle(rise):
    def low(seated_s):          # the pelvis's time in its lowest band between cycles: the seated time and the leans
        demo = cycled(rise, 5, seated_s=seated_s)
        cycles = find_cycles(demo.t_s, demo.q[:, 2])
        assert len(cycles) == 5
        return [b.rise_start_s - a.seated_s for a, b in zip(cycles, cycles[1:])]
    assert np.array(low(1.0)) - np.array(low(0.1)) == pytest.approx([0.9] * 4, abs=0.002)


def test_cycles_out_of_range_are_refused(rise):
    with pytest.raises(InputError, match="cycles must be 1-10"):
        cycled(rise, 11)
    with pytest.raises(InputError, match="seated time between cycles 5 s"):
        cycled(rise, 2, seated_s=5.0)


def test_synth_human_writes_a_five_times_trial_whose_markers_show_five_rises(tmp_path):
    assert sit2stand(["synth-human", "--cycles", "5", "--seated", "0.1", "--out", str(tmp_path / "bag")]) == 0
    trial = read_trial(tmp_path / "bag")
    pelvis = [trial.marker_names.index(n) for n in ("LASI", "RASI", "LPSI", "RPSI")]
    z = np.nanmean(np.where(trial.valid[:, pelvis], trial.positions[:, pelvis, 2], np.nan), axis=1)
    assert len(find_cycles(trial.marker_t_s, z)) == 5


def test_the_robot_stands_and_sits_in_every_cycle_of_a_trial_with_brief_touches(tmp_path):
    """--whole on two cycles with a 0.1 s touch between them: after its sit-down the plan is seated again (hips on
    the seat) and the second rise plays as the first; the summary has a row per cycle."""
    bag = tmp_path / "bag"
    assert sit2stand(["synth-human", "--cycles", "2", "--seated", "0.1", "--out", str(bag)]) == 0
    assert sit2stand(["retarget", str(bag), "--whole", "--simulate", "--robot", "g1", "--plan", "frames", "--out",
                      str(tmp_path / "rt")]) == 0
    summary = json.loads((tmp_path / "rt" / "summary.json").read_text())
    cycles = summary["cycles"]
    assert [(c["cycle"], c["stood"], c["sat"]) for c in cycles] == [(1, True, True), (2, True, True)]
    assert summary["fall"] is None and summary["sat_down"]
    for c in cycles:                    # the robot's rise and sit-down near the human's own durations
        assert c["robot_rise_s"] < 1.5 * c["human_rise_s"] and c["robot_sit_s"] < 1.5 * c["human_sit_s"]
