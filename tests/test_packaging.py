"""The Python package is an ament_python package: colcon installs each node where `ros2 run sit2stand <node>` looks."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT
from sit2stand.launch import OUR_NODES


@pytest.mark.timeout(180)
def test_colcon_builds_src_as_an_ament_python_package(tmp_path):
    colcon = Path(sys.prefix) / "bin" / "colcon"
    if not colcon.exists():
        pytest.skip("colcon is not installed in this environment")
    env = dict(os.environ, PATH=f"{Path(sys.prefix) / 'bin'}:{os.environ['PATH']}")
    src = tmp_path / "src"
    shutil.copytree(ROOT / "src", src, ignore=shutil.ignore_patterns("*.egg-info", "__pycache__", "build"))
    result = subprocess.run([str(colcon), "--log-base", "log", "build", "--base-paths", str(src), "--build-base",
                             "build", "--install-base", "install"], cwd=tmp_path, env=env, capture_output=True,
                            text=True, timeout=170)
    assert result.returncode == 0, result.stdout + result.stderr
    prefix = tmp_path / "install" / "sit2stand"
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "sit2stand").exists()
    assert (prefix / "share" / "sit2stand" / "package.xml").exists()
    for node in sorted(OUR_NODES):
        exe = prefix / "lib" / "sit2stand" / node
        assert exe.exists() and os.access(exe, os.X_OK), f"ros2 run sit2stand {node} would not find {exe}"
    xml = list(prefix.rglob("replayer_fastdds.xml"))
    assert xml, "the replayer's Fast DDS profile must be installed with the package"
