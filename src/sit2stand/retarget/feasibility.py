"""Dynamic feasibility of a kinematic plan: its zero-moment point (ZMP) and the retiming that keeps it in the feet.

A COM-hard kinematic plan (Mistry et al. 2010) says nothing about forces: played at the human's speed it can demand
a ZMP outside the feet, which no joint controller can follow (measured on TALOS: a 1.5 s rise needs the ZMP 8-16 cm
outside the feet, 3 s keeps a 5-6 cm margin). :func:`plan_zmp` computes the ZMP along a plan from the centroidal
dynamics; :func:`support_margin` is its signed distance inside the feet's support polygon (negative: outside);
:func:`retime_factor` finds the smallest time-scale factor s >= 1 (the plan played s times slower: velocities / s,
accelerations / s^2) whose ZMP keeps ``margin_m`` inside the feet wherever the feet carry the robot.
"""

from __future__ import annotations

import functools

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


@functools.lru_cache(maxsize=64)
def _edge_normals(vertices: bytes, count: int) -> tuple[np.ndarray, np.ndarray]:
    poly = np.frombuffer(vertices, float).reshape(count, 2)
    nxt = np.concatenate([poly[1:], poly[:1]])
    edges = nxt - poly
    area2 = float(np.sum(poly[:, 0] * nxt[:, 1] - nxt[:, 0] * poly[:, 1]))
    inward = np.sign(area2) * np.stack([-edges[:, 1], edges[:, 0]], axis=1)
    inward /= np.sqrt((inward ** 2).sum(axis=1))[:, None]
    offsets = (inward * poly).sum(axis=1)
    inward.flags.writeable = offsets.flags.writeable = False      # shared between callers
    return inward, offsets


def edge_normals(polygon_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit inward normals (V, 2) of a convex polygon's edges (vertices in order, either way round) and each edge's
    offset n . vertex: a point p is inside edge k by n_k . p - offset_k. Read-only arrays, kept per polygon: the
    live player asks for the same feet's three times a frame."""
    poly = np.ascontiguousarray(polygon_xy, float)
    return _edge_normals(poly.tobytes(), len(poly))


def frame_time_scales(com_m: np.ndarray, com_acc: np.ndarray, dl_nm: np.ndarray, mass_kg: float,
                      polygon_xy: np.ndarray, margin_m: float, max_factor: float = 4.0,
                      resolution: float = 0.02) -> np.ndarray:
    """Per frame, the smallest time-scale factor s (on a grid of ``resolution`` in [1, ``max_factor``]) whose ZMP
    (:func:`zmp_at_scale`) keeps ``margin_m`` inside ``polygon_xy``; ``max_factor`` where none does (a NaN frame too).

    Solved, not searched: with k = 1/s^2, an edge's margin times the vertical force m (g + k a_z) is linear in k,
    A + k C >= 0, so each edge keeps the margin on a half-line of k and the polygon on their intersection
    [k_lo, k_hi] (k_hi also short of the k where the feet stop pushing); s is the first grid point at or past
    1/sqrt(k_hi) if its k is still >= k_lo. Slowing down moves a frame's ZMP toward its COM: when the COM has the
    margin, every larger s keeps it too, and a plan needs the largest of its frames' factors."""
    c, a, dl = (np.atleast_2d(np.asarray(x, float)) for x in (com_m, com_acc, dl_nm))
    inward, offsets = edge_normals(polygon_xy)
    A = (c[:, :2] @ inward.T - (offsets + margin_m)) * (mass_kg * G)                    # (N, E): k = 0
    moment = np.stack([c[:, 2] * mass_kg * a[:, 0] + dl[:, 1], c[:, 2] * mass_kg * a[:, 1] - dl[:, 0]], axis=1)
    C = A * (a[:, 2:3] / G) - moment @ inward.T
    bound = -A / np.where(C == 0.0, 1.0, C)
    k_hi = np.where(C < 0, bound, np.where((C == 0) & (A < 0), -np.inf, np.inf)).min(axis=1)
    falling = a[:, 2] < 0                   # and the feet push: g + k a_z > 0
    k_hi = np.where(falling, np.minimum(k_hi, G / np.where(falling, -a[:, 2], 1.0) * (1.0 - 1e-12)), k_hi)
    k_lo = np.where(C > 0, bound, -np.inf).max(axis=1)
    scales = np.arange(1.0, max_factor + 1e-9, resolution)
    steps = np.ceil((np.sqrt(1.0 / np.clip(k_hi, 1e-300, 1.0)) - 1.0) / resolution - 1e-9)
    inside = steps < len(scales)
    s = scales[np.where(inside, steps, 0).astype(int)]
    ok = inside & (k_hi > 0) & (1.0 / s**2 >= k_lo) & np.isfinite(A).all(axis=1) & np.isfinite(C).all(axis=1)
    return np.where(ok, s, max_factor)


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
