"""sit2stand.retarget.phases: a trial's phases from the pelvis, the COM and the chair; a trial that ends seated is
played up to the human's sit-down."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from sit2stand.cli import main as sit2stand
from sit2stand.errors import InputError
from sit2stand.human.offline import read_trial
from sit2stand.io import messages as M
from sit2stand.io.bag import BagReader, BagWriter
from sit2stand.retarget.offline import trial_phases
from sit2stand.retarget.phases import find_phases

ROOT = Path(__file__).resolve().parents[1]


def truth_com(trial):
    t, com = trial.truth
    return np.stack([np.interp(trial.marker_t_s, t, com[:, i]) for i in range(3)], axis=1)


def chair_force(trial):
    chair = next(p for p in trial.plates if p.name == "chair")
    return np.interp(trial.marker_t_s, chair.t_s, chair.force_n[:, 2])


@pytest.mark.parametrize("name", ["natural", "elderly"])
def test_a_shipped_rise_is_seated_flexion_extension_standing(name):
    trial = read_trial(ROOT / "bags" / name)
    p = trial_phases(trial, truth_com(trial), chair_force(trial))
    assert p.starts_seated and not p.ends_seated and p.sit_down_s is None
    assert p.rise_start_s < p.seat_off_s < p.standing_s
    # the synthesiser's own seat-off (the chair fully unloaded): the 30 N threshold comes at most 0.1 s before it
    events = dict(e.split("@") for e in trial_events(name))
    assert -0.1 <= p.seat_off_s - float(events["seat_off"].rstrip("s")) <= 0.01
    order = [lab for i, lab in enumerate(p.labels) if i == 0 or p.labels[i - 1] != lab]
    assert order == ["seated", "flexion", "extension", "standing"]


def trial_events(name):
    with BagReader(ROOT / "bags" / name) as bag:
        return [e.strip() for e in bag.custom_data["events"].split(";") if e.strip()]


def test_a_trial_that_sits_back_down_has_its_sit_down_found():
    trial = read_trial(ROOT / "bags" / "natural")
    com, z = truth_com(trial), trial.positions[:, 0, 2]
    t = np.concatenate([trial.marker_t_s, trial.marker_t_s[-1] + 0.01 + trial.marker_t_s - trial.marker_t_s[0]])
    p = find_phases(t, np.r_[z, z[::-1]], np.r_[com[:, 0], com[::-1, 0]], 1.75)
    assert p.ends_seated and p.sit_down_s > p.standing_s
    assert p.labels[-1] == "seated" and "sitting_down" in set(p.labels)
    assert p.rise_and_stand(t).sum() < len(t) and p.rise_and_stand(t)[: len(z)].all()


def test_no_rise_is_named():
    t = np.arange(100) * 0.01
    with pytest.raises(InputError, match="not a sit-to-stand"):
        find_phases(t, np.full(100, 0.55), np.zeros(100), 1.75)


@pytest.fixture(scope="module")
def up_and_down(tmp_path_factory) -> Path:
    """The natural rise followed by its mirror image: the human sits back down (chair plate included)."""
    bag = tmp_path_factory.mktemp("trial") / "up_and_down"
    mirrored = ("/mocap/", "/force_plate/", "/ground_truth/com")
    with BagReader(ROOT / "bags" / "natural") as src, BagWriter(bag, custom_data=src.custom_data) as out:
        for topic, info in src.topics().items():
            out.add_topic(topic, info.msgtype)
        back = 2 * src.end_ns + 10_000_000          # the mirror of a stamp t is back - t
        for msg in src.messages():
            out.write_raw(msg.topic, msg.timestamp_ns, msg.data)
            if msg.topic.startswith(mirrored):
                obj = src.deserialize(msg)
                t_ns = back - msg.timestamp_ns
                obj = dataclasses.replace(obj, header=M.header(t_ns, obj.header.frame_id))
                out.write(msg.topic, t_ns, obj)
    return bag


def test_retarget_plays_rise_and_stand_of_a_trial_that_ends_seated(tmp_path, up_and_down):
    """By default the plan stops before the sit-down: it ends standing (the simulated stand-up: the test below)."""
    assert sit2stand(["retarget", str(up_and_down), "--plan", "frames", "--out", str(tmp_path / "rt")]) == 0
    summary = json.loads((tmp_path / "rt" / "summary.json").read_text())
    assert summary["phases"]["played"] == "rise and stand" and summary["phases"]["sit_down_s"] is not None
    assert summary["frames"] < 2 * 391 - 100, "the sit-down frames are left out"


def test_retarget_into_a_finished_run_is_refused_before_it_touches_its_files(tmp_path, up_and_down, capsys):
    out = tmp_path / "rt"
    (out / "retarget").mkdir(parents=True)
    (out / "marker_map.yaml").write_text("the finished run's map\n")
    assert sit2stand(["retarget", str(up_and_down), "--out", str(out)]) == 2
    assert "rt/retarget: exists already" in capsys.readouterr().err
    assert (out / "marker_map.yaml").read_text() == "the finished run's map\n" and not (out / "summary.json").exists()


def test_retarget_whole_stands_up_and_sits_back_down_at_the_humans_timing(tmp_path, up_and_down):
    """--whole: the plan is seated again from the human's touch-down (the chair takes the load: no ZMP criterion
    that would hold a COM behind the heels at the cap), and the robot sits back down on the chair."""
    assert sit2stand(["retarget", str(up_and_down), "--whole", "--simulate", "--plan", "frames",
                      "--out", str(tmp_path / "rt")]) == 0
    summary = json.loads((tmp_path / "rt" / "summary.json").read_text())
    assert summary["phases"]["played"] == "whole trial"
    assert summary["stood_up"] and summary["sat_down"] and summary["fall"] is None
    assert summary["time_scale"] < 1.5, "the sit-down is not stretched (it was at the cap of 4 to the end)"
    assert abs(summary["pelvis_final_m"] - summary["pelvis_planned_final_m"]) < 0.05
