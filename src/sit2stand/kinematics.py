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


_SKEW_AT = [1, 2, 5, 3, 6, 7]
"""Entries of a row-major 3 x 3 matrix that -[p]x fills, from p's coordinates ``_SKEW_FROM`` with ``_SKEW_SIGN``."""
_SKEW_FROM = [2, 1, 0, 2, 1, 0]
_SKEW_SIGN = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0])


class PointJacobians:
    """Positions and world linear Jacobians of frame origins (markers), for any subset of frames.

    Call after ``pin.computeJointJacobians(model, data, q)``.
    Equal to ``pin.getFrameJacobian(model, data, f, pin.LOCAL_WORLD_ALIGNED)[:3]`` frame by frame.
    """

    def __init__(self, model: pin.Model) -> None:
        self.model = model
        self.nv = model.nv
        self._masks: dict[int, np.ndarray] = {}
        self._mask_sets: dict[tuple[int, ...], np.ndarray] = {}
        self._joints_of: dict[tuple[int, ...], tuple] = {}

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

    def _on_joints(self, fids: tuple[int, ...]) -> tuple[list[int], np.ndarray, np.ndarray]:
        """The distinct parent joints of ``fids``, each frame's index among them and its offset in its joint's
        frame, homogeneous (M, 4, 1) [m]."""
        model = self.model
        joints = sorted({model.frames[f].parentJoint for f in fids})
        column = {j: i for i, j in enumerate(joints)}
        offsets = np.array([[*model.frames[f].placement.translation, 1.0] for f in fids]).reshape(-1, 4, 1)
        return joints, np.array([column[model.frames[f].parentJoint] for f in fids], int), offsets

    def positions(self, data: pin.Data, frame_ids) -> np.ndarray:
        """World positions (M, 3) [m] of ``frame_ids``, from their joints' placements (after
        ``pin.forwardKinematics``; the frames' own placements need not be updated). Equal to :func:`positions`, at a
        third of its cost: Pinocchio's per-element accessors, not the arithmetic, dominate."""
        fids = tuple(frame_ids)
        if not fids:
            return np.zeros((0, 3))
        on = self._joints_of.get(fids)
        if on is None:
            on = self._joints_of[fids] = self._on_joints(fids)
        joints, which, offsets = on
        oMi = data.oMi.tolist()          # one call: indexing Pinocchio's vector costs ~0.6 us per element
        X = np.array([oMi[j].homogeneous for j in joints])
        return (X[which] @ offsets)[:, :3, 0]

    def __call__(self, data: pin.Data, frame_ids) -> tuple[np.ndarray, np.ndarray]:
        """World positions (M, 3) [m] and linear Jacobians (M, 3, nv) [m per unit of v] of ``frame_ids``."""
        fids = tuple(frame_ids)
        P = self.positions(data, fids)
        masks = self._mask_sets.get(fids)
        if masks is None:
            masks = self._mask_sets[fids] = np.array([self.support_mask(int(f)) for f in fids]).reshape(-1, self.nv)
        # v_p = v_O + omega x p = v_O - [p]x omega, for all points in one batched product
        S = np.zeros((len(P), 9))
        S[:, _SKEW_AT] = P[:, _SKEW_FROM] * _SKEW_SIGN
        J = data.J[:3] + S.reshape(-1, 3, 3) @ data.J[3:]
        J *= masks[:, None, :]
        return P, J


def positions(data: pin.Data, frame_ids) -> np.ndarray:
    """World positions (M, 3) [m] of frames (after ``updateFramePlacements`` or ``framesForwardKinematics``)."""
    oMf = data.oMf.tolist()    # one call, then plain list indexing (Pinocchio's own costs ~0.6 us per element)
    return np.array([oMf[f].translation for f in frame_ids]).reshape(-1, 3)
