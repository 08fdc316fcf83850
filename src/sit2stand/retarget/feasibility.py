"""Dynamic feasibility of a kinematic plan: its zero-moment point (ZMP) and the retiming that keeps it in the feet.

A COM-hard kinematic plan (Mistry et al. 2010) says nothing about forces: played at the human's speed it can demand
a ZMP outside the feet, which no joint controller can follow (measured on TALOS: a 1.5 s rise needs the ZMP 8-16 cm
outside the feet, 3 s keeps a 5-6 cm margin). :func:`plan_zmp` computes the ZMP along a plan from the centroidal
dynamics; :func:`support_margin` is its signed distance inside the feet's support polygon (negative: outside);
:func:`retime_factor` finds the smallest time-scale factor s >= 1 (the plan played s times slower: velocities / s,
accelerations / s^2) whose ZMP keeps ``margin_m`` inside the feet wherever the feet carry the robot.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..dynamics import model_cop, plan_derivatives
from ..io.forceplate import point_in_polygon


def plan_zmp(model: pin.Model, qs: np.ndarray, dt: float, time_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(ZMP (N, 3) on the floor, COM (N, 3)) of the plan ``qs`` sampled every ``dt`` and played ``time_scale`` x
    slower."""
    v, a = plan_derivatives(model, qs, dt * time_scale)
    data = model.createData()
    zmp, com = np.zeros((len(qs), 3)), np.zeros((len(qs), 3))
    for k, q in enumerate(qs):
        c, _, _, z = model_cop(model, data, q, v[k], a[k])
        zmp[k], com[k] = z, c
    return zmp, com


def support_polygon(corners_xy: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise) of the feet's sole corners (K, 2)."""
    from scipy.spatial import ConvexHull

    pts = np.asarray(corners_xy, float)
    return pts[ConvexHull(pts).vertices]


def support_margin(points_xy: np.ndarray, polygon_xy: np.ndarray) -> np.ndarray:
    """Signed distance [m] of each point inside the convex polygon (negative: outside)."""
    pts = np.atleast_2d(points_xy)
    poly = np.asarray(polygon_xy, float)
    edges = np.roll(poly, -1, axis=0) - poly
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1) / np.linalg.norm(edges, axis=1)[:, None]
    sign = np.sign(np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1]))
    dist = -sign * ((pts[:, None, :] - poly[None, :, :]) * normals[None, :, :]).sum(axis=2)
    out = dist.min(axis=1)
    inside = point_in_polygon(pts, poly)
    return np.where(inside, np.abs(out), -np.abs(out))


def retime_factor(model: pin.Model, qs: np.ndarray, dt: float, polygon_xy: np.ndarray, on_feet: np.ndarray,
                  margin_m: float = 0.04, max_factor: float = 4.0) -> tuple[float, float]:
    """Smallest time-scale factor s in [1, ``max_factor``] whose ZMP keeps ``margin_m`` inside ``polygon_xy`` on the
    frames ``on_feet`` (the robot off the chair). Returns (s, the margin reached [m]); s = ``max_factor`` and a
    smaller margin when even that is not enough (the plan must then be changed, not slowed)."""
    def margin(s: float) -> float:
        zmp, _ = plan_zmp(model, qs, dt, s)
        return float(support_margin(zmp[on_feet, :2], polygon_xy).min()) if on_feet.any() else np.inf

    m1 = margin(1.0)
    if m1 >= margin_m:
        return 1.0, m1
    m_max = margin(max_factor)
    if m_max < margin_m:
        return max_factor, m_max
    lo, hi = 1.0, max_factor
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        if margin(mid) >= margin_m:
            hi = mid
        else:
            lo = mid
    return hi, margin(hi)
