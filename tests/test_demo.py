"""`make demo`'s module: its input check, where it leaves the identified parameters, and its human side run for real
(offline COM, then the replayer -> human_com -> recorder graph over DDS)."""

import json
from pathlib import Path

import pytest

from sit2stand import demo

ROOT = Path(__file__).resolve().parents[1]


def test_a_missing_demonstration_is_named_and_nothing_is_written(tmp_path, capsys):
    out = tmp_path / "demo"
    assert demo.main(["--bags", str(tmp_path / "nowhere"), "--out", str(out), "--skip-robot"]) == 2
    assert f"no demonstration bag at {tmp_path / 'nowhere'}" in capsys.readouterr().err
    assert not out.exists()


def test_the_identified_parameters_are_looked_for_in_each_robots_demo_folder(tmp_path):
    assert demo.demo_params("talos", tmp_path) == tmp_path / "runs" / "demo" / "robot" / "identified_full.yaml"
    assert demo.demo_params("g1", tmp_path) == tmp_path / "runs" / "demo_g1" / "robot" / "identified_full.yaml"


@pytest.mark.graph
def test_the_human_side_of_the_demo_writes_its_figures_and_passes_on_a_shipped_demonstration(tmp_path, ros_env, capsys):
    out = tmp_path / "demo"
    code = demo.main(["--skip-robot", "--bags", str(ROOT / "bags" / "elderly"), "--out", str(out), "--rate", "2"])
    text = capsys.readouterr().out
    assert code == 0, text[-3000:]
    summary = json.loads((out / "summary.json").read_text())["elderly"]
    assert summary["offline"]["com_rms_vs_truth_scaled_mm"] <= 10.0
    assert summary["live"]["frames"] >= 500                     # 531 marker frames in the bag
    assert summary["live"]["com_error_mean_mm"] <= 20.0
    for png in ("com_paths.png", "elderly/human_com.png"):
        assert (out / png).stat().st_size > 10_000, png
    assert "robot" not in json.loads((out / "summary.json").read_text())
