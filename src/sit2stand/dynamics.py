"""Whole-body dynamics shared by the human and the robot: COM, centroidal momentum rate and the model COP (ZMP).

For any Pinocchio model with a floating base, the total external wrench is F = m (a_com - g) and, about the origin,
M_O = c x F + dL_G/dt (centroidal angular momentum rate). Its centre of pressure on the floor (z = ``floor_z``) is
the zero-moment point (ZMP) of the motion: where the feet must push for the motion to happen.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .io.forceplate import center_of_pressure

G = 9.81


def model_cop(model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray, a: np.ndarray,
              floor_z: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """COM, its velocity and acceleration, and the model COP on the floor from the centroidal dynamics:
    F = m (a_com - g), M_O = c x F + dL_G/dt."""
    pin.centerOfMass(model, data, q, v, a)
    com, vcom, acom = data.com[0].copy(), data.vcom[0].copy(), data.acom[0].copy()
    pin.computeCentroidalMomentumTimeVariation(model, data, q, v, a)
    mass = data.mass[0]
    force = mass * (acom + np.array([0.0, 0.0, G]))
    moment = np.cross(com, force) + data.dhg.angular
    point = np.array([0.0, 0.0, floor_z])
    cop, _ok, _tau = center_of_pressure(force, moment - np.cross(point, force), point, np.array([0.0, 0.0, 1.0]),
                                        threshold_n=1.0)
    return com, vcom, acom, cop


def plan_derivatives(model: pin.Model, qs: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocities and accelerations (N, nv) of a configuration sequence by central differences (tangent space)."""
    n = len(qs)
    v = np.zeros((n, model.nv))
    for k in range(n):
        lo, hi = max(k - 1, 0), min(k + 1, n - 1)
        v[k] = pin.difference(model, qs[lo], qs[hi]) / max((hi - lo) * dt, 1e-12)
    return v, np.gradient(v, dt, axis=0)
