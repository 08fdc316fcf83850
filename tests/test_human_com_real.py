"""The human COM estimator on a real sit-to-stand recording, against Vicon's own model (read from ../shared)."""

import pytest

from conftest import real_file
from sit2stand.human.offline import run
from sit2stand.io.c3d import read_c3d, write_trial_bag


@pytest.fixture(scope="module")
def child_summary(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("child")
    write_trial_bag(read_c3d(real_file("sts_child_vicon_01.c3d"), feet_plate=2), tmp / "bag")
    return run(tmp / "bag", tmp / "out", quiet=True)


def test_standing_com_to_cop_no_worse_than_vicon(child_summary):
    ours, vicon = child_summary["standing_com_to_cop_mm"], child_summary["standing_reference_com_to_cop_mm"]
    assert ours["mean"] <= vicon["mean"] and ours["max"] <= vicon["max"], (ours, vicon)
    assert child_summary["standing_frames"] >= 20


def test_close_to_vicons_com_and_the_plates_weigh_the_child(child_summary):
    # Vicon's CentreOfMass is its adult (Dempster) segment weighting; ours uses the children's table (Jensen 1989),
    # whose model COP fits the plate better (12.2 against 14.8 mm): 42 mm from Vicon's, nearly all of it height (a
    # child's larger head; the plates barely see the COM's height, and no longer pull it down to Vicon's).
    # So this bounds the distance to a different model, not an error.
    assert child_summary["com_rms_vs_reference_mm"] < 60.0
    assert child_summary["marker_rms_mm"] < 8.0
    # the file says 14.5 kg; the plate reads ~10 % more in quiet standing, and the estimator says so
    assert 15.5 < child_summary["body_mass_used_kg"] < 16.5
    assert any("plates weigh" in n for n in child_summary["notes"])
