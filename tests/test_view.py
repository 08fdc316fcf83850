"""sit2stand view: runs as Rerun recordings that Rerun's own reader opens with the robot's meshes, the chairs, the
plates and the COM in them; the mesh URIs a bag or a live Foxglove client gets."""

from pathlib import Path

import numpy as np
import pytest
from conftest import rerun_entities

from sit2stand.cli import main as sit2stand
from sit2stand.errors import InputError
from sit2stand.io.bag import BagReader
from sit2stand.forceplate import PLATE_CORNERS_KEY
from sit2stand.robot.description import robot_description
from sit2stand.robot.packages import package_asset, package_share, package_uris
from sit2stand.view.scene import load_scene, rise_time_s, run_bags

ROOT = Path(__file__).resolve().parents[1]


def _meshes(entities: dict[str, set[str]], prefix: str) -> list[str]:
    return [e for e, cols in entities.items() if e.startswith(prefix) and any(c.startswith("Asset3D:") for c in cols)]


def test_a_simulated_g1_rise_has_its_meshes_chair_com_and_the_demonstrations_plates(g1_simulated_run, tmp_path):
    rrd = tmp_path / "g1.rrd"
    assert sit2stand(["view", str(g1_simulated_run), "--save", str(rrd)]) == 0
    entities = rerun_entities(rrd)
    assert len(_meshes(entities, "/world/robot/")) >= 20, "G1's visual meshes, carried in the recording"
    for needed in ("/world/chair", "/world/robot/com", "/world/robot/planned_com", "/world/robot/cop",
                   "/world/robot/support", "/world/human/markers", "/world/human/plates/feet",
                   "/world/human/plates/feet/force", "/plots/knee/robot", "/plots/com_z/robot_planned"):
        assert needed in entities, f"{needed} missing: {sorted(entities)}"
    scene = load_scene(g1_simulated_run)
    assert [b.name for b in scene.bags] == ["retarget", "robot", "natural"], "its bags, then the demonstration"
    assert scene.robot.profile.name == "g1" and scene.chair.half_size[2] * 2 > 0.2
    seated, standing = scene.robot.com[0, 2], scene.robot.com[-1, 2]
    assert standing > seated + 0.15, f"COM {seated:.2f} -> {standing:.2f} m: the recording shows the rise"
    assert scene.robot.angles_deg["knee"][0] > 80 and scene.robot.angles_deg["knee"][-1] < 30
    t_mid = rise_time_s(scene)
    assert scene.robot.t_s[0] < t_mid < scene.robot.t_s[-1]


def test_an_imported_lab_trial_shows_its_markers_and_plates_where_the_c3d_puts_them(sts_bag, tmp_path):
    with BagReader(sts_bag) as bag:
        assert PLATE_CORNERS_KEY in bag.custom_data, "the importer keeps where the plates are"
    scene = load_scene(sts_bag)
    assert scene.robot is None and scene.markers is not None
    plates = {p.name: p for p in scene.plates}
    assert plates and all(p.corners is not None and p.corners.shape == (4, 3) for p in plates.values())
    for p in plates.values():         # a loaded plate's COP lies on it
        cop = p.cop[np.isfinite(p.cop).all(axis=1)]
        lo, hi = p.corners[:, :2].min(axis=0) - 0.01, p.corners[:, :2].max(axis=0) + 0.01
        assert len(cop) and np.all((cop[:, :2] >= lo) & (cop[:, :2] <= hi)), p.name
    rrd = tmp_path / "sts.rrd"
    assert sit2stand(["view", str(sts_bag), "--save", str(rrd)]) == 0
    entities = rerun_entities(rrd)
    assert "/world/human/markers" in entities and not _meshes(entities, "/world/robot/")
    assert {f"/world/human/plates/{name}" for name in plates} <= set(entities)


def test_a_folder_without_a_bag_is_named_in_the_error(tmp_path):
    with pytest.raises(InputError, match=f"{tmp_path}: not a bag, and no bag in it"):
        run_bags(tmp_path)
    assert sit2stand(["view", str(tmp_path), "--save", str(tmp_path / "x.rrd")]) == 2
    assert not (tmp_path / "x.rrd").exists()


def test_file_uris_go_back_to_the_package_uris_a_live_client_fetches():
    for robot in ("talos", "g1"):
        assert package_uris(robot_description(robot, "file")) == robot_description(robot, "package")


def test_the_asset_server_gives_mesh_files_of_known_packages_and_nothing_else(tmp_path):
    share = package_share("example-robot-data")
    mesh = next((share / "robots" / "talos_data" / "meshes").rglob("*.STL"))
    uri = f"package://example-robot-data/{mesh.relative_to(share).as_posix()}"
    assert package_asset(uri) == mesh.read_bytes() == package_asset(f"file://{mesh}")
    secret = tmp_path / "secret.stl"
    secret.write_bytes(b"solid x")
    assert package_asset(f"file://{secret}") is None, "a mesh outside the packages"
    assert package_asset(f"file://{share / 'robots' / 'talos_data' / 'robots' / 'talos_reduced.urdf'}") is None
    assert package_asset("package://example-robot-data/../../../../etc/passwd") is None
    assert package_asset("package://no-such-package/a.stl") is None
