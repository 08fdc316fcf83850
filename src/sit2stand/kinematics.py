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
        fids = tuple(int(f) for f in frame_ids)
        P = np.array([data.oMf[f].translation for f in fids]).reshape(-1, 3)
        masks = self._mask_sets.get(fids)
        if masks is None:
            masks = self._mask_sets[fids] = np.array([self.support_mask(f) for f in fids]).reshape(-1, self.nv)
        Jl, Ja = data.J[:3], data.J[3:]
        # omega x p, column by column: (w_y p_z - w_z p_y, w_z p_x - w_x p_z, w_x p_y - w_y p_x)
        px, py, pz = (P[:, i, None] for i in range(3))
        wx, wy, wz = Ja
        J = np.empty((len(P), 3, self.nv))
        J[:, 0] = Jl[0] + wy * pz - wz * py
        J[:, 1] = Jl[1] + wz * px - wx * pz
        J[:, 2] = Jl[2] + wx * py - wy * px
        return P, J * masks[:, None, :]
