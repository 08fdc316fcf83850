"""sit2stand.retarget.feasibility: ZMP of a plan, margins in the support polygon, retiming."""

import numpy as np
import pinocchio as pin
import pytest

from sit2stand.retarget.feasibility import (frame_time_scales, plan_zmp, retime_factor, support_margin,
                                            support_polygon, zmp_at_scale)
from sit2stand.dynamics import G
from sit2stand.robot.model import controller_model


def squat_plan(model, duration_s, dt=0.01, depth=0.9):
    """Both legs bend and unbend (hip, knee, ankle), the base following so the feet stay put, in ``duration_s``."""
    idx = lambda n: model.joints[model.getJointId(n)].idx_q  # noqa: E731
    data = model.createData()
    t = np.arange(0, duration_s + 1e-9, dt)
    s = 0.5 * (1 - np.cos(2 * np.pi * t / duration_s))
    qs = []
    for sk in s:
        q = pin.neutral(model)
        for side in ("left", "right"):
            q[idx(f"leg_{side}_3_joint")], q[idx(f"leg_{side}_4_joint")] = -0.5 * depth * sk, depth * sk
            q[idx(f"leg_{side}_5_joint")] = -0.5 * depth * sk
        pin.framesForwardKinematics(model, data, q)
        sole = data.oMf[model.getFrameId("sole_left")].translation
        q[0] -= sole[0]
        q[2] -= sole[2]
        qs.append(q)
    return np.array(qs)


@pytest.fixture(scope="module")
def model():
    return controller_model()


def test_static_plan_has_its_zmp_under_the_com(model):
    qs = squat_plan(model, 4.0)
    qs[:] = qs[len(qs) // 3]                  # the same posture held
    zmp, com = plan_zmp(model, qs, 0.01)
    assert np.abs(zmp[:, :2] - com[:, :2]).max() < 1e-9


def test_faster_plans_move_the_zmp_further_and_retiming_restores_the_margin(model):
    poly = support_polygon(np.array([[-0.085, 0.15], [0.125, 0.15], [0.125, -0.15], [-0.085, -0.15]]))
    fast = squat_plan(model, 0.6)
    slow = squat_plan(model, 3.0)
    dev = lambda qs: np.abs(np.subtract(*plan_zmp(model, qs, 0.01))[:, 0]).max()  # noqa: E731
    assert dev(fast) > 5 * dev(slow)
    on_feet = np.ones(len(fast), bool)
    s, margin = retime_factor(model, fast, 0.01, poly, on_feet, margin_m=0.05)   # ZMP swings +-6 cm at 0.6 s
    assert 1.0 < s < 4.0 and margin >= 0.05 - 1e-6
    assert retime_factor(model, slow, 0.01, poly, np.ones(len(slow), bool), margin_m=0.0)[0] == 1.0


def test_support_margin_sign_and_value():
    square = support_polygon(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float))
    m = support_margin(np.array([[0.5, 0.5], [0.9, 0.5], [1.2, 0.5]]), square)
    assert m == pytest.approx([0.5, 0.1, -0.2])


def test_each_frames_time_scale_is_the_first_grid_point_whose_zmp_keeps_the_margin():
    """The solved per-frame scale against a search of the grid itself: 20,000 random frames (COMs inside and outside
    the feet, accelerations up to a fall faster than gravity, NaN frames) on a rectangle and on a polygon given the
    other way round, for three margins and caps."""
    rng = np.random.default_rng(5)
    polygons = [np.array([[0.15, 0.2], [-0.08, 0.2], [-0.08, -0.2], [0.15, -0.2]]),
                np.array([[0.1, 0.1], [0.12, -0.1], [-0.1, -0.12], [-0.12, 0.0], [-0.1, 0.1]])]      # clockwise
    n = 20_000
    com = np.c_[rng.normal(0.0, 0.08, (n, 2)), rng.uniform(0.5, 1.0, n)]
    acc, dl = rng.normal(0.0, 3.0, (n, 3)), rng.normal(0.0, 8.0, (n, 3))
    acc[:50, 2], com[50:60, 0], acc[60:70, 1] = -12.0, np.nan, np.nan
    for polygon in polygons:
        for margin, cap in ((0.04, 4.0), (0.0, 2.0), (0.02, 1.5)):
            grid = np.arange(1.0, cap + 1e-9, 0.02)
            inv2 = np.repeat(1.0 / grid**2, n)[:, None]
            zmp = zmp_at_scale(np.tile(com, (len(grid), 1)), np.tile(acc, (len(grid), 1)) * inv2,
                               np.tile(dl, (len(grid), 1)) * inv2, 90.0, 1.0)
            pushes = G + np.tile(acc[:, 2], len(grid)) * inv2[:, 0] > 0       # a ZMP needs the feet to push
            ok = ((support_margin(zmp[:, :2], polygon) >= margin) & pushes).reshape(len(grid), n)
            searched = np.where(ok.any(axis=0), grid[np.argmax(ok, axis=0)], cap)
            solved = frame_time_scales(com, acc, dl, 90.0, polygon, margin, cap)
            np.testing.assert_array_equal(solved, searched)
