"""The whole pipeline as real processes over DDS: replayer -> human_com -> retargeter -> driver -> recorder."""

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import GRAPHS
from sit2stand.cli import main as sit2stand
from sit2stand.data import plant_path
from sit2stand.io.bag import BagReader
from sit2stand.io.messages import stamp_ns
from sit2stand.retarget.report import analyse

pytestmark = pytest.mark.graph
ROOT = Path(__file__).resolve().parents[1]


def test_the_robot_stands_up_live_from_the_shipped_elderly_demonstration(elderly_standup):
    """The short end-to-end stand-up: CAD robot, CAD parameters (the consistent case), elderly-like rise (the run
    shared with test_graph_tf)."""
    folder, result = elderly_standup
    out = folder / "run"
    log = result.stdout[-4000:] + result.stderr[-2000:]
    assert result.returncode == 0, log
    assert "[retargeter] 531 frames" in result.stdout, log
    # the graph asks for SCHED_FIFO 50 for the retargeter: granted, or refused and said so; the node reports which
    assert ("started retargeter" in result.stdout and
            ("SCHED_FIFO priority 50" in result.stdout or "was not permitted" in result.stdout)), log
    assert "scheduling SCHED_" in result.stdout, log
    assert (folder / "markers.yaml").is_file()
    with BagReader(out) as bag:
        topics = bag.topics()
        assert topics["/robot/retarget/ik"].count == 531, "one IK pose per marker frame"
        cmds = bag.read("/robot/joint_command")
        marker_t = np.array([stamp_ns(m.header) for _, m in bag.read("/mocap/markers")]) * 1e-9
        cmd_t = np.array([stamp_ns(m.header) for _, m in cmds]) * 1e-9
        # the plan's commands: after it, the retargeter re-sends the last pose at rest (zero velocities; its
        # positions still move with the COM feedback) while it holds
        held = next(i for i in range(len(cmds), 0, -1) if np.any(cmds[i - 1][1].points[0].velocities))
        ratio = np.ptp(cmd_t[:held + 1]) / np.ptp(marker_t)     # both on the replayer's clock
        assert np.ptp(cmd_t[held:]) > 2.5, "held for hold_s (3 s) of the robot's time"
        # the robot's duration over the human's: longer than the human's, and the retargeter's own figure
        reported = float(re.search(r"\[retargeter\] .* time scale ([\d.]+)", result.stdout).group(1))
        assert ratio > 1.0 and abs(ratio - reported) < 0.15 * reported, (ratio, reported)
        pos = np.array([list(m.points[0].positions) + list(m.points[0].velocities) + list(m.points[0].accelerations)
                        for _, m in cmds])
        assert np.all(np.isfinite(pos))
        base = bag.read("/robot/base_pose")
        z = np.array([m.pose.position.z for _, m in base])
        shift = np.array([[m.vector.x, m.vector.y] for _, m in bag.read("/robot/com_feedback")])
    assert z[0] < 0.65 and z[-1] > 0.85, f"pelvis from {z[0]:.2f} m to {z[-1]:.2f} m: did not stand up"
    assert "upright" in result.stdout and "FALLEN" not in result.stdout, log
    # the COM feedback: one shift per command, none while the plan is seated, bounded; the robot's COM on the plan
    assert len(shift) == len(cmds) and np.all(shift[:100] == 0.0)
    assert 0.0 < np.abs(shift).max() <= 0.03 + 1e-9
    assert "COM feedback largest shift" in result.stdout, log
    summary = analyse(out, "elderly", None, plant_path("cad")).summary
    # typically 0.6 cm; one full-suite run on the 2-core host gave 2.1 cm (a scheduling outlier, the robot standing)
    assert summary["stood_up"] and summary["com_tracking_rms_m"] < 0.03, summary
    # the posture over the rise against the human skeleton's, each at the same share of its rise: present for every
    # sagittal joint, and not a different motion (the robot's seat is lower: its knees start ~35 degrees deeper)
    rms = summary["posture_rms_deg"]
    assert set(rms) == {"trunk", "hip", "knee", "ankle"} and all(0 < v < 60 for v in rms.values()), rms


