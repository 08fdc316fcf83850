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
from scipy.spatial import ConvexHull

from ..dynamics import G, model_cop, plan_derivatives


def plan_dynamics(model: pin.Model, qs: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """COM (N, 3) [m], COM acceleration (N, 3) [m/s^2] and centroidal angular momentum rate (N, 3) [N m] of the plan
    ``qs`` sampled every ``dt`` (central differences), at its own timing."""
    v, a = plan_derivatives(model, qs, dt)
    data = model.createData()
    out = np.zeros((3, len(qs), 3))
    for k, q in enumerate(qs):
        out[0, k], _, out[1, k], _ = model_cop(model, data, q, v[k], a[k])
        out[2, k] = data.dhg.angular
    return out[0], out[1], out[2]


def zmp_at_scale(com_m: np.ndarray, com_acc: np.ndarray, dl_nm: np.ndarray, mass_kg: float,
                 time_scale: float) -> np.ndarray:
    """ZMP (N, 3) on the floor z = 0 of a plan played ``time_scale`` x slower, from its COM, COM acceleration and
    angular momentum rate at its own timing: played s x slower every acceleration and every velocity product, hence
    both terms of dL/dt, scale by 1/s^2 (exact for a uniform time scaling).
    x = c_x - (c_z F_x + dL_y) / F_z,  y = c_y - (c_z F_y - dL_x) / F_z,  F = m (a / s^2 + g e_z)."""
    c, a, dl = (np.atleast_2d(np.asarray(x, float)) for x in (com_m, com_acc, dl_nm))
    k = 1.0 / time_scale**2
    fz = mass_kg * (G + k * a[:, 2])
    fx, fy = mass_kg * k * a[:, 0], mass_kg * k * a[:, 1]
    x = c[:, 0] - (c[:, 2] * fx + k * dl[:, 1]) / fz
    y = c[:, 1] - (c[:, 2] * fy - k * dl[:, 0]) / fz
    return np.stack([x, y, np.zeros_like(x)], axis=1)


def plan_zmp(model: pin.Model, qs: np.ndarray, dt: float, time_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(ZMP (N, 3) on the floor, COM (N, 3)) of the plan ``qs`` sampled every ``dt`` and played ``time_scale`` x
    slower."""
    com, acc, dl = plan_dynamics(model, qs, dt)
    return zmp_at_scale(com, acc, dl, float(pin.computeTotalMass(model)), time_scale), com


def support_polygon(corners_xy: np.ndarray) -> np.ndarray:
    """Convex hull (counter-clockwise) of the feet's sole corners (K, 2)."""
    pts = np.asarray(corners_xy, float)
    return pts[ConvexHull(pts).vertices]


def support_margin(points_xy: np.ndarray, polygon_xy: np.ndarray) -> np.ndarray:
    """Signed distance [m] of each point inside the convex polygon (negative: outside, by the edge it is furthest
    past; NaN for a NaN point): the smallest of its distances inward from the polygon's edges. Called twice per
    command by the plan player, so it is kept to a few array operations."""
    pts = np.atleast_2d(np.asarray(points_xy, float))
    inward, offsets = edge_normals(polygon_xy)
    return (pts @ inward.T - offsets).min(axis=1)


def edge_normals(polygon_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit inward normals (V, 2) of a convex polygon's edges (vertices in order, either way round) and each edge's
    offset n . vertex: a point p is inside edge k by n_k . p - offset_k."""
    poly = np.asarray(polygon_xy, float)
    nxt = np.concatenate([poly[1:], poly[:1]])
    edges = nxt - poly
    area2 = float(np.sum(poly[:, 0] * nxt[:, 1] - nxt[:, 0] * poly[:, 1]))
    inward = np.sign(area2) * np.stack([-edges[:, 1], edges[:, 0]], axis=1)
    inward /= np.sqrt((inward ** 2).sum(axis=1))[:, None]
    return inward, (inward * poly).sum(axis=1)


def frame_time_scales(com_m: np.ndarray, com_acc: np.ndarray, dl_nm: np.ndarray, mass_kg: float,
                      polygon_xy: np.ndarray, margin_m: float, max_factor: float = 4.0,
                      resolution: float = 0.02) -> np.ndarray:
    """Per frame, the smallest time-scale factor s (on a grid of ``resolution`` in [1, ``max_factor``]) whose ZMP
    (:func:`zmp_at_scale`) keeps ``margin_m`` inside ``polygon_xy``; ``max_factor`` where none does. Slowing down moves
    a frame's ZMP toward its COM, and the margin is concave inside a convex polygon, so every larger s keeps the
    margin too (when the COM itself has it): a plan needs the largest of its frames' factors."""
    c, a, dl = (np.atleast_2d(np.asarray(x, float)) for x in (com_m, com_acc, dl_nm))
    scales = np.arange(1.0, max_factor + 1e-9, resolution)
    n, k = len(c), len(scales)
    inv2 = np.repeat(1.0 / scales**2, n)[:, None]                   # grid-major: (k * n, 1)
    z = zmp_at_scale(np.tile(c, (k, 1)), np.tile(a, (k, 1)) * inv2, np.tile(dl, (k, 1)) * inv2, mass_kg, 1.0)
    ok = (support_margin(z[:, :2], polygon_xy) >= margin_m).reshape(k, n)
    first = np.argmax(ok, axis=0)
    return np.where(ok.any(axis=0), scales[first], max_factor)


def retime_factor(model: pin.Model, qs: np.ndarray, dt: float, polygon_xy: np.ndarray, on_feet: np.ndarray,
                  margin_m: float = 0.04, max_factor: float = 4.0) -> tuple[float, float]:
    """Smallest time-scale factor s in [1, ``max_factor``] whose ZMP keeps ``margin_m`` inside ``polygon_xy`` on the
    frames ``on_feet`` (the robot off the chair): the largest of those frames' :func:`frame_time_scales`. Returns
    (s, the margin reached [m]); s = ``max_factor`` and a smaller margin when even that is not enough (the plan must
    then be changed, not slowed)."""
    com, acc, dl = plan_dynamics(model, qs, dt)
    mass = float(pin.computeTotalMass(model))
    if not on_feet.any():
        return 1.0, np.inf
    s = float(frame_time_scales(com[on_feet], acc[on_feet], dl[on_feet], mass, polygon_xy, margin_m,
                                max_factor).max())
    zmp = zmp_at_scale(com[on_feet], acc[on_feet], dl[on_feet], mass, s)
    return s, float(support_margin(zmp[:, :2], polygon_xy).min())
