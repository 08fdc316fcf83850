"""sit2stand batch: cases as rows of one table, resumable, a failing case recorded while the batch goes on; on a Ray
cluster of two nodes (a head and a worker started as their own processes), tasks run on both and a killed worker
loses no case."""

import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import psutil
import pytest

from sit2stand.batch.engine import TABLE, TABLE_CSV, read_table, run_jobs
from sit2stand.batch.standup import Setting, grid_cases, standup_jobs
from sit2stand.errors import InputError

RAY = str(Path(sys.executable).parent / "ray")


def test_a_robot_given_as_a_profile_file_keys_its_cases_by_the_files_name(tmp_path):
    """A case's key names its folder: a profile's path would make that folder a tree of the path's directories."""
    grid = tmp_path / "grid.yaml"
    grid.write_text("height_m: 1.7\nmass_kg: 65\n")
    setting = Setting(robot=str(tmp_path / "robots" / "h1.yaml"), plant="cad")
    assert [j.key for j in standup_jobs(grid_cases(grid, seed=3, setting=setting))] == ["00_natural_h1_cad"]


def test_a_grid_runs_in_process_each_case_a_row_and_a_failing_case_is_recorded_not_fatal(tmp_path):
    grid = tmp_path / "grid.yaml"
    grid.write_text("height_m: 1.7\nmass_kg: 65\nrobot: [g1, no_such_robot]\n")
    jobs = standup_jobs(grid_cases(grid, seed=3, setting=Setting(plant="default", plan="frames")))
    assert [j.key for j in jobs] == ["00_natural_g1_default", "01_natural_no_such_robot_default"]
    rows = run_jobs(jobs, tmp_path / "b", workers=1)
    ok, bad = rows
    assert (ok["status"], ok["attempts"], ok["robot"], ok["height_m"]) == ("ok", 1, "g1", 1.7)
    assert ok["stood_up"] in (True, False) and ok["time_scale"] > 0.9
    assert (bad["status"], bad["attempts"]) == ("failed", 2) and "no_such_robot" in bad["error"]
    table = read_table(tmp_path / "b")
    assert list(table["key"]) == [j.key for j in jobs] and (tmp_path / "b" / TABLE_CSV).exists()
    again = run_jobs(jobs, tmp_path / "b", workers=1)        # everything is in the table: nothing runs again
    assert [r["key"] for r in again] == [j.key for j in jobs]
    assert read_table(tmp_path / "b")["wall_s"].iloc[0] == table["wall_s"].iloc[0]


def test_a_bad_grid_names_the_file_and_the_field(tmp_path):
    grid = tmp_path / "g.yaml"
    grid.write_text("stature: [1.7]\n")
    with pytest.raises(InputError, match=f"{grid}: field 'stature': not a grid key"):
        grid_cases(grid)
    grid.write_text("style: [natural, sprint]\n")
    with pytest.raises(InputError, match="field 'style'"):
        grid_cases(grid)
    grid.write_text("height_m: [tall]\n")
    with pytest.raises(InputError, match="field 'height_m'"):
        grid_cases(grid)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _task_workers() -> list[psutil.Process]:
    """Ray worker processes running a batch case now (Ray names a busy worker after its task)."""
    out = []
    for p in psutil.process_iter(["cmdline"]):
        if any("ray::_run_task" in part for part in (p.info["cmdline"] or [])):
            out.append(p)
    return out


@pytest.fixture()
def two_nodes(tmp_path):
    """A Ray head and a worker node, each started by `ray start` as its own processes, one CPU each."""
    port = _free_port()
    # token authentication, as a lab cluster runs: one token (64 hex digits, as Ray makes them) for every process
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "token",
           "RAY_AUTH_TOKEN": secrets.token_hex(32)}
    head = subprocess.run([RAY, "start", "--head", f"--port={port}", "--num-cpus=1", "--include-dashboard=false",
                           "--disable-usage-stats"], env=env, capture_output=True, text=True, timeout=120)
    assert head.returncode == 0, head.stdout + head.stderr
    try:
        worker = subprocess.run([RAY, "start", f"--address=127.0.0.1:{port}", "--num-cpus=1"], env=env,
                                capture_output=True, text=True, timeout=120)
        assert worker.returncode == 0, worker.stdout + worker.stderr
        yield f"127.0.0.1:{port}", env
    finally:
        subprocess.run([RAY, "stop", "--force"], env=env, capture_output=True, timeout=120)


@pytest.mark.cluster
def test_a_batch_runs_on_both_nodes_and_a_killed_worker_loses_no_case(two_nodes, tmp_path):
    address, env = two_nodes
    out = tmp_path / "batch"
    cmd = [sys.executable, "-m", "sit2stand.cli", "batch", "standup", "--robot", "g1", "--cad", "--plan", "frames",
           "--address", address, "--out", str(out)]
    proc = subprocess.Popen([*cmd, "--cases", "4"], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    killed = None
    deadline = time.monotonic() + 240
    while killed is None and proc.poll() is None and time.monotonic() < deadline:
        busy = _task_workers()
        if busy:
            killed = busy[0].pid
            os.kill(killed, signal.SIGKILL)        # a worker dies in the middle of a case
        time.sleep(0.2)
    output, _ = proc.communicate(timeout=300)
    assert killed is not None, output
    table = pd.read_parquet(out / TABLE)
    assert len(table) == 4 and set(table["status"]) == {"ok"}, output
    assert table["attempts"].max() == 2, "the case whose worker was killed ran again"
    assert table["node"].nunique() == 2, f"cases ran on {table['node'].unique()}: {output}"
    assert (out / "batch.png").exists()
    resumed = subprocess.run([*cmd, "--cases", "5"], env=env, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    assert "4 of 5 cases already in" in resumed.stderr
    table = pd.read_parquet(out / TABLE)
    assert len(table) == 5 and list(table["key"][:4]) == list(pd.read_csv(out / TABLE_CSV)["key"][:4])
    shutil.rmtree(out / "cases", ignore_errors=True)
