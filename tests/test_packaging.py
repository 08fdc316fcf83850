"""The package stands alone: pip builds it with its dependencies, scripts and data; colcon builds it as an
ament_python package (each node where `ros2 run sit2stand <node>` looks); nothing in it points outside it."""

import ast
import email
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from conftest import ROOT

from sit2stand.data import DataFileNotFound, folder, graph_path, names, params_path, plant_path
from sit2stand.errors import Sit2StandError
from sit2stand.launch import OUR_NODES, load_graph

SRC = ROOT / "src"
COPY_IGNORE = shutil.ignore_patterns("*.egg-info", "__pycache__", "build", "dist")
# what src/ imports -> the distribution that provides it (PyPI names, as in pyproject.toml's dependencies)
IMPORT_TO_DIST = {"numpy": "numpy", "scipy": "scipy", "matplotlib": "matplotlib", "yaml": "pyyaml",
                  "pinocchio": "pin", "proxsuite": "proxsuite", "daqp": "daqp", "mujoco": "mujoco", "ezc3d": "ezc3d",
                  "rosbags": "rosbags", "mcap": "mcap", "rclpy": "ros-jazzy-rclpy",
                  "zstandard": "mcap", "lz4": "mcap",   # mcap's own dependencies (MCAP chunk compressions)
                  "qtm_rt": "qtm-rt", "natnet": "natnet", "foxglove": "foxglove-sdk", "rerun": "rerun-sdk",
                  "ray": "ray", "pandas": "pandas", "collada": "pycollada",
                  "crocoddyl": "crocoddyl",
                  "mink": "mink", "pink": "pin-pink"}     # bench.ik_rivals: the bench-ik extra, in its own venv
# ROS interface packages and where they come from on PyPI (sit2stand_msgs and tf2_msgs: msgs/, built with colcon)
WITH_RCLPY = {"builtin_interfaces", "rcl_interfaces", "rosgraph_msgs"}
COMMON_INTERFACES = {"std_msgs", "std_srvs", "sensor_msgs", "geometry_msgs", "trajectory_msgs", "diagnostic_msgs",
                     "visualization_msgs"}
RUNTIME_DISTS = {"ros-jazzy-rclpy", "ros-jazzy-common-interfaces", "ros-jazzy-rmw-fastrtps-cpp", "rosbags", "mcap",
                 "ezc3d", "pin", "proxsuite", "daqp", "mujoco", "example-robot-data", "numpy", "scipy", "matplotlib",
                 "pyyaml", "qtm-rt", "natnet", "foxglove-sdk", "pycollada"}


def _dist_name(requirement: str) -> str:
    return re.split(r"[\s<>=!~;\[]", requirement.strip(), maxsplit=1)[0].lower().replace("_", "-")


NO_DEPS = {_dist_name(line) for line in (SRC.parent / "ros_ws" / "requirements-nodeps.txt").read_text().splitlines()
           if line.strip() and not line.startswith("#")}
"""Installed by the set-up with ``--no-deps`` (their metadata pins what conflicts with the stack): imported, but not
in pyproject.toml's dependencies, where a resolver would refuse them."""
RIVALS_SIDE = SRC / "sit2stand" / "bench" / "ik_rivals.py"
"""Runs in the venv of `make bench-ik` only: it may also import the bench-ik extra."""


