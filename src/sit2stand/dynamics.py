"""Whole-body dynamics shared by the human and the robot: COM, centroidal momentum rate and the model COP (ZMP).

For any Pinocchio model with a floating base, the total external wrench is F = m (a_com - g) and, about the origin,
M_O = c x F + dL_G/dt (centroidal angular momentum rate). Its centre of pressure on the floor (z = ``floor_z``) is
the zero-moment point (ZMP) of the motion: where the feet must push for the motion to happen.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter
import pinocchio as pin

from .errors import InputError
from .forceplate import center_of_pressure
from .vectors import cross

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
    moment = cross(com, force) + data.dhg.angular
    point = np.array([0.0, 0.0, floor_z])
    cop, _ok, _tau = center_of_pressure(force, moment - cross(point, force), point, np.array([0.0, 0.0, 1.0]),
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


def smooth_motion(model: pin.Model, qs: np.ndarray, dt: float, window: int = 31,
                  order: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Smoothed configurations and their velocities and accelerations (N, nq), (N, nv), (N, nv).

    Savitzky-Golay position, first and second derivative of decoupled coordinates: the floating base's position
    (world), its rotation vector r about the first frame's orientation (R = R0 exp(r)), and the joint angles. They
    map to Pinocchio's free-flyer velocity (body frame) as v = R^T p', w = Jr(r) r', with accelerations
    R^T p'' - w x (R^T p') and Jr r'' + (dJr/dt) r'. Differentiating the fit, not the smoothed samples, keeps the
    noise of accelerations small (1 mm of marker noise gives ~0.1 m/s^2 at 100 Hz with the defaults; the window
    keeps ~95 % of a 2 Hz motion's acceleration).
    """
    n = len(qs)
    window = min(window, n - (1 - n % 2))
    if window <= order:
        raise InputError(f"{n} frames are too few to smooth (need more than {order + 1})")
    R0 = pin.Quaternion(qs[0][3:7]).normalized().matrix()
    rot = np.array([pin.log3(R0.T @ pin.Quaternion(q[3:7]).normalized().matrix()) for q in qs])
    x = np.hstack([qs[:, :3], rot, qs[:, 7:]])
    xs, xd, xdd = (savgol_series(x, window, order, d) / dt**d for d in (0, 1, 2))
    q_s = np.zeros_like(qs)
    v = np.zeros((n, model.nv))
    a = np.zeros((n, model.nv))
    for k in range(n):
        r, rd, rdd = xs[k, 3:6], xd[k, 3:6], xdd[k, 3:6]
        R = R0 @ pin.exp3(r)
        q_s[k, :3] = xs[k, :3]
        q_s[k, 3:7] = pin.Quaternion(R).coeffs()
        q_s[k, 7:] = xs[k, 6:]
        Jr = pin.Jexp3(r)
        h = 1e-4
        dJr = (pin.Jexp3(r + h * rd) - pin.Jexp3(r - h * rd)) / (2 * h)
        w = Jr @ rd
        v_lin = R.T @ xd[k, :3]
        v[k, :3], v[k, 3:6], v[k, 6:] = v_lin, w, xd[k, 6:]
        a[k, :3] = R.T @ xdd[k, :3] - cross(w, v_lin)
        a[k, 3:6] = Jr @ rdd + dJr @ rd
        a[k, 6:] = xdd[k, 6:]
    return q_s, v, a


def savgol_frames(window_s: float, dt: float, minimum: int = 5) -> int:
    """An odd Savitzky-Golay window [frames] spanning ``window_s`` [s] of frames ``dt`` [s] apart (at least
    ``minimum``, above the filters' order 4)."""
    return max(minimum, 2 * int(round(window_s / dt / 2)) + 1)


def savgol_series(x: np.ndarray, window: int, order: int, deriv: int) -> np.ndarray:
    """Savitzky-Golay along axis 0 with the polynomial fitted to the nearest window at the edges."""
    return savgol_filter(x, window, order, deriv=deriv, axis=0, mode="interp")
