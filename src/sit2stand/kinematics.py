"""Kinematics shared by the human skeleton fit and the robot IK: many points' Jacobians at once.

Both fit marker points fixed to links, and both need, per Gauss-Newton step, the world positions of tens of frame
origins and their linear Jacobians. Asking Pinocchio frame by frame (``getFrameJacobian``) costs a Python call per
marker; here they come from one ``computeJointJacobians`` by the rigid-body relation ``v_p = v_O + omega x p``
(world-frame joint Jacobians, ``data.J``), masked to each point's supporting joints.

Units SI; world frame (REP-103).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin


class PointJacobians:
    """Positions and world linear Jacobians of frame origins (markers), for any subset of frames.

    Call after ``pin.computeJointJacobians(model, data, q)`` and ``pin.updateFramePlacements(model, data)``.
    Equal to ``pin.getFrameJacobian(model, data, f, pin.LOCAL_WORLD_ALIGNED)[:3]`` frame by frame.
    """

    def __init__(self, model: pin.Model) -> None:
        self.model = model
        self.nv = model.nv
        self._masks: dict[int, np.ndarray] = {}
        self._mask_sets: dict[tuple[int, ...], np.ndarray] = {}

    def support_mask(self, frame_id: int) -> np.ndarray:
        """(nv,) 1 on the velocity coordinates that move this frame, 0 elsewhere."""
        mask = self._masks.get(frame_id)
        if mask is None:
            model = self.model
            mask = np.zeros(self.nv)
            for j in model.supports[model.frames[frame_id].parentJoint]:
                if j > 0:
                    mask[model.joints[j].idx_v:model.joints[j].idx_v + model.joints[j].nv] = 1.0
            self._masks[frame_id] = mask
        return mask

    def __call__(self, data: pin.Data, frame_ids) -> tuple[np.ndarray, np.ndarray]:
        """World positions (M, 3) [m] and linear Jacobians (M, 3, nv) [m per unit of v] of ``frame_ids``."""
        fids = tuple(frame_ids)
        P = positions(data, fids)
        masks = self._mask_sets.get(fids)
        if masks is None:
            masks = self._mask_sets[fids] = np.array([self.support_mask(int(f)) for f in fids]).reshape(-1, self.nv)
        # v_p = v_O + omega x p = v_O - [p]x omega, for all points in one batched product
        S = np.zeros((len(P), 3, 3))
        S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = P[:, 2], -P[:, 1], P[:, 0]
        S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = -P[:, 2], P[:, 1], -P[:, 0]
        J = data.J[:3] + S @ data.J[3:]
        J *= masks[:, None, :]
        return P, J


def positions(data: pin.Data, frame_ids) -> np.ndarray:
    """World positions (M, 3) [m] of frames (after ``updateFramePlacements`` or ``framesForwardKinematics``)."""
    P = np.empty((len(frame_ids), 3))
    oMf = data.oMf
    for i, f in enumerate(frame_ids):
        P[i] = oMf[f].translation
    return P
