"""Kinematics shared by the human skeleton fit and the robot IK: many points' Jacobians at once.

Both fit marker points fixed to links, and both need, per Gauss-Newton step, the world positions of tens of frame
origins and their linear Jacobians. Asking Pinocchio frame by frame (``getFrameJacobian``) costs a Python call per
marker; here they come from one ``computeJointJacobians`` by the rigid-body relation ``v_p = v_O + omega x p``
(world-frame joint Jacobians, ``data.J``), masked to each point's supporting joints.

Units SI; world frame (REP-103).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from . import native


_CROSS_AT = [4, 5, 9, 11, 15, 16]
"""Entries of a point's (3, 6) row-major block [I | -[p]x] that hold p's coordinates ``_CROSS_FROM`` with
``_CROSS_SIGN``: v_p = v_O + omega x p = [I | -[p]x] (v_O, omega)."""
_CROSS_FROM = [2, 1, 2, 0, 1, 0]
_CROSS_SIGN = np.array([1.0, -1.0, -1.0, 1.0, 1.0, -1.0])


@functools.lru_cache(maxsize=64)
def _block_layout(m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For M points: the blocks [I | 0] (M * 3, 6) (copy them: their p-entries are refilled per call), the flat
    indices of those entries, the flat indices into P (M, 3) that fill them, and their signs."""
    blocks = np.tile(np.hstack([np.eye(3), np.zeros((3, 3))]), (m, 1))
    fill = (18 * np.arange(m)[:, None] + np.array(_CROSS_AT)).ravel()
    source = (3 * np.arange(m)[:, None] + np.array(_CROSS_FROM)).ravel()
    return blocks, fill, source, np.tile(_CROSS_SIGN, m)


@dataclass(frozen=True)
class PointSet:
    """What a set of M frames needs precomputed (:meth:`PointJacobians.point_set`): their distinct parent joints,
    where each frame's position lies in the product of the joints' placements with all offsets, the offsets, the
    rows' support masks and the blocks [I | -[p]x] (M * 3, 6) whose p-entries are refilled per call; and for the
    compiled kernel (:mod:`sit2stand.native`) each frame's row in ``joints``, its offset (M, 3) and each joint's
    supporting tangent indices (``dofs[dof_start[j]:dof_start[j] + dof_count[j]]``)."""

    size: int
    joints: list[int]
    take: np.ndarray          # (M, 3) flat indices into the (4 * joints, M) product
    offsets: np.ndarray       # (4, M) homogeneous offsets in the parent joints' frames [m]
    masks: np.ndarray         # (M * 3, nv)
    blocks: np.ndarray        # (M * 3, 6)
    fill: np.ndarray          # flat indices of the p-entries in ``blocks``
    source: np.ndarray        # flat indices into P (M, 3) that fill them
    sign: np.ndarray          # and their signs
    joint_id: np.ndarray      # (M,) int32: each frame's parent joint (Pinocchio's index)
    joint_row: np.ndarray     # (M,) int32: its place in ``joints``
    offsets_m: np.ndarray     # (M, 3) offsets in the parent joints' frames [m]
    dofs: np.ndarray          # int32, the joints' supporting tangent indices, one run per joint
    dof_start: np.ndarray     # (len(joints),) int32
    dof_count: np.ndarray     # (len(joints),) int32

    @functools.cached_property
    def kernel_block(self):
        """The compiled kernel's view of the set (:class:`sit2stand.native.PointerBlock`): joint ids and rows,
        offsets, dofs, their starts and counts."""
        return native.PointerBlock(self.joint_id, self.joint_row, self.offsets_m, self.dofs, self.dof_start,
                                   self.dof_count)


