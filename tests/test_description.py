"""robot/description.py: TALOS's URDF and the transforms of its frame tree, checked against MuJoCo's own forward
kinematics of the simulated robot (a second, independent implementation) for every link."""

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from sit2stand.io.topics import LAB_FRAME, WORLD_FRAME
from sit2stand.robot.description import (DescriptionError, FrameTree, quaternions_xyzw, robot_description,
                                         urdf_joints)
from sit2stand.robot.model import PlantConfig
from sit2stand.robot.profile import ProfileError, load_profile
from sit2stand.robot.plant import Plant

TALOS = load_profile("talos")


@pytest.fixture(scope="module")
def plant():
    return Plant(PlantConfig.load("cad"))


@pytest.fixture(scope="module")
def tree(plant):
    return FrameTree(plant.joint_names)


def _se3(translation, xyzw):
    return pin.SE3(pin.Quaternion(xyzw[3], xyzw[0], xyzw[1], xyzw[2]).toRotationMatrix(), np.asarray(translation))


def world_poses(tree, base_pose, q, root=WORLD_FRAME) -> dict[str, tuple[str, pin.SE3]]:
    """Every frame's pose in ``root`` (or in the frame its chain ends at), composed along the tree from the
    transforms (as tf2 would)."""
    t, r = tree.transforms(base_pose, q)
    edges = {c: (p, _se3(tk, rk)) for (p, c), tk, rk in zip(tree.pairs, t, r)}
    for s in tree.static_transforms():
        assert s.child not in edges, f"{s.child} has two parents"
        edges[s.child] = (s.parent, _se3(s.translation_m, s.rotation_xyzw))
    out = {}
    for frame in edges:
        X, f = pin.SE3.Identity(), frame
        while f in edges and f != root:
            p, Xp = edges[f]
            X, f = Xp * X, p
        out[frame] = (f, X)
    return out


def test_the_description_is_talos_urdf_with_its_mesh_uris():
    urdf = robot_description()
    assert '<robot name="talos"' in urdf and "package://example-robot-data/robots/talos_data/meshes/" in urdf
    assert "<mujoco>" not in urdf
    local = robot_description(meshes="file")
    assert "package://" not in local and "file:///" in local
    assert len(urdf_joints(urdf)) == 59


def test_bad_variants_and_mesh_kinds_are_named():
    with pytest.raises(ProfileError,
                       match="'talos_nope': no such robot profile file.*packaged: alexander, g1, icub, romeo"):
        robot_description("talos_nope")
    with pytest.raises(DescriptionError, match="meshes 'http'"):
        robot_description(meshes="http")
    with pytest.raises(DescriptionError, match="joints not_a_joint are not in the URDF"):
        FrameTree(["leg_left_1_joint", "not_a_joint"])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_every_link_is_where_mujoco_puts_it(plant, tree, seed):
    """Random joint positions and base pose: each of the 60 URDF links, composed from world along /tf and
    /tf_static, within 1e-12 m and 1e-12 of MuJoCo's body pose."""
    rng = np.random.default_rng(seed)
    m, d = plant.model, mujoco.MjData(plant.model)
    d.qpos[:3] = rng.normal(size=3)
    quat = rng.normal(size=4)
    d.qpos[3:7] = quat / np.linalg.norm(quat)
    d.qpos[plant.qadr] = rng.uniform(-1.5, 1.5, len(plant.qadr))
    mujoco.mj_kinematics(m, d)
    poses = world_poses(tree, d.qpos[:7], d.qpos[plant.qadr])
    checked = 0
    for i in range(1, m.nbody):
        name = m.body(i).name
        if name == "chair":
            continue
        root, X = poses[name]
        assert root == WORLD_FRAME
        np.testing.assert_allclose(X.translation, d.xpos[i], atol=1e-12, err_msg=name)
        np.testing.assert_allclose(X.rotation, d.xmat[i].reshape(3, 3), atol=1e-12, err_msg=name)
        checked += 1
    assert checked == 60
    for side in ("left", "right"):
        sole = d.site(f"sole_{side}").xpos
        np.testing.assert_allclose(poses[f"sole_{side}"][1].translation, sole, atol=1e-12)
        aligned = poses[f"sole_{side}_world_aligned"][1]
        np.testing.assert_allclose(aligned.translation, sole, atol=1e-12)
        np.testing.assert_allclose(aligned.rotation, np.eye(3), atol=1e-15)


def test_the_tree_has_one_root_and_sit2stands_frames(tree):
    """lab is the root (lab -> world identity), every link hangs from world; moving joints are 32 (TALOS reduced)."""
    poses = world_poses(tree, np.array([0, 0, 1.0, 1, 0, 0, 0]), np.zeros(32), root=LAB_FRAME)
    assert {root for root, _ in poses.values()} == {LAB_FRAME}
    assert len(tree.pairs) == 1 + 32 + 2
    static = {(s.parent, s.child): s for s in tree.static_transforms()}
    assert static[(LAB_FRAME, WORLD_FRAME)].translation_m == (0.0, 0.0, 0.0)
    assert static[("leg_left_6_link", "sole_left")].translation_m == (0.0, 0.0, -TALOS.sole.below_foot_m)
    np.testing.assert_allclose(static[("leg_left_6_link", "left_sole_link")].translation_m,
                               (0, 0, -TALOS.sole.below_foot_m))
    assert {"base_link", "leg_left_4_link", "left_sole_link", "sole_right_world_aligned"} <= set(tree.links())


def test_quaternions_of_rotation_matrices_in_all_four_branches():
    R = np.array([pin.SE3.Random().rotation for _ in range(500)] +
                 [np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1]), np.eye(3)])
    q = quaternions_xyzw(R)
    assert np.all(q[:, 3] >= 0) and np.allclose(np.linalg.norm(q, axis=1), 1)
    back = np.array([pin.Quaternion(w, x, y, z).toRotationMatrix() for x, y, z, w in q])
    np.testing.assert_allclose(back, R, atol=1e-14)
