"""sit2stand.human.com_feed: what the human COM node keeps between callbacks, without ROS."""

import numpy as np

from sit2stand.human.com_feed import (PENDING_PLATE_SAMPLES, SUBJECT_WAIT_FRAMES, FrameCosts, PlateInbox,
                                      SubjectWait, shed)


class Estimator:
    def __init__(self):
        self.got = {}

    def add_plate_samples(self, name, t, force, moment):
        self.got[name] = (t, force, moment)


def test_frames_wait_for_the_subject_in_order_and_too_many_say_so():
    wait = SubjectWait()
    assert all(wait.hold(k) for k in range(SUBJECT_WAIT_FRAMES))
    assert not wait.hold("one too many")
    seen = []
    wait.release(seen.append)
    assert seen[:3] == [0, 1, 2] and len(seen) == SUBJECT_WAIT_FRAMES + 1 and wait.frames == []


def test_plate_samples_go_to_the_estimator_as_one_array_per_plate_and_a_flood_keeps_the_newest():
    inbox, est = PlateInbox(), Estimator()
    for k in range(PENDING_PLATE_SAMPLES + 1):
        inbox.add("feet", (k * 1e-3, 1.0, 2.0, 3.0 + k, 0.1, 0.2, 0.3))
    inbox.add("chair", (0.0, 0, 0, 400.0, 0, 0, 0))
    inbox.flush(est)
    t, force, moment = est.got["feet"]
    assert len(t) == PENDING_PLATE_SAMPLES // 2 and t[-1] == PENDING_PLATE_SAMPLES * 1e-3
    assert force.shape == (len(t), 3) and np.allclose(moment[0], [0.1, 0.2, 0.3])
    assert est.got["chair"][1][0, 2] == 400.0
    est.got.clear()
    inbox.flush(est)
    assert est.got == {}, "flushed samples are not sent twice"


def test_a_frame_is_shed_only_past_the_threshold_and_costs_are_summarised():
    assert not shed(0.0, 10.0, 9.0), "0: never"
    assert shed(0.03, 10.0, 9.9) and not shed(0.03, 10.0, 9.99)
    costs = FrameCosts()
    costs.wall_s += [0.001] * 99 + [0.010]
    costs.cpu_s += [0.0008] * 100
    costs.skipped, costs.shed = 2, 1
    f = costs.figures({"chair": 3})
    assert f["frames"] == "100" and f["cost_p50_ms"] == "1.000" and float(f["cost_p99_ms"]) > 1.0
    assert f["cpu_p50_ms"] == "0.800" and f["plate_dropouts"] == "chair: 3 frames"
    assert FrameCosts().figures({})["cost_p50_ms"] == "nan"
