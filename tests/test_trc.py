"""sit2stand.io.trc: OpenSim TRC markers and .mot ground reaction forces in SI units and REP-103 (subject01 of
OpenSim's Gait2392 example, read in place from ../shared); import-trc and human-com on it; bad input fails clearly."""

import json

import numpy as np
import pytest

from conftest import real_file
from sit2stand.cli import main
from sit2stand.human.offline import read_trial
from sit2stand.io.bag import BagReader
from sit2stand.forceplate import center_of_pressure, shift_moment
from sit2stand.io.topics import SUBJECT_TOPIC
from sit2stand.io.trc import OPENSIM_AXES, TrcError, read_grf_mot, read_opensim_trial, read_trc

G = 9.81
MASS_KG = 72.6


def test_opensim_axes_map_y_up_to_rep103():
    R = OPENSIM_AXES.rotation()
    np.testing.assert_array_equal(R @ [1, 2, 3], [1, -3, 2])          # (x, y, z) -> (x, -z, y)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_subject01_markers_in_metres_facing_x_left_y_up_z():
    m = read_trc(real_file("subject01_walk1.trc"))
    assert (len(m.names), m.positions_m.shape[0], m.rate_hz, m.t0_s) == (41, 151, 60.0, 0.0)
    assert m.valid.all()
    p = {n: m.positions_m[:, i] for i, n in enumerate(m.names)}
    assert np.all(p["R.Heel"][:, 2] < p["R.ASIS"][:, 2] - 0.7) and np.all(p["L.Heel"][:, 2] < p["L.ASIS"][:, 2] - 0.7)
    assert 1.7 < np.median(p["Top.Head"][:, 2]) < 1.85
    assert np.all(p["L.ASIS"][:, 1] > p["R.ASIS"][:, 1])               # left is +y
    assert np.all(p["L.ASIS"][:, 0] > p["V.Sacral"][:, 0])             # facing +x: the sacrum behind the ASIS
    assert np.mean(p["R.Toe.Tip"][:, 0] - p["R.Heel"][:, 0]) > 0.15    # toes ahead of the heel


def test_subject01_plates_weigh_the_subject_with_gravity_along_minus_z():
    plates = read_grf_mot(real_file("subject01_walk1_grf.mot"))
    assert [p.name for p in plates] == ["plate0", "plate1"] and [p.index for p in plates] == [0, 1]
    for p in plates:
        assert len(p.t_s) == 1501 and p.rate_hz == pytest.approx(600.0)
        assert np.allclose(np.diff(p.t_s), 1 / 600)                     # 0.0017, 0.0033, ... back on the grid
    force = plates[0].force_n + plates[1].force_n
    # the reaction holds the body up (+z); over the trial's two gait cycles it averages the weight: 72.9 kg
    assert force[:, 2].min() > 0.7 * MASS_KG * G * 0.9
    assert np.mean(force[:, 2]) / G == pytest.approx(MASS_KG, rel=0.01)
    assert abs(np.mean(force[:, 0])) < 10 and abs(np.mean(force[:, 1])) < 10


def test_subject01_cop_is_under_the_stance_foot_and_the_wrench_is_about_the_origin():
    trial = read_opensim_trial(real_file("subject01_walk1.trc"), real_file("subject01_walk1_grf.mot"))
    m, right = trial.markers, trial.plates[0]
    heel, toe = (m.positions_m[:, m.names.index(n)] for n in ("R.Heel", "R.Toe.Tip"))
    k = np.searchsorted(right.t_s, m.times_s)                           # plate samples at the marker frames
    stance = right.force_n[k, 2] > 500
    assert stance.sum() > 40
    cop = right.cop_m[k][stance]
    assert np.all(cop[:, 0] > heel[stance, 0] - 0.03) and np.all(cop[:, 0] < toe[stance, 0] + 0.03)
    assert np.all(np.abs(cop[:, 1] - heel[stance, 1]) < 0.06) and np.all(cop[:, 1] < 0)   # the right foot: -y
    # the moment about the lab origin gives back the same COP on the plate's surface (z = -7.5 mm here)
    ok = right.cop_valid
    surface = np.array([0.0, 0.0, np.median(right.cop_m[ok, 2])])
    moment = shift_moment(right.moment_origin_nm[ok], right.force_n[ok], np.zeros(3), surface)
    again, _, tau = center_of_pressure(right.force_n[ok], moment, surface, np.array([0, 0, 1.0]))
    np.testing.assert_allclose(again, right.cop_m[ok], atol=1e-9)
    np.testing.assert_allclose(tau, right.free_moment_nm[ok], atol=1e-9)


