"""Graph tests of the human COM estimator: replayer -> human_com -> recorder, real processes over DDS."""

import subprocess
import sys

import numpy as np
import pytest

from conftest import GRAPHS, real_file
from sit2stand.cli import main
from sit2stand.io.topics import MARKERS_TOPIC, MOCAP_TYPE
from sit2stand.human.demonstration_bag import write_demonstration_bag
from sit2stand.human.synth import SynthConfig, synthesize
from sit2stand.io import messages as M
from sit2stand.io.bag import BagReader, BagWriter

pytestmark = pytest.mark.graph


def series(bag, topic):
    msgs = bag.read(topic)
    t = np.array([M.stamp_ns(m.header) for _, m in msgs]) * 1e-9
    return t, np.array([[m.position.x, m.position.y, m.position.z] for _, m in msgs]), msgs


def test_live_human_com_in_a_graph(tmp_path, ros_env):
    demo = synthesize(SynthConfig(style="natural", seed=6, stand_after_s=0.8))
    write_demonstration_bag(demo, tmp_path / "demo")
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "sit2stand.cli", "launch", str(GRAPHS / "human_com.yaml"), f"bag:={tmp_path / 'demo'}",
           f"out:={out}", "height:=1.75", f"mass:={demo.human.total_mass:.3f}"]
    result = subprocess.run(cmd, env=ros_env, capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "per-frame cost p50" in result.stdout
    with BagReader(out) as bag:
        t, com, msgs = series(bag, "/human/com")
        tg, truth, _ = series(bag, "/ground_truth/com")
        assert len(msgs) == len(demo.marker_t_s), "one COM per marker frame"
        assert all(m.source == "skeleton_fit" for _, m in msgs)
        truth_i = np.array([np.interp(t, tg, truth[:, i]) for i in range(3)]).T
        err = np.linalg.norm(com - truth_i, axis=1)
        assert np.mean(err[t - t[0] > 1.0]) < 0.02, f"live COM error {np.mean(err) * 1e3:.1f} mm"
        assert bag.topics()["/human/scaling"].count >= 1
        assert bag.topics()["/human/joint_states"].count == len(msgs)
        # the model COP starts after the 50 calibration frames and lags half a 31-frame window
        assert bag.topics()["/human/model_cop"].count >= len(msgs) - 50 - 31


def test_a_60_hz_trial_plays_through_the_graph_in_lockstep_without_stalls(tmp_path, ros_env):
    """OpenSim's 60 Hz walk in the human COM graph (rate_hz:=60): the replayer's clock leads the estimator by one
    60 Hz frame, not the 10 ms of a 100 Hz one, under which every frame waited out the 10 s stall timeout."""
    bag = tmp_path / "walk"
    trc, mot = real_file("subject01_walk1.trc"), real_file("subject01_walk1_grf.mot")
    assert main(["import-trc", str(trc), "--grf", str(mot), "--mass", "72.6", "--height", "1.8", "--out", str(bag)]) \
        == 0
    cmd = [sys.executable, "-m", "sit2stand.cli", "launch", str(GRAPHS / "human_com.yaml"), f"bag:={bag}",
           f"out:={tmp_path / 'run'}", "rate_hz:=60"]
    result = subprocess.run(cmd, env=ros_env, capture_output=True, text=True, timeout=120)
    log = result.stdout[-3000:] + result.stderr[-3000:]
    assert result.returncode == 0, log
    assert "by at most 16.8333 ms" in result.stdout and "for a while" not in result.stdout, log
    with BagReader(tmp_path / "run") as out:
        assert out.topics()["/human/com"].count == 151


def test_too_few_markers_stop_the_node_with_a_clear_error(tmp_path, ros_env, run_node):
    with BagWriter(tmp_path / "few") as bag:
        bag.add_topic(MARKERS_TOPIC, MOCAP_TYPE)
        for k in range(50):
            t = 10_000_000_000 + k * 10_000_000
            bag.write(MARKERS_TOPIC, t, M.mocap_frame(t, ["LASI", "RASI", "LPSI", "FOO", "BAR"], np.ones((5, 3)),
                                                        np.ones(5, bool)))
    node = run_node("sit2stand.nodes.human_com", "--ros-args", "-p", "height_m:=1.75", "-p", "mass_kg:=75.0")
    assert node.wait_for_output("waiting for", 60), node.output
    play = run_node("sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={tmp_path / 'few'}",
                    "-p", "wait_for_subscribers:=1", "-p", "wait_timeout_s:=60.0")
    assert node.wait(120) == 2, node.output
    assert "/mocap/markers" in node.output and "at least 8 are needed" in node.output
    play.stop()


def test_a_bad_calibration_file_stops_the_node_naming_it(tmp_path, run_node):
    (tmp_path / "cal.yaml").write_text("lengths: {thigh: 1.0}\n")      # no marker placements
    node = run_node("sit2stand.nodes.human_com", "--ros-args", "-p", f"calibration_file:={tmp_path / 'cal.yaml'}")
    assert node.wait(30) != 0, node.output
    assert "calibration_file" in node.output and "cal.yaml" in node.output


def test_the_node_on_opensims_gait2392_markers_with_the_subject_from_the_bag(tmp_path, run_node):
    """subject01 (OpenSim's Gait2392 set, 41 markers at 60 Hz, no chair) imported with import-trc: the node takes the
    marker set as a parameter and the subject from /human/subject (no height_m/mass_kg given)."""
    bag = tmp_path / "walk"
    trc, mot = real_file("subject01_walk1.trc"), real_file("subject01_walk1_grf.mot")
    assert main(["import-trc", str(trc), "--grf", str(mot), "--mass", "72.6", "--height", "1.8", "--out", str(bag)]) \
        == 0
    node = run_node("sit2stand.nodes.human_com", "--ros-args", "-p", "marker_set:=gait2392", "-p", "rate_hz:=60.0",
                    "-p", "calibration_frames:=20", "-p", "chair_on_plate:=false", "-p", "viz_rate_hz:=0.0")
    assert node.wait_for_output("waiting for", 60), node.output
    play = run_node("sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={bag}", "-p", "wait_for_subscribers:=1",
                    "-p", "wait_timeout_s:=60.0")
    assert play.wait(120) == 0, play.output
    assert node.stop() == 0, node.output         # after a signal it finishes the frames already received
    out = node.output
    assert "subject from /human/subject: 1.8 m, 72.6 kg" in out
    assert "marker set gait2392: 41 of the stream's 41 markers" in out
    assert "[human_com] 151 frames, 0 skipped" in out, out


def test_a_capture_at_another_rate_than_the_nodes_stops_it_saying_which(tmp_path, run_node):
    """The same 60 Hz trial with the node left at its 100 Hz: its filters would run 1.7x too fast; it stops within
    its first frames, naming the topic, both rates and the parameter to set."""
    bag = tmp_path / "walk"
    trc, mot = real_file("subject01_walk1.trc"), real_file("subject01_walk1_grf.mot")
    assert main(["import-trc", str(trc), "--grf", str(mot), "--mass", "72.6", "--height", "1.8", "--out", str(bag)]) \
        == 0
    node = run_node("sit2stand.nodes.human_com", "--ros-args", "-p", "marker_set:=gait2392", "-p",
                    "chair_on_plate:=false", "-p", "calibration_frames:=20", "-p", "viz_rate_hz:=0.0")
    assert node.wait_for_output("waiting for", 60), node.output
    play = run_node("sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={bag}", "-p", "wait_for_subscribers:=1",
                    "-p", "wait_timeout_s:=60.0")
    assert node.wait(120) == 2, node.output
    assert "/mocap/markers: frames stamped every 16.67 ms (60.0 Hz), but rate_hz is 100 Hz" in node.output, node.output
    assert "rate_hz:=60" in node.output
    play.stop()