class PointJacobians:
    """Positions and world linear Jacobians of frame origins (markers), for any subset of frames.

    Call after ``pin.computeJointJacobians(model, data, q)``.
    Equal to ``pin.getFrameJacobian(model, data, f, pin.LOCAL_WORLD_ALIGNED)[:3]`` frame by frame. Per call: one
    product of the joints' placements with all offsets, and one (M * 3, 6) x (6, nv) product with ``data.J``; the
    rest is precomputed per set of frames (Pinocchio's per-element accessors and small batched products, not the
    arithmetic, dominate a per-frame loop).
    """

    def __init__(self, model: pin.Model) -> None:
        self.model = model
        self.nv = model.nv
        self._frames: dict[int, tuple[int, np.ndarray, np.ndarray]] = {}
        self._layouts: dict[tuple[int, ...] | bytes, PointSet] = {}
        self._weighted: tuple | None = None     # (set, row weights, masks weighted by them) of the last call
        self._joint_masks: np.ndarray | None = None     # (njoints, nv): see _joint_mask

    def support_mask(self, frame_id: int) -> np.ndarray:
        """(nv,) 1 on the velocity coordinates that move this frame, 0 elsewhere."""
        return self._frame(frame_id)[2]

    def _frame(self, frame_id: int) -> tuple[int, np.ndarray, np.ndarray]:
        """A frame's parent joint, homogeneous offset in it (4,) and support mask (nv,), kept per frame: a new set
        of frames (a marker lost or found) is then laid out from them in a few products."""
        known = self._frames.get(frame_id)
        if known is None:
            frame = self.model.frames[frame_id]
            known = self._frames[frame_id] = (frame.parentJoint, np.array([*frame.placement.translation, 1.0]),
                                              self._joint_mask(frame.parentJoint))
        return known

    def point_set(self, frame_ids) -> PointSet:
        """The precomputed layout of ``frame_ids`` (cached per set): pass it instead of the ids where one set is
        asked for again and again (a tuple's hash costs as much as a small product)."""
        if isinstance(frame_ids, PointSet):
            return frame_ids
        # an array's bytes are a cheaper key than a tuple of its numbers
        key = frame_ids.astype(np.int64).tobytes() if isinstance(frame_ids, np.ndarray) else tuple(frame_ids)
        layout = self._layouts.get(key)
        if layout is None:
            frames = [self._frame(int(f)) for f in frame_ids]
            m = len(frames)
            joints = sorted({parent for parent, _, _ in frames})
            column = np.array([joints.index(parent) for parent, _, _ in frames], int)
            take = ((4 * column[:, None] + np.arange(3)) * m + np.arange(m)[:, None])
            offsets = np.array([offset for _, offset, _ in frames]).reshape(m, 4).T
            masks = np.repeat(np.array([mask for _, _, mask in frames]).reshape(m, self.nv), 3, axis=0)
            blocks, fill, source, sign = _block_layout(m)
            supports = [np.flatnonzero(self._joint_mask(j)).astype(np.int32) for j in joints]
            counts = np.array([len(s) for s in supports], np.int32)
            layout = self._layouts[key] = PointSet(
                m, joints, take, offsets, masks, blocks.copy(), fill, source, sign,
                np.array([parent for parent, _, _ in frames], np.int32), column.astype(np.int32),
                np.ascontiguousarray(offsets[:3].T), np.concatenate([np.zeros(0, np.int32), *supports]),
                (np.cumsum(counts) - counts).astype(np.int32), counts)
        return layout

    def _joint_mask(self, joint: int) -> np.ndarray:
        """(nv,) 1 on the velocity coordinates that move ``joint``'s frame (read-only)."""
        if self._joint_masks is None:       # all joints' at once, each from its parent's
            model = self.model
            masks = np.zeros((model.njoints, self.nv))
            for j in range(1, model.njoints):
                jt = model.joints[j]
                masks[j] = masks[model.parents[j]]
                masks[j, jt.idx_v:jt.idx_v + jt.nv] = 1.0
            masks.flags.writeable = False
            self._joint_masks = masks
        return self._joint_masks[joint]

    def placements(self, data: pin.Data, layout: PointSet) -> np.ndarray:
        """The homogeneous world placements (len(joints), 4, 4) of the set's parent joints (after
        ``pin.forwardKinematics``)."""
        oMi = data.oMi.tolist()          # one call: indexing Pinocchio's vector costs ~0.6 us per element
        return np.array([oMi[j].homogeneous for j in layout.joints])

    def positions(self, data: pin.Data, frame_ids) -> np.ndarray:
        """World positions (M, 3) [m] of ``frame_ids`` (or their :class:`PointSet`), from their joints' placements
        (after ``pin.forwardKinematics``; the frames' own placements need not be updated). Equal to
        :func:`positions`, at a third of its cost."""
        layout = self.point_set(frame_ids)
        if not layout.size:
            return np.zeros((0, 3))
        return (self.placements(data, layout).reshape(-1, 4) @ layout.offsets).take(layout.take)

    def __call__(self, data: pin.Data, frame_ids, row_weights: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
        """World positions (M, 3) [m] and linear Jacobians (M, 3, nv) [m per unit of v] of ``frame_ids`` (or their
        :class:`PointSet`); with ``row_weights`` (M * 3,), each Jacobian row scaled by its weight (kept, masks
        and weights together, for the next call with the same array: change its values only in a new array)."""
        layout = self.point_set(frame_ids)
        P = self.positions(data, layout)
        layout.blocks.flat[layout.fill] = P.take(layout.source) * layout.sign
        J = layout.blocks @ data.J
        J *= layout.masks if row_weights is None else self._weighted_masks(layout, row_weights)
        return P, J.reshape(layout.size, 3, self.nv)

    def _weighted_masks(self, layout: PointSet, row_weights: np.ndarray) -> np.ndarray:
        last = self._weighted
        if last is None or last[0] is not layout or last[1] is not row_weights:
            last = self._weighted = (layout, row_weights, layout.masks * row_weights[:, None])
        return last[2]


def positions(data: pin.Data, frame_ids) -> np.ndarray:
    """World positions (M, 3) [m] of frames (after ``updateFramePlacements`` or ``framesForwardKinematics``)."""
    oMf = data.oMf.tolist()    # one call, then plain list indexing (Pinocchio's own costs ~0.6 us per element)
    return np.array([oMf[f].translation for f in frame_ids]).reshape(-1, 3)