def _trc(path, units="mm", rows=("1\t0.00\t1\t2\t3\t4\t5\t6", "2\t0.01\t\t\t\t4\t5\t6", "4\t0.03\t1\t2\t3")):
    path.write_text("PathFileType\t4\t(X/Y/Z)\tx.trc\n"
                    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\n"
                    f"100.00\t100.00\t{len(rows)}\t2\t{units}\n"
                    "Frame#\tTime\tA\t\t\tB\t\t\n\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n\n" + "\n".join(rows) + "\n")
    return path


def test_trc_units_blanks_gaps_and_short_rows(tmp_path):
    m = read_trc(_trc(tmp_path / "a.trc", units="m"))
    assert m.positions_m.shape == (4, 2, 3) and m.rate_hz == 100.0          # frame 3 is missing: a NaN frame
    np.testing.assert_array_equal(m.valid, [[True, True], [False, True], [False, False], [True, False]])
    np.testing.assert_allclose(m.positions_m[0, 0], [1, -3, 2])             # metres, OpenSim axes -> REP-103
    assert np.isnan(m.positions_m[1, 0]).all() and np.isnan(m.positions_m[3, 1]).all()
    np.testing.assert_allclose(read_trc(_trc(tmp_path / "b.trc", units="mm")).positions_m[0, 1], [4e-3, -6e-3, 5e-3])
    np.testing.assert_allclose(read_trc(_trc(tmp_path / "c.trc", units="cm")).positions_m[0, 0], [0.01, -0.03, 0.02])


@pytest.mark.parametrize("units, match", [("furlong", "unknown length unit 'furlong'"), ("", "unknown length unit")])
def test_trc_errors_name_the_file_and_field(tmp_path, units, match):
    with pytest.raises(TrcError, match=match):
        read_trc(_trc(tmp_path / "u.trc", units=units))
    (tmp_path / "n.trc").write_text("hello\n" * 8)
    with pytest.raises(TrcError, match="n.trc: not a TRC file"):
        read_trc(tmp_path / "n.trc")


def test_mot_errors_name_the_missing_columns(tmp_path):
    path = tmp_path / "g.mot"
    path.write_text("g\nversion=1\nnRows=2\nnColumns=4\nendheader\ntime\tground_force_vx\tground_force_vy\t"
                    "ground_force_vz\n0\t1\t2\t3\n0.1\t1\t2\t3\n")
    with pytest.raises(TrcError, match=r"plate \(no prefix\) lacks the column\(s\) ground_force_px, ground_force_py"):
        read_grf_mot(path)
    path.write_text("g\nendheader\ntime\tfoo\n0\t1\n")
    with pytest.raises(TrcError, match="no ground_force_v"):
        read_grf_mot(path)


def test_import_trc_then_human_com_with_gait2392(tmp_path, capsys):
    bag, out = tmp_path / "bag", tmp_path / "out"
    assert main(["import-trc", str(real_file("subject01_walk1.trc")), "--grf",
                 str(real_file("subject01_walk1_grf.mot")), "--mass", str(MASS_KG), "--height", "1.8",
                 "--out", str(bag)]) == 0
    trial = read_trial(bag)
    assert (trial.height_m, trial.mass_kg, len(trial.marker_names)) == (1.8, MASS_KG, 41)
    assert sorted(p.name for p in trial.plates) == ["plate0", "plate1"]
    with BagReader(bag) as b:                          # the subject in the stream too, for a live human_com
        ((_, subject),) = b.read(SUBJECT_TOPIC)
    assert (subject.height_m, subject.mass_kg) == (1.8, MASS_KG)
    assert main(["human-com", str(bag), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["marker_set"] == "gait2392" and summary["frames_fitted"] == 151
    assert summary["newton_residual_rms_xyz_n"][2] < 25.0                 # measured 15.7 N
    com = np.genfromtxt(out / "com.csv", delimiter=",", names=True)
    assert com.dtype.names == ("t", "x", "y", "z", "vx", "vy", "vz", "ax", "ay", "az", "valid") and len(com) == 151
    assert com["valid"].all() and np.all((com["z"] > 0.85) & (com["z"] < 1.2))
    angles = (out / "joint_angles.csv").read_text().splitlines()
    assert angles[0].startswith("t,pelvis_tx,pelvis_ty,pelvis_tz,pelvis_rz,pelvis_ry,pelvis_rx,lumbar_y")
    sto = (out / "human_states.sto").read_text().splitlines()
    end = sto.index("endheader")
    assert sto[:5] == ["human_states", "version=1", "nRows=151", "nColumns=45", "inDegrees=no"]
    labels = sto[end + 1].split("\t")
    assert labels[0] == "time" and labels[-6:] == ["com_x", "com_y", "com_z", "com_vx", "com_vy", "com_vz"]
    rows = np.array([line.split("\t") for line in sto[end + 2:]], float)
    assert rows.shape == (151, 45)
    np.testing.assert_allclose(rows[:, labels.index("com_z")], com["z"], atol=1e-8)
    assert "marker set gait2392" in capsys.readouterr().out
