"""human/description.py: the skeleton's URDF and /tf frames against Pinocchio's model of the skeleton itself."""

import numpy as np
import pinocchio as pin
import pytest

from sit2stand.errors import InputError
from sit2stand.human.description import SkeletonFrames, human_urdf, link_names
from sit2stand.human.skeleton import Subject, build_human
from sit2stand.io.topics import HUMAN_ROOT_FRAME, LAB_FRAME


@pytest.fixture(scope="module")
def human():
    return build_human(Subject(1.62, 58.0, "female"))


def _compose(pairs, translations, rotations, frame):
    """Pose of ``frame`` in lab, composed along the transforms as tf2 does."""
    edges = {child: (parent, pin.SE3(pin.Quaternion(r[3], *r[:3]).toRotationMatrix(), t))
             for (parent, child), t, r in zip(pairs, translations, rotations)}
    X = pin.SE3.Identity()
    while frame != LAB_FRAME:
        frame, Xp = edges[frame]
        X = Xp * X
    return X


def test_every_segment_frame_is_where_pinocchio_puts_its_joint(human):
    """Random configurations: each link composed from lab along /tf equals Pinocchio's oMi within 1e-12."""
    frames = SkeletonFrames(human)
    links = link_names(human)
    data = human.model.createData()
    rng = np.random.default_rng(3)
    for _ in range(20):
        q = pin.randomConfiguration(human.model, -2 * np.ones(human.model.nq), 2 * np.ones(human.model.nq))
        q[:3] = rng.normal(size=3)
        pin.forwardKinematics(human.model, data, q)
        t, r = frames.transforms(q)
        for jid in range(1, human.model.njoints):
            X = _compose(frames.pairs, t, r, links[jid])
            np.testing.assert_allclose(X.homogeneous, data.oMi[jid].homogeneous, atol=1e-12)


def test_the_tree_is_lab_pelvis_then_segments(human):
    frames = SkeletonFrames(human)
    assert frames.pairs[0] == (LAB_FRAME, HUMAN_ROOT_FRAME)
    assert len(frames.pairs) == human.model.njoints - 1 == 33
    children = [c for _, c in frames.pairs]
    assert len(set(children)) == len(children)
    for segment in ("torso", "head", "thigh_l", "shank_r", "foot_l", "toes_r", "hand_l"):
        assert segment in children
    assert ("hip_l_y_link", "thigh_l") not in frames.pairs and ("hip_l_x_link", "thigh_l") in frames.pairs


def test_the_urdf_loads_as_the_same_joints_and_masses(human):
    """Pinocchio reads the URDF back: the same 32 revolute joints (names, placements, limits) and segment masses."""
    urdf = human_urdf(human)
    model = pin.buildModelFromXML(urdf)
    assert model.nq == human.model.nq - 7
    for jid in range(1, model.njoints):
        name = model.names[jid]
        ref = human.model.getJointId(name)
        np.testing.assert_allclose(model.jointPlacements[jid].homogeneous,
                                   human.model.jointPlacements[ref].homogeneous, atol=1e-5)
        assert model.lowerPositionLimit[jid - 1] == pytest.approx(human.model.lowerPositionLimit[ref + 5], abs=1e-5)
    total = sum(model.inertias[j].mass for j in range(model.njoints))    # the root link's on the universe
    assert total == pytest.approx(human.total_mass, rel=1e-5)
    assert urdf.count("<cylinder") == len(human.geometry)


def test_a_configuration_of_the_wrong_size_is_named(human):
    with pytest.raises(InputError, match="has 39 entries, not \\(3,\\)"):
        SkeletonFrames(human).transforms(np.zeros(3))
