"""sit2stand.io.c3d: the real lab files import in SI units and a REP-103 frame; bad input fails clearly."""

import ezc3d
import numpy as np
import pytest

from conftest import real_file
from sit2stand.io.topics import MARKERS_TOPIC, REFERENCE_COM_TOPIC, SUBJECT_TOPIC, plate_topic
from sit2stand.io.bag import BagReader
from sit2stand.io.c3d import C3DError, read_c3d, write_trial_bag
from sit2stand.forceplate import point_in_polygon


G = 9.81


def synthetic_c3d(path, *, with_gaps=True):
    """A small marker-only C3D: heel/toe markers pointing along file +X, z up, one marker with gaps."""
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ("LHEE", "LTOE", "RHEE", "RTOE", "C7")
    c3d.add_parameter("POINT", "UNITS", ["mm"])
    pts = np.ones((4, 5, 20))
    pts[0] *= 100.0
    pts[1] *= 200.0
    pts[2] *= 50.0
    pts[0, 1] += 150.0
    pts[0, 3] += 150.0
    pts[2, 4] = 1400.0
    if with_gaps:
        pts[:3, 4, 5] = np.nan
        pts[:3, 4, 6] = 0.0
    c3d["data"]["points"] = pts
    c3d.write(str(path))
    return path


def test_sit_to_stand_child_done_when():
    """The issue's check: markers at 100 Hz, feet plate at 2000 Hz, standing force ~ m g, COP inside the plate."""
    trial = read_c3d(real_file("sts_child_vicon_01.c3d"), feet_plate=2)
    assert trial.markers.rate_hz == 100.0
    (feet,) = trial.plates  # only plate index 2 is loaded; the others are not published
    assert feet.name == "feet" and feet.index == 2 and feet.rate_hz == 2000.0
    assert trial.body_mass_kg == pytest.approx(14.5)
    # standing phase: pelvis (ASIS/PSIS mean) height within 5 % of its final rise
    idx = [trial.markers.names.index(n) for n in ("LASI", "RASI", "LPSI", "RPSI")]
    pelvis_z = np.nanmean(trial.markers.positions_m[:, idx, 2], axis=1)
    standing = pelvis_z >= pelvis_z.min() + 0.95 * (pelvis_z.max() - pelvis_z.min())
    t_stand = trial.markers.times_s[standing]
    sel = (feet.t_s >= t_stand[0]) & (feet.t_s <= t_stand[-1])
    ratio = feet.force_n[sel, 2].mean() / (trial.body_mass_kg * G)
    assert abs(ratio - 1.0) < 0.15, f"standing vertical force is {ratio:.3f} x m g"
    assert feet.cop_valid[sel].all()
    assert point_in_polygon(feet.cop_m[sel, :2], feet.corners_m[:, :2]).all()
    # REP-103: z up (pelvis ~0.4-0.55 m above the floor for a 1.03 m child), x forward (heel to toe)
    assert 0.35 < pelvis_z.min() < pelvis_z.max() < 0.7
    toe, heel = trial.markers.names.index("LTOE"), trial.markers.names.index("LHEE")
    assert np.nanmean(trial.markers.positions_m[:, toe, 0] - trial.markers.positions_m[:, heel, 0]) > 0.05
    # model outputs are not markers, but Vicon's COM is kept as a reference
    assert "CentreOfMass" in trial.model_points.names and "CentreOfMass" not in trial.markers.names
    assert not any(n.endswith("Angles") for n in trial.markers.names + trial.model_points.names)


def test_sit_to_stand_bag_topics_and_rates(sts_bag):
    with BagReader(sts_bag) as bag:
        topics = bag.topics()
        assert topics[MARKERS_TOPIC].count == 91
        assert topics[plate_topic("feet")].count == 1820
        assert topics[REFERENCE_COM_TOPIC].count == 91
        assert set(topics) == {MARKERS_TOPIC, "/mocap/model_points", REFERENCE_COM_TOPIC, plate_topic("feet"),
                               SUBJECT_TOPIC}
        assert "forward=" in bag.custom_data["lab_axes"]
        ((_, subject),) = bag.read(SUBJECT_TOPIC)       # latched, as in synthesised bags
        assert (subject.height_m, subject.mass_kg) == pytest.approx((1.03, 14.5))
        assert [q.durability.name for q in bag.qos(SUBJECT_TOPIC)] == ["TRANSIENT_LOCAL"]


