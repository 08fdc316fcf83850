"""sit2stand.retarget.export: a simulated stand-up as CSV rows and NPZ arrays a learning pipeline reads, exactly."""

from pathlib import Path

import mujoco
import numpy as np
import pytest

from sit2stand.errors import InputError
from sit2stand.retarget.export import export, read_states
from sit2stand.robot.model import PlantConfig
from sit2stand.robot.plant import Plant

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def g1_run(g1_simulated_run):
    return g1_simulated_run


def test_the_csv_has_a_row_per_frame_that_replays_the_simulated_joints_exactly(g1_run, tmp_path):
    done = export(g1_run, tmp_path / "m.csv", "csv", rate_hz=50.0)
    states = read_states(g1_run)                   # 100 Hz: every second state is a 50 Hz frame
    span = states.t_s[-1] - states.t_s[0] + 0.01
    rows = np.loadtxt(tmp_path / "m.csv", delimiter=",")
    assert done["robot"] == "g1" and len(rows) == done["frames"] == round(span * 50)
    assert rows.shape[1] == 3 + 4 + 29
    plant = Plant(PlantConfig(robot="g1"), with_chair=False)
    names = plant.joint_names                      # the profile's actuated order
    for k in (0, len(rows) // 2, len(rows) - 1):
        state = 2 * k
        np.testing.assert_array_equal(rows[k, 7:], [states.q[state, states.joint_names.index(n)] for n in names])
        np.testing.assert_array_equal(rows[k, :3], states.root_pos[state])
        x, y, z, w = rows[k, 3:7]
        plant.data.qpos[:7] = [*rows[k, :3], w, x, y, z]
        plant.data.qpos[plant.qadr] = rows[k, 7:]
        mujoco.mj_kinematics(plant.model, plant.data)
        np.testing.assert_allclose(plant.data.site("pelvis").xpos, rows[k, :3], atol=1e-12)


def test_the_npz_names_its_arrays_and_ends_standing_on_both_feet(g1_run, tmp_path):
    export(g1_run, tmp_path / "m.npz", "npz", rate_hz=30.0)
    d = np.load(tmp_path / "m.npz")
    n = len(d["root_pos"])
    assert float(d["fps"]) == 30.0 and d["dof_pos"].shape == d["dof_vel"].shape == (n, 29)
    assert d["root_quat_xyzw"].shape == (n, 4) and d["com"].shape == (n, 3)
    assert d["body_pos"].shape == (n, len(d["body_names"]), 3) and "left_knee_link" in list(d["body_names"])
    assert d["foot_contacts"][-1].all() and d["com"][-1, 2] > d["com"][0, 2] + 0.15     # stood up on both feet
    assert list(d["joint_names"][:2]) == ["left_hip_pitch_joint", "left_hip_roll_joint"]


def test_export_names_what_it_cannot_read(tmp_path):
    with pytest.raises(InputError, match="natural: no /robot/joint_states: not a simulated stand-up"):
        export(ROOT / "bags" / "natural", tmp_path / "m.csv")
