"""Robot files as description repositories ship them: meshes named by the URDF's own package
(``package://h1_description/meshes/...`` in unitree_ros's ``robots/h1_description/urdf/h1.urdf``), a ``<mujoco>``
block of the file's own, and meshes found nowhere."""

from __future__ import annotations

from pathlib import Path

import mujoco
import pytest

from sit2stand.robot.mujoco_urdf import urdf_for_mujoco
from sit2stand.robot.packages import mesh_uris_to_files, resolve_uri
from sit2stand.robot.profile import load_profile

from test_profile import copied_profile

G1_MESHES = "package://example-robot-data/robots/g1_description/meshes/"


def g1_as_a_package(root: Path, package: str = "g1_pkg", mujoco_block: bool = True) -> Path:
    """G1's URDF in a description repository's layout, ``root/robots/<package>/urdf/g1.urdf``, naming its meshes
    ``package://<package>/meshes/...`` (the folder a link to G1's), with a ``<mujoco>`` block of its own."""
    g1 = load_profile("g1").urdf
    folder = root / "robots" / package
    (folder / "urdf").mkdir(parents=True)
    (folder / "meshes").symlink_to(g1.parent.parent / "meshes")
    text = g1.read_text().replace(G1_MESHES, f"package://{package}/meshes/")
    if mujoco_block:
        text = text.replace("<robot name=\"g1_29dof_rev_1_0\">",
                            "<robot name=\"g1_29dof_rev_1_0\">\n  <mujoco>\n    <compiler meshdir=\"../meshes\" "
                            "discardvisual=\"false\"/>\n  </mujoco>", 1)
        assert "<mujoco>" in text
    urdf = folder / "urdf" / "g1.urdf"
    urdf.write_text(text)
    return urdf


def test_meshes_of_the_urdfs_own_package_and_its_mujoco_block_compile(tmp_path):
    urdf = g1_as_a_package(tmp_path)
    profile = load_profile(str(copied_profile(tmp_path, name="g1_pkg", urdf=str(urdf))))
    text = urdf_for_mujoco(profile)
    assert text.count("<mujoco>") == 1 and "package://" not in text
    model = mujoco.MjModel.from_xml_string(text)
    assert model.nmesh > 20 and model.njnt == 29          # the free joint is the plant's to add


def test_a_package_is_found_in_ros_package_path(tmp_path, monkeypatch):
    g1_as_a_package(tmp_path / "repo")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    with pytest.raises(FileNotFoundError, match="ROS_PACKAGE_PATH"):
        resolve_uri("package://g1_pkg/meshes/pelvis.STL", elsewhere)
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "repo" / "robots"))
    assert resolve_uri("package://g1_pkg/meshes/pelvis.STL", elsewhere).is_file()


def test_a_mesh_found_nowhere_names_the_urdf_and_the_uri(tmp_path):
    urdf = g1_as_a_package(tmp_path, mujoco_block=False)
    broken = urdf.read_text().replace("package://g1_pkg/meshes/pelvis.STL", "package://g1_pkg/meshes/no_pelvis.STL")
    with pytest.raises(FileNotFoundError, match=r"g1\.urdf: mesh package://g1_pkg/meshes/no_pelvis\.STL: no file"):
        mesh_uris_to_files(broken, urdf)
    with pytest.raises(FileNotFoundError, match=r"g1\.urdf: mesh package://nowhere_pkg/x\.STL: package 'nowhere_pkg'"):
        mesh_uris_to_files(broken.replace("package://g1_pkg/meshes/no_pelvis", "package://nowhere_pkg/x"), urdf)