@pytest.mark.parametrize("name, n_plates, point_rate, analog_rate", [
    ("walk_amti_eb015pi.c3d", 2, 50.0, 200.0),
    ("qualisys_sample.c3d", 2, 200.0, 2000.0),
    ("cmj_vicon_kistler.c3d", 1, 200.0, 2000.0),   # the second Kistler plate is never loaded
])
def test_other_labs_files_import(tmp_path, name, n_plates, point_rate, analog_rate):
    trial = read_c3d(real_file(name))
    assert trial.markers.rate_hz == point_rate and len(trial.plates) == n_plates
    assert trial.axes.up == "+Z"
    for plate in trial.plates:
        assert plate.rate_hz == analog_rate
        loaded = plate.cop_valid
        assert loaded.any()
        # zeroed plates: every valid COP lies on its plate (walking file needs FORCE_PLATFORM:ZERO honoured)
        assert point_in_polygon(plate.cop_m[loaded, :2], plate.corners_m[:, :2], margin_m=-0.005).all()
    counts = write_trial_bag(trial, tmp_path / "bag")
    assert counts[MARKERS_TOPIC] == trial.markers.positions_m.shape[0]


def test_kistler_jump_quiet_standing_weight():
    trial = read_c3d(real_file("cmj_vicon_kistler.c3d"))
    fz = trial.plates[0].force_n[:2000, 2]  # first second: quiet standing before the jump
    assert np.median(fz) / G == pytest.approx(76.7, rel=0.03)


def test_occluded_markers_are_invalid_never_zero(tmp_path):
    trial = read_c3d(synthetic_c3d(tmp_path / "s.c3d"), markers_only=True)
    c7 = trial.markers.names.index("C7")
    assert not trial.markers.valid[5, c7] and not trial.markers.valid[6, c7]   # NaN and exact zeros
    assert trial.markers.valid[4, c7] and trial.markers.valid[7, c7]
    assert np.isnan(trial.markers.positions_m[[5, 6], c7]).all()
    assert trial.markers.positions_m[4, c7] == pytest.approx([0.1, 0.2, 1.4])  # mm -> m, x forward
    with BagReader(write_trial_bag_path(trial, tmp_path / "bag")) as bag:
        frames = bag.read(MARKERS_TOPIC)
        assert list(frames[5][1].valid) == [True, True, True, True, False]
        assert np.isnan(frames[6][1].positions[4].x)


def write_trial_bag_path(trial, path):
    write_trial_bag(trial, path)
    return path


def test_negative_residual_marks_a_marker_invalid():
    path = real_file("walk_amti_eb015pi.c3d")
    trial = read_c3d(path)
    residual = ezc3d.c3d(str(path))["data"]["meta_points"]["residuals"][0]  # (points, frames)
    assert (residual < 0).any(), "this file has occlusions (residual -1)"
    assert (~trial.markers.valid).sum() == (residual[: len(trial.markers.names)].T < 0).sum()
    assert np.isnan(trial.markers.positions_m[~trial.markers.valid]).all()


def test_forward_axis_detected_from_heel_to_toe_and_overridable(tmp_path):
    path = synthetic_c3d(tmp_path / "s.c3d")
    auto = read_c3d(path, markers_only=True)
    assert (auto.axes.forward, auto.axes.up) == ("+X", "+Z") and "heel-to-toe" in auto.axes.reason
    given = read_c3d(path, markers_only=True, forward="-Y", up="+Z")
    c7 = given.markers.names.index("C7")
    # file (x, y, z) = (0.1, 0.2, 1.4) m -> lab x = -y = -0.2, lab y = up x forward applied = x = 0.1
    assert given.markers.positions_m[0, c7] == pytest.approx([-0.2, 0.1, 1.4])
    with pytest.raises(C3DError, match="not perpendicular"):
        read_c3d(path, markers_only=True, forward="+Z", up="+Z")


def test_c3d_without_force_plates_is_a_clear_error(tmp_path):
    path = synthetic_c3d(tmp_path / "markers_only.c3d")
    with pytest.raises(C3DError, match="has no force plates") as err:
        read_c3d(path)
    assert "markers_only.c3d" in str(err.value)


def test_plate_index_that_does_not_exist():
    with pytest.raises(C3DError, match=r"--feet-plate 7 does not exist: it has 4 \(indices 0..3\)"):
        read_c3d(real_file("sts_child_vicon_01.c3d"), feet_plate=7)


def test_not_a_c3d_file(tmp_path):
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(b"\x00" * 64)
    with pytest.raises(C3DError, match="bad.c3d"):
        read_c3d(bad)


def test_a_truncated_file_is_refused_not_read_in_part(tmp_path):
    """A copy cut half way: ezc3d reads 44 of its 91 frames and rewrites its own header to match; the raw header
    still says 91, and the import says the file is truncated."""
    whole = real_file("sts_child_vicon_01.c3d").read_bytes()
    cut = tmp_path / "cut.c3d"
    cut.write_bytes(whole[: len(whole) // 2])
    with pytest.raises(C3DError, match="announces 91 frames, the file holds 44: it is truncated"):
        read_c3d(cut, feet_plate=2)
