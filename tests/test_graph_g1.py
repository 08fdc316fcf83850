"""Unitree G1 in the live capture graph: serve-c3d -> mocap_bridge -> human_com -> retargeter -> driver (G1) ->
recorder, with ``robot:=g1`` the only change; the bag carries G1's description and frame tree."""

from pathlib import Path

import pytest

from sit2stand.capture.rehearsal import LiveRunError, run_live
from sit2stand.io.bag import BagReader

pytestmark = pytest.mark.graph
ROOT = Path(__file__).resolve().parents[1]


def test_g1_stands_up_live_and_its_bag_carries_its_urdf_and_frames(tmp_path, ros_env, elderly_calibration):
    calibration = elderly_calibration
    try:
        run = run_live(tmp_path, ros_env, calibration, ROOT / "bags" / "elderly", robot="g1")
    except LiveRunError as err:
        pytest.fail(str(err))
    assert "Unitree G1 (29 DoF) seated on a 0.231 m chair; plant g1_cad" in run.log, run.log[-4000:]
    assert run.stood_up, f"{run.report}\n{run.log[-3000:]}"
    with BagReader(tmp_path / "run") as bag:
        _, description = bag.read("/robot_description")[0]
        _, state = bag.read("/robot/joint_states")[0]
        _, tf = bag.read("/tf")[0]
    assert '<robot name="g1_29dof_rev_1_0"' in description.data and "floating_base_joint" not in description.data
    assert state.header.frame_id == "pelvis" and len(state.name) == 29
    assert (tf.transforms[0].header.frame_id, tf.transforms[0].child_frame_id) == ("world", "pelvis")