def _top_level_imports(paths) -> set[str]:
    found = set()
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split(".")[0])
    return found - set(sys.stdlib_module_names) - {"sit2stand"}


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel pip builds from src/ (a copy: setuptools writes build/ beside the sources)."""
    tmp = tmp_path_factory.mktemp("wheel")
    shutil.copytree(SRC, tmp / "src", ignore=COPY_IGNORE)
    result = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                             "--disable-pip-version-check", str(tmp / "src"), "-w", str(tmp / "dist")],
                            capture_output=True, text=True, timeout=170)
    assert result.returncode == 0, result.stdout + result.stderr
    (whl,) = (tmp / "dist").glob("sit2stand-*.whl")
    return whl


@pytest.mark.timeout(180)
def test_the_wheel_declares_the_runtime_stack_scripts_and_data(wheel):
    with zipfile.ZipFile(wheel) as z:
        files = set(z.namelist())
        info = next(n for n in files if n.endswith(".dist-info/METADATA"))
        meta = email.message_from_string(z.read(info).decode())
        entry_points = z.read(info.replace("METADATA", "entry_points.txt")).decode()
    requires = [r for r in meta.get_all("Requires-Dist") if "extra ==" not in r]
    assert RUNTIME_DISTS <= {_dist_name(r) for r in requires}, requires
    assert all(re.search(r"[<>=~]", r) for r in requires), f"every dependency has a version range: {requires}"
    assert {"pytest", "pytest-timeout", "ruff"} <= {_dist_name(r) for r in meta.get_all("Requires-Dist")
                                                    if "extra == \"test\"" in r}
    assert meta["Requires-Python"] and meta["Version"] == "0.2.0" and meta["Name"] == "sit2stand"
    for script in ["sit2stand", *sorted(OUR_NODES)]:
        assert re.search(rf"^{script} = sit2stand\.", entry_points, re.M), f"console script {script} is missing"
    for kind in ("plants", "graphs", "params"):
        for name in names(kind):
            assert f"sit2stand/data/{kind}/{name}.yaml" in files, f"{kind}/{name}.yaml is not in the wheel"
    assert "sit2stand/nodes/replayer_fastdds.xml" in files
    assert "sit2stand/native/ik_kernels.c" in files, "the IK kernels' source, compiled on first use"


def test_every_third_party_import_of_src_is_a_declared_dependency():
    tomllib = pytest.importorskip("tomllib")
    project = tomllib.loads((SRC / "pyproject.toml").read_text())["project"]
    declared = {_dist_name(r) for r in project["dependencies"]} | NO_DEPS
    rivals = {_dist_name(r) for r in project["optional-dependencies"]["bench-ik"]}
    main_side = [p for p in (SRC / "sit2stand").rglob("*.py") if p != RIVALS_SIDE]
    unknown, undeclared = [], []
    imports = [(m, declared) for m in sorted(_top_level_imports(main_side))]
    imports += [(m, declared | rivals) for m in sorted(_top_level_imports([RIVALS_SIDE]))]
    for module, allowed in imports:
        if module in WITH_RCLPY:
            dist = "ros-jazzy-rclpy"
        elif module in COMMON_INTERFACES:
            dist = "ros-jazzy-common-interfaces"
        elif module in ("sit2stand_msgs", "tf2_msgs"):
            continue
        elif module in IMPORT_TO_DIST:
            dist = IMPORT_TO_DIST[module]
        else:
            unknown.append(module)
            continue
        if dist not in allowed:
            undeclared.append(f"{module} ({dist})")
    assert not unknown, f"imports with no known distribution (add them to pyproject.toml and this map): {unknown}"
    assert not undeclared, f"imported but not in pyproject.toml's dependencies: {undeclared}"


def test_package_xml_depends_on_every_ros_package_src_imports():
    xml = (SRC / "package.xml").read_text()
    exec_depends = set(re.findall(r"<exec_depend>([^<]+)</exec_depend>", xml))
    ros_imports = {m for m in _top_level_imports((SRC / "sit2stand").rglob("*.py"))
                   if m == "rclpy" or m.endswith(("_msgs", "_srvs", "_interfaces"))}
    assert ros_imports, "no ROS imports found: the scan is broken"
    assert ros_imports <= exec_depends, f"package.xml lacks {sorted(ros_imports - exec_depends)}"
    for dep in ("python3-numpy", "python3-scipy", "python3-matplotlib", "python3-yaml", "pinocchio", "proxsuite"):
        assert dep in exec_depends, f"package.xml lacks {dep}"


def test_nothing_in_the_package_points_into_the_source_repository():
    for path in (SRC / "sit2stand").rglob("*.py"):
        for i, line in enumerate(path.read_text().splitlines(), 1):
            assert "ros_ws" not in line, f"{path.relative_to(ROOT)}:{i} names ros_ws/: {line.strip()}"


def test_packaged_files_are_found_by_name_or_path(tmp_path):
    assert plant_path() == plant_path("default") == folder("plants") / "default.yaml"
    assert plant_path("heavy_front.yaml").name == "heavy_front.yaml"
    assert graph_path("standup") == folder("graphs") / "standup.yaml"
    assert params_path("recorder").read_text().startswith("#")
    assert {"standup", "human_com", "roundtrip"} <= set(names("graphs"))
    mine = tmp_path / "mine.yaml"
    mine.write_text("name: mine\n")
    assert plant_path(mine) == mine and plant_path(str(mine)) == mine
    with pytest.raises(DataFileNotFound, match="cad, default, g1_cad, g1_default, heavy_front") as err:
        plant_path("no_such_plant")
    assert isinstance(err.value, Sit2StandError) and isinstance(err.value, FileNotFoundError)
    with pytest.raises(DataFileNotFound, match="standup"):
        graph_path(tmp_path / "missing.yaml")


def test_packaged_graphs_name_their_parameter_files_and_plant():

    for name in names("graphs"):
        text = graph_path(name).read_text()
        assert "../" not in text and "$(dirname)" not in text, f"graphs/{name}.yaml reaches outside itself"
        graph = load_graph(name)
        for node in graph.nodes:
            files = [node.command[i + 1] for i, a in enumerate(node.command) if a == "--params-file"]
            assert all(Path(f).is_file() for f in files)
        graph.discard()


@pytest.mark.timeout(180)
def test_colcon_builds_src_as_an_ament_python_package(tmp_path):
    colcon = Path(sys.prefix) / "bin" / "colcon"
    if not colcon.exists():
        pytest.skip("colcon is not installed in this environment")
    env = dict(os.environ, PATH=f"{Path(sys.prefix) / 'bin'}:{os.environ['PATH']}")
    src = tmp_path / "src"
    shutil.copytree(SRC, src, ignore=COPY_IGNORE)
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
    assert list(prefix.rglob("sit2stand/data/graphs/standup.yaml")), "the packaged graphs must be installed"
    assert list(prefix.rglob("sit2stand/data/plants/default.yaml")), "the packaged plants must be installed"
