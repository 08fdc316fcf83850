"""The force plates of a digital-human demonstration (:mod:`sit2stand.human.synth`): the body's external wrench shared
between the chair and the feet, the two plates' geometry, and their noisy measurement.

Lab frame: REP-103, origin on the floor midway between the ankles; the chair is behind (x < 0). Forces [N], moments
[N m] about the lab origin unless a name says otherwise.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..forceplate import PlateSeries, center_of_pressure, point_in_polygon
from .skeleton import REFERENCE_STATURE_M, HumanModel

if TYPE_CHECKING:
    from .synth import SynthConfig, _Body, _Centroidal, _Timeline

PLATE_GAP_M = 0.01
"""Space between the chair plate and the feet plate, and the seat COP's least distance from the chair plate's front
edge [m]."""
MIN_SEAT_AHEAD_M = 0.05
"""The least chair plate in front of the seated hips, at the reference stature [m]: under the thighs."""


def min_jerk(t: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """0 -> 1 minimum-jerk ramp between t0 and t1 (zero velocity and acceleration at both ends)."""
    s = np.clip((t - t0) / max(t1 - t0, 1e-9), 0.0, 1.0)
    return s**3 * (10 - 15 * s + 6 * s**2)


def foot_span_x(human: HumanModel) -> tuple[float, float]:
    """Heel and toe-tip x [m] of the (flat, fixed) feet in the lab frame."""
    model = human.model
    heel_x = human.geometry["foot_l"]["from"][0]
    tip_x = model.jointPlacements[model.getJointId("toe_l_y")].translation[0] + human.geometry["toes_l"]["to"][0]
    return heel_x, tip_x


def share_loads(body: _Body, style: dict, tl: _Timeline, q: np.ndarray,
                 dyn: _Centroidal) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """Split the external wrench between chair and feet: ((force [N], moment about O [N m]) of each)."""
    # before seat-off: the static share that balances the COM between the seat contact and a feet COP target
    # (mid-foot, moving toward the forefoot as the trunk flexes; ~75-80 % on the chair when sitting still), fading
    # to zero over the unloading window that ends at seat-off. The chair COP moves within the buttock-thigh contact
    # (ischia to mid-thigh) to take the trunk's dynamic moment; what it cannot take goes to the feet.
    H, seat, t, t_so = body.height_m, body.seat_m, tl.t, tl.seat_off
    force, moment_o = dyn.force_n, dyn.moment_o_nm
    n = len(t)
    hx = q[:, 0]
    x_feet = 0.06 * H / REFERENCE_STATURE_M + style["cop_forward"] * H / REFERENCE_STATURE_M * min_jerk(
        t, tl.rise_start, t_so)
    x_contact = hx - 0.01
    alpha = np.clip((x_feet - dyn.com_m[:, 0]) / (x_feet - x_contact), 0.05, 0.95)
    alpha *= 1 - min_jerk(t, t_so - style["unload"], t_so)
    f_chair = alpha[:, None] * force
    with np.errstate(divide="ignore", invalid="ignore"):
        x_seat = (seat * f_chair[:, 0] - x_feet * (force[:, 2] - f_chair[:, 2]) - moment_o[:, 1]) / f_chair[:, 2]
        # the chair's COP on its plate lies seat * fx / fz behind the seat point: keep it on a plate cut short
        cop_front = plate_rects(body)[0][:, 0].max() - PLATE_GAP_M + seat * f_chair[:, 0] / f_chair[:, 2]
    x_seat = np.clip(np.nan_to_num(x_seat, nan=0.0), hx - 0.12 * H / REFERENCE_STATURE_M,
                     np.fmin(hx + 0.15 * H / REFERENCE_STATURE_M, cop_front))
    seat_point = np.stack([x_seat, np.zeros(n), np.full(n, seat)], axis=1)
    m_chair = np.cross(seat_point, f_chair)
    return (f_chair, m_chair), (force - f_chair, moment_o - m_chair)


def measure_plates(cfg: SynthConfig, rng: np.random.Generator, body: _Body, t: np.ndarray,
                    loads: tuple[tuple[np.ndarray, np.ndarray], ...]) -> list[PlateSeries]:
    """The chair plate under the seat and the feet plate under the feet, on the floor, with sensor noise [N, N m]."""
    chair_plate, feet_plate = plate_rects(body)
    plates = []
    for name, corners, (f, m_o) in zip(("chair", "feet"), (chair_plate, feet_plate), loads):
        centre = corners.mean(axis=0)
        f_meas = f + rng.normal(0.0, cfg.force_noise_n, f.shape)
        m_c = m_o - np.cross(centre, f) + rng.normal(0.0, cfg.moment_noise_nm, f.shape)   # noise about its centre
        m_meas = m_c + np.cross(centre, f_meas)
        cop, ok, tau = center_of_pressure(f_meas, m_c, centre, np.array([0.0, 0.0, 1.0]))
        plates.append(PlateSeries(name, t, f_meas, m_meas, cop, ok, tau, corners))
    return plates


def feet_cop_warnings(human: HumanModel, feet: PlateSeries) -> list[str]:
    """A warning where the feet plate's COP leaves the feet in more than 1 % of its loaded samples."""
    heel_x, tip_x = foot_span_x(human)
    feet_support = np.array([[heel_x, -0.15], [tip_x, -0.15], [tip_x, 0.15], [heel_x, 0.15]])
    outside = ~point_in_polygon(feet.cop_m[feet.cop_valid, :2], feet_support)
    if outside.mean() > 0.01:
        return [f"feet COP leaves the feet in {outside.mean():.1%} of loaded samples (motion too fast?)"]
    return []


def plate_rects(body: _Body) -> tuple[np.ndarray, np.ndarray]:
    """Corners (4, 3) [m] of the chair plate (under the seated hips) and the feet plate (under the feet). Where the
    thighs are short for the seat the chair plate is cut short in front, ``PLATE_GAP_M`` behind the feet plate, as a
    lab places two plates; ValueError where that would leave the seated hips less than ``MIN_SEAT_AHEAD_M`` (scaled)
    of plate ahead of them."""
    scale = body.height_m / REFERENCE_STATURE_M
    hip_x = body.hip_seated_xz[0]
    feet_plate = _rect(np.array([0.09 * scale, 0.0, 0.0]), 0.18 * scale, 0.25 * scale)
    back, front = hip_x - 0.24 * scale, min(hip_x + 0.20 * scale, feet_plate[:, 0].min() - PLATE_GAP_M)
    if front < hip_x + MIN_SEAT_AHEAD_M * scale:
        raise ValueError(f"the chair plate would end {front - hip_x:+.3f} m from the seated hips, in front of them "
                         "the feet plate; raise the seat or shorten the thighs")
    chair_plate = _rect(np.array([(back + front) / 2, 0.0, 0.0]), (front - back) / 2, 0.25 * scale)
    return chair_plate, feet_plate


def _rect(centre: np.ndarray, half_x: float, half_y: float) -> np.ndarray:
    """Corners (4, 3) [m] of a floor rectangle of the given half sizes [m] about ``centre``."""
    c = np.asarray(centre, float)
    return np.array([[c[0] + half_x, c[1] + half_y, 0.0], [c[0] - half_x, c[1] + half_y, 0.0],
                     [c[0] - half_x, c[1] - half_y, 0.0], [c[0] + half_x, c[1] - half_y, 0.0]])
