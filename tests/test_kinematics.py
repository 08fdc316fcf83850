"""sit2stand.kinematics: many markers' positions and Jacobians at once equal Pinocchio's frame by frame."""

import numpy as np
import pinocchio as pin
import pytest

from sit2stand.human.skeleton import Subject, build_human
from sit2stand.kinematics import PointJacobians, positions
from sit2stand.retarget.robot import robot_setup


@pytest.mark.parametrize("which", ["talos", "human"])
def test_point_jacobians_equal_pinocchio_frame_by_frame(which):
    model = robot_setup().model if which == "talos" else build_human(Subject(1.75, 75.0)).model
    data = model.createData()
    rng = np.random.default_rng(0)
    frames = list(range(1, model.nframes))
    points = PointJacobians(model)
    for _ in range(3):
        q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
        q[3:7] = rng.normal(size=4)
        q[3:7] /= np.linalg.norm(q[3:7])
        pin.computeJointJacobians(model, data, q)
        subset = sorted(rng.choice(frames, size=20, replace=False).tolist())
        P, J = points(data, subset)           # from the joints alone: the frames' placements not yet updated
        pin.updateFramePlacements(model, data)
        for i, f in enumerate(subset):
            assert np.allclose(P[i], data.oMf[f].translation, atol=1e-12)
            assert np.allclose(J[i], pin.getFrameJacobian(model, data, f, pin.LOCAL_WORLD_ALIGNED)[:3], atol=1e-12)
        assert np.allclose(positions(data, subset), P, atol=1e-12)