def test_under_whole_body_torque_control_the_robot_stands_up_live_near_the_humans_timing(tmp_path, ros_env):
    """controller:=wbc (the graph's default, said here): the driver runs the whole-body QP as the robot's on-board
    controller (the retargeter's COM feedback off) and reports its QP time; the elderly rise plays within 1.5x the
    human's duration (1.04 when written; joint PD with COM feedback: ~1.1)."""
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "sit2stand.cli", "launch", str(GRAPHS / "standup.yaml"),
           f"bag:={ROOT / 'bags' / 'elderly'}", f"out:={out}", f"plant:={plant_path('cad')}", "controller:=wbc"]
    result = subprocess.run(cmd, env=ros_env, capture_output=True, text=True, timeout=240)
    log = result.stdout[-4000:] + result.stderr[-2000:]
    assert result.returncode == 0, log
    assert "COM feedback off (the robot's whole-body torque controller tracks the COM)" in result.stdout, log
    qp = re.search(r"\[driver\] .*whole-body QP p50 ([\d.]+) ms p99 ([\d.]+) ms \(CPU p99 ([\d.]+) ms; (\d+) steps\)",
                   result.stdout)
    assert qp and int(qp.group(4)) > 1000 and 0 < float(qp.group(3)), log
    scale = float(re.search(r"\[retargeter\] .* time scale ([\d.]+)", result.stdout).group(1))
    assert scale < 1.5, log
    with BagReader(out) as bag:
        status = [{kv.key: kv.value for kv in m.values} for _, m in bag.read("/robot/status")]
    assert status[-1]["controller"] == "wbc" and {"qp_p99_ms", "qp_cpu_p99_ms"} <= set(status[-1]), status[-1]
    # the cad plant hides nothing: the controller's feet find its model's COM where its own is
    assert abs(float(status[-1]["com_offset_x_m"])) < 0.005, status[-1]
    summary = analyse(out, "elderly", None, plant_path("cad")).summary
    assert summary["stood_up"] and not summary["fallen"] and summary["com_tracking_rms_m"] < 0.04, summary


def test_live_the_robot_stands_and_sits_in_each_cycle_of_a_trial_with_a_brief_touch(tmp_path, ros_env):
    """Two sit-stand-sit cycles, 0.1 s on the seat between them (`synth-human --cycles`), through the stand-up graph:
    after its first sit-down the plan is seated again and the second rise plays as the first; the analysis has a
    row per cycle and judges the standing posture at the robot's highest."""
    bag, out = tmp_path / "two_cycles", tmp_path / "run"
    assert sit2stand(["synth-human", "--cycles", "2", "--seated", "0.1", "--out", str(bag)]) == 0
    cmd = [sys.executable, "-m", "sit2stand.cli", "launch", str(GRAPHS / "standup.yaml"), f"bag:={bag}",
           f"out:={out}", f"plant:={plant_path('g1_cad')}", "robot:=g1"]
    result = subprocess.run(cmd, env=ros_env, capture_output=True, text=True, timeout=240)
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    summary = analyse(out, "two_cycles", None, plant_path("g1_cad"), robot="g1").summary
    assert summary["stood_up"] and summary["sat_down"] and not summary["fallen"], summary
    assert [(c["stood"], c["sat"]) for c in summary["cycles"]] == [(True, True), (True, True)], summary["cycles"]


def test_marker_frames_without_a_human_com_stop_the_retargeter_with_a_clear_error(tmp_path, run_node):
    """A demonstration played without any /human/com: the node names what it waited for and exits 2."""
    node = run_node("sit2stand.nodes.retargeter", "--ros-args", "-p", "wait_for_robot:=false",
                    "-p", "input_timeout_s:=3.0")
    play = run_node("sit2stand.nodes.replayer", "--ros-args", "-p", f"bag:={ROOT / 'bags' / 'elderly'}",
                    "-p", "wait_for:=['/mocap/markers:1']", "-p", "wait_timeout_s:=60.0", "-p", "publish_clock:=false")
    assert play.wait(120) == 0, play.output
    assert node.wait(60) == 2, node.output
    assert "waited 3 s for /human/com" in node.output


def test_a_bad_parameters_file_stops_the_retargeter_at_start_naming_it(tmp_path, run_node):
    """The robot model is built when the node starts (not on the first frame): a broken identified-parameters file
    is reported then, by name."""
    (tmp_path / "params.yaml").write_text("not: [a parameter file\n")
    node = run_node("sit2stand.nodes.retargeter", "--ros-args", "-p", f"controller_params:={tmp_path / 'params.yaml'}")
    assert node.wait(60) == 2, node.output
    assert "params.yaml" in node.output and "controller_params" in node.output


def test_an_unknown_on_board_controller_stops_the_driver_and_the_retargeter_naming_it(run_node):
    driver = run_node("sit2stand.nodes.driver", "--ros-args", "-p", "controller:=torque")
    retargeter = run_node("sit2stand.nodes.retargeter", "--ros-args", "-p", "controller:=torque")
    for node in (driver, retargeter):
        assert node.wait(60) == 2, node.output
        assert "controller 'torque'" in node.output and "wbc" in node.output, node.output


def test_a_marker_rate_no_capture_has_stops_the_estimator_and_the_retargeter_naming_it(run_node):
    nodes = [run_node(f"sit2stand.nodes.{name}", "--ros-args", "-p", "rate_hz:=0.0") for name in ("human_com",
                                                                                                  "retargeter")]
    for node in nodes:
        assert node.wait(60) == 2, node.output
        assert "rate_hz 0.0: a capture rate of at least 20 Hz" in node.output, node.output
