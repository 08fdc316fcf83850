"""The subject in the stream: /human/subject (sit2stand_msgs/Subject, latched) carries stature, mass and sex, and
`human-com`'s reader takes them from it when the bag's custom_data lacks them (a ROS 1 round trip drops it)."""

import numpy as np

from sit2stand.human.offline import read_trial
from sit2stand.io import messages as M
from sit2stand.io.bag import BagReader, BagWriter, reliable_qos
from sit2stand.io.topics import MARKERS_TOPIC, MOCAP_TYPE, SUBJECT_TOPIC, SUBJECT_TYPE


def _bag(path, custom, with_subject):
    with BagWriter(path, custom_data=custom) as bag:
        bag.add_topic(MARKERS_TOPIC, MOCAP_TYPE)
        if with_subject:
            bag.add_topic(SUBJECT_TOPIC, SUBJECT_TYPE, [reliable_qos(1, transient_local=True)])
            bag.write(SUBJECT_TOPIC, 1_000, M.subject(1_000, 1.62, 58.5, "female"))
        for k in range(3):
            bag.write(MARKERS_TOPIC, 10_000_000 * (k + 1), M.mocap_frame(10_000_000 * (k + 1), ["LASI", "RASI"],
                                                                          np.zeros((2, 3)), np.ones(2, bool)))


def test_the_subject_topic_stands_in_for_missing_custom_data(tmp_path):
    _bag(tmp_path / "a", {}, True)
    trial = read_trial(tmp_path / "a")
    assert (trial.height_m, trial.mass_kg, trial.sex) == (1.62, 58.5, "female")
    with BagReader(tmp_path / "a") as bag:
        assert [q.durability.name for q in bag.qos(SUBJECT_TOPIC)] == ["TRANSIENT_LOCAL"]


def test_custom_data_still_comes_first_and_neither_leaves_it_unknown(tmp_path):
    _bag(tmp_path / "b", {"height_m": "1.80", "body_mass_kg": "80", "sex": "male"}, True)
    trial = read_trial(tmp_path / "b")
    assert (trial.height_m, trial.mass_kg, trial.sex) == (1.80, 80.0, "male")
    _bag(tmp_path / "c", {}, False)
    assert read_trial(tmp_path / "c").height_m is None
