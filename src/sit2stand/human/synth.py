"""Digital-human sit-to-stand demonstrations: markers and force plates of a known body, with the true COM.

The rise follows the phases described in the sit-to-stand literature (Schenkman et al., Phys. Ther. 1990: flexion
momentum, momentum transfer at seat-off, extension, stabilisation): the trunk and pelvis flex forward while the hips
stay on the seat; at seat-off the hips leave the seat and move forward, then up, while the trunk extends back to
upright. ``natural`` rises in ~1.6 s with ~35 degrees of trunk flexion; ``elderly`` is slower (~3 s) with deeper
trunk flexion (~55 degrees) before seat-off, so that the COM first drops before it rises (Mistry et al. 2010, Fig. 7).

Kinematics (sagittal, feet flat and fixed, hips on the seat until seat-off) give q(t) at 1 kHz; velocities and
accelerations by differentiation; whole-body inverse dynamics of the skeleton (Pinocchio, centroidal momentum rate)
give the total external wrench  F = m (a_com - g),  M_O = c x F + dL_G/dt  (about the lab origin), shared between the
chair and the feet: before seat-off the chair takes the static share that puts the feet COP at mid-foot, fading to
zero over the unloading window that ends at seat-off. Markers: forward kinematics at 100 Hz (``marker_rate_hz``),
with a per-trial placement error, measurement noise and occlusion gaps. Plates: 1000 Hz with noise, COP from the
wrench (:mod:`sit2stand.human.synth_plates`).

Lab frame: REP-103, origin on the floor midway between the ankles; the chair is behind (x < 0).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..dynamics import G, plan_derivatives
from ..errors import InputError
from ..io.frame_rate import MIN_RATE_HZ
from ..forceplate import PlateSeries
from .anthropometry import ankle_height_m
from .skeleton import (LENGTH_GROUPS, REFERENCE_STATURE_M, SEGMENT_MASS_SD, SEGMENTS, ExtraMass, HumanModel, Subject,
                       build_human)
from .synth_plates import feet_cop_warnings, foot_span_x, measure_plates, min_jerk, share_loads

STYLES = {
    # rise duration [s], seat-off as a fraction of it, peak pelvis tilt and lumbar flexion [rad], shank tilt at
    # the seated start [rad] (feet drawn back), chair unloading window before seat-off [s]
    "natural": dict(duration=1.6, seat_off=0.40, pelvis_tilt=0.40, lumbar=0.22, shank_tilt=0.22, unload=0.15,
                    peak_after_seat_off=0.18, cop_forward=0.05),
    "elderly": dict(duration=3.0, seat_off=0.55, pelvis_tilt=0.55, lumbar=0.42, shank_tilt=0.15, unload=0.35,
                    peak_after_seat_off=0.03, cop_forward=0.06),
}


@dataclass
class SynthConfig:
    """What to synthesise. ``None`` means the style's or the body's default."""

    style: str = "natural"
    height_m: float = 1.75
    mass_kg: float = 75.0
    sex: str = "male"
    seat_height_m: float | None = None     # default 0.26 x stature
    duration_s: float | None = None        # rise duration; default from the style
    seed: int = 0
    extra: list[ExtraMass] = field(default_factory=list)
    declared_mass_factor: float = 1.0       # the bag's body mass = the true one x this (a scale error; plates: truth)
    vary_subject: bool = True               # random segment length (sd 3 %) and mass (SEGMENT_MASS_SD) factors
    sit_before_s: float = 0.8
    stand_after_s: float = 1.5
    marker_rate_hz: float = 100.0
    plate_rate_hz: float = 1000.0
    marker_noise_m: float = 0.001
    marker_placement_sd_m: float = 0.004
    occlusion_gaps: int = 5
    force_noise_n: float = 1.0
    moment_noise_nm: float = 0.3

    def __post_init__(self) -> None:
        if self.style not in STYLES:
            raise InputError(f"style must be one of {', '.join(STYLES)}, not {self.style!r}")
        if self.duration_s is not None and not 0.8 <= self.duration_s <= 8.0:
            raise InputError(f"rise duration {self.duration_s:g} s is outside 0.8..8 s")
        if self.seat_height_m is not None and not 0.18 * self.height_m <= self.seat_height_m <= 0.36 * self.height_m:
            raise InputError(f"seat height {self.seat_height_m:g} m is outside 18-36 % of the stature")
        if not 0.5 <= self.declared_mass_factor <= 1.5:
            raise InputError(f"declared mass factor {self.declared_mass_factor:g} is outside 0.5..1.5")
        ratio = self.plate_rate_hz / self.marker_rate_hz if self.marker_rate_hz >= MIN_RATE_HZ else 0.0
        if not (ratio >= 1 and abs(ratio - round(ratio)) < 1e-9):
            raise InputError(f"marker rate {self.marker_rate_hz:g} Hz must be at least {MIN_RATE_HZ:g} Hz "
                             f"and divide the plate rate {self.plate_rate_hz:g} Hz (e.g. 50, 100, 125, 200, 250, 500)")


@dataclass
class Demonstration:
    """A synthesised trial. Times [s] from the trial start; dynamics at the plate rate, markers at the marker rate."""

    config: SynthConfig
    human: HumanModel                       # the TRUE body (extra masses included)
    t_s: np.ndarray                         # (K,) plate-rate times
    q: np.ndarray                           # (K, nq)
    com_m: np.ndarray                       # (K, 3)
    com_vel: np.ndarray
    com_acc: np.ndarray
    marker_t_s: np.ndarray                  # (N,)
    marker_names: list[str]
    markers_m: np.ndarray                   # (N, M, 3), NaN where occluded
    marker_valid: np.ndarray                # (N, M)
    plates: list[PlateSeries]
    seat_off_s: float
    rise_start_s: float
    rise_end_s: float
    seat_height_m: float
    warnings: list[str] = field(default_factory=list)


def _random_subject(cfg: SynthConfig, rng: np.random.Generator) -> Subject:
    """The configured subject, with random segment length and mass factors where ``cfg.vary_subject``."""
    lengths, masses = {}, {}
    if cfg.vary_subject:
        lengths = {g: float(np.clip(rng.normal(1.0, 0.03), 0.92, 1.08)) for g in LENGTH_GROUPS}
        per_side = {}
        for seg in SEGMENTS:
            base = seg[:-2] if seg[-2:] in ("_l", "_r") else seg
            per_side.setdefault(base, float(np.clip(rng.normal(1.0, SEGMENT_MASS_SD), 0.8, 1.2)))
            masses[seg] = per_side[base] * float(np.clip(rng.normal(1.0, 0.01), 0.97, 1.03))
    body_mass = cfg.mass_kg
    return Subject(cfg.height_m, body_mass, cfg.sex, lengths, masses, list(cfg.extra))


def _world_pitch(v: np.ndarray) -> np.ndarray:
    """World pitch [rad] (about +y) of unit sagittal (x, z) directions: R_y(p) (0, 0, -1) = (-sin p, -cos p)."""
    return np.arctan2(-v[:, 0], -v[:, 1])


def _leg_ik(hip_xz: np.ndarray, ankle_xz: np.ndarray, l_th: float, l_sh: float) -> tuple[np.ndarray, np.ndarray]:
    """World pitch angles (about +y) of thigh and shank putting the knee in front of the hip-ankle line."""
    d_vec = ankle_xz - hip_xz
    d = np.linalg.norm(d_vec, axis=-1)
    d = np.minimum(d, (l_th + l_sh) * 0.99999)
    u = d_vec / np.linalg.norm(d_vec, axis=-1, keepdims=True)
    cos_a = np.clip((l_th**2 + d**2 - l_sh**2) / (2 * l_th * d), -1.0, 1.0)
    a = np.arccos(cos_a)
    # rotate u by -a about +y: (x, z) -> (x cos a - z sin a, x sin a + z cos a)
    th_dir = np.stack([u[:, 0] * np.cos(a) - u[:, 1] * np.sin(a), u[:, 0] * np.sin(a) + u[:, 1] * np.cos(a)], axis=1)
    knee = hip_xz + l_th * th_dir
    sh_dir = (ankle_xz - knee) / l_sh
    return _world_pitch(th_dir), _world_pitch(sh_dir)


PELVIS_SEATED_RAD = -0.12
"""Pelvis pitch when sitting [rad] (about +y; negative: the posterior tilt of a seated pelvis)."""


@dataclass
class _Body:
    """The true body and the sagittal geometry its rise is planned with (lengths [m], lab frame, (x, z) pairs)."""

    human: HumanModel
    data: pin.Data
    jid: dict[str, int]                 # joint name -> index in q
    q0: np.ndarray                      # neutral configuration
    height_m: float
    thigh_m: float
    shank_m: float
    ankle_xz: np.ndarray                # the fixed ankles: x = 0, z = ankle height
    seat_m: float                       # seat height
    hip_above_seat_m: float
    hip_seated_xz: np.ndarray           # hips on the seat at the start
    hip_standing_xz: np.ndarray         # hips when standing, knees almost straight

    @property
    def model(self) -> pin.Model:
        """The body's Pinocchio model."""
        return self.human.model


@dataclass
class _Timeline:
    """Plate-rate time base and the rise's events, all [s] from the trial start."""

    t: np.ndarray
    dt: float
    duration: float
    rise_start: float
    seat_off: float
    rise_end: float
    peak: float                         # trunk flexion peak, just after seat-off


@dataclass
class _Plan:
    """The planned motion: configurations filled stage by stage, with the pelvis pitch [rad] and hip height [m]."""

    q: np.ndarray                       # (K, nq)
    pelvis_pitch: np.ndarray            # (K,)
    hip_z: np.ndarray                   # (K,)


@dataclass
class _Centroidal:
    """Whole-body COM motion and the total external wrench about the lab origin (SI)."""

    com_m: np.ndarray                   # (K, 3)
    com_vel: np.ndarray                 # (K, 3) [m/s]
    com_acc: np.ndarray                 # (K, 3) [m/s^2]
    force_n: np.ndarray                 # (K, 3)
    moment_o_nm: np.ndarray             # (K, 3)


def synthesize(cfg: SynthConfig) -> Demonstration:
    """Synthesise one sit-to-stand demonstration (see the module docstring)."""
    rng = np.random.default_rng(cfg.seed)
    style = STYLES[cfg.style]
    body = _body(cfg, style, rng)
    tl = _timeline(cfg, style)
    plan = _trunk_and_arms(body, tl, style)
    k_so, com_at_seat_off = _roll_forward_on_seat(body, plan, tl)
    _track_com_path(body, plan, k_so, _com_path_after_seat_off(body, plan, tl, k_so, com_at_seat_off))
    _check_limits(body.human, plan.q)
    dyn = _centroidal(body, plan.q, tl.dt)
    plates = measure_plates(cfg, rng, body, tl.t, share_loads(body, style, tl, plan.q, dyn))
    warnings = feet_cop_warnings(body.human, plates[1])
    idx, markers, valid = _markers(cfg, rng, body, plan.q)
    return Demonstration(cfg, body.human, tl.t, plan.q, dyn.com_m, dyn.com_vel, dyn.com_acc, tl.t[idx],
                         body.human.marker_names, markers, valid, plates, tl.seat_off, tl.rise_start, tl.rise_end,
                         body.seat_m, warnings)


def _body(cfg: SynthConfig, style: dict, rng: np.random.Generator) -> _Body:
    """Build the (randomised) subject, and place its hips on the seat and standing over the fixed ankles."""
    H = cfg.height_m
    human = build_human(_random_subject(cfg, rng))
    model, data = human.model, human.model.createData()
    jid = {name: model.joints[model.getJointId(name)].idx_q for name in model.names[2:]}
    q0 = pin.neutral(model)
    pin.framesForwardKinematics(model, data, q0)
    l_th = np.linalg.norm(model.jointPlacements[model.getJointId("knee_l_y")].translation)
    l_sh = np.linalg.norm(model.jointPlacements[model.getJointId("ankle_l_y")].translation)
    h_a = ankle_height_m(H, cfg.sex) * human.subject.lengths.get("foot", 1.0)
    seat = cfg.seat_height_m if cfg.seat_height_m is not None else 0.26 * H
    hip_above_seat = 0.055 * H
    # seated start: ankle at x = 0, shank tilted back, thigh from the knee to the hip on the seat
    beta = style["shank_tilt"]
    knee0 = np.array([l_sh * np.sin(beta), h_a + l_sh * np.cos(beta)])
    z_h0 = seat + hip_above_seat
    dz = z_h0 - knee0[1]
    if abs(dz) >= l_th:
        raise ValueError(f"seat height {seat:.3f} m cannot be reached with thigh length {l_th:.3f} m")
    hip0 = np.array([knee0[0] - np.sqrt(l_th**2 - dz**2), z_h0])
    hip1 = np.array([0.0, h_a + l_sh + l_th - 0.004])   # standing height, knees almost straight
    return _Body(human, data, jid, q0, H, l_th, l_sh, np.array([0.0, h_a]), seat, hip_above_seat, hip0, hip1)


def _timeline(cfg: SynthConfig, style: dict) -> _Timeline:
    """The plate-rate time base and the rise's start, seat-off, trunk peak and end [s]."""
    duration = cfg.duration_s or style["duration"]
    dt = 1.0 / cfg.plate_rate_hz
    t_total = cfg.sit_before_s + duration + cfg.stand_after_s
    t = np.arange(int(round(t_total / dt)) + 1) * dt
    t_rise0 = cfg.sit_before_s
    t_so = t_rise0 + style["seat_off"] * duration
    t_rise1 = t_rise0 + duration
    t_peak = t_so + style["peak_after_seat_off"] * duration
    return _Timeline(t, dt, duration, t_rise0, t_so, t_rise1, t_peak)


def _trunk_and_arms(body: _Body, tl: _Timeline, style: dict) -> _Plan:
    """Pelvis tilt, lumbar flexion, arms, head and hip height over time [rad, m]; the legs are set later."""
    # trunk: seated posterior pelvic tilt -> anterior tilt + lumbar flexion peaking just after seat-off -> upright
    t, duration, t_rise0, t_peak, t_rise1 = tl.t, tl.duration, tl.rise_start, tl.peak, tl.rise_end
    p_seated = PELVIS_SEATED_RAD
    pel = p_seated + (style["pelvis_tilt"] - p_seated) * min_jerk(t, t_rise0, t_peak) \
        - style["pelvis_tilt"] * min_jerk(t, t_peak, t_rise1)
    lum = style["lumbar"] * (min_jerk(t, t_rise0, t_peak) - min_jerk(t, t_peak + 0.05 * duration, t_rise1))
    breathing = 0.012 * np.sin(2 * np.pi * 0.25 * t)
    lum = lum + breathing * (1 - min_jerk(t, t_rise0, t_rise0 + 0.2))
    trunk = pel + lum
    s_rise = np.clip((t - t_rise0) / duration, 0, 1)
    swing = 0.5 * (1 - np.cos(2 * np.pi * s_rise))   # 0 -> 1 -> 0 with zero slope at both ends
    hip0, hip1 = body.hip_seated_xz, body.hip_standing_xz
    hz = hip0[1] + (hip1[1] - hip0[1]) * min_jerk(t, tl.seat_off, t_rise1)   # hips leave the seat at seat-off

    jid = body.jid
    q = np.tile(body.q0, (len(t), 1))
    q[:, 2] = hz
    q[:, 4], q[:, 6] = np.sin(pel / 2), np.cos(pel / 2)   # quaternion (x, y, z, w) of R_y(pelvis pitch)
    for side in "lr":
        q[:, jid[f"shoulder_{side}_y"]] = -0.35 * trunk - 0.35 * swing
        q[:, jid[f"shoulder_{side}_x"]] = (0.12 if side == "l" else -0.12) * (1 + 0.3 * swing)
        q[:, jid[f"elbow_{side}_y"]] = -0.35 - 0.4 * swing
    q[:, jid["lumbar_y"]] = lum
    q[:, jid["neck_y"]] = -0.55 * trunk
    q[:, jid["neck_z"]] = 0.05 * np.sin(2 * np.pi * 0.4 * t)
    q[:, jid["lumbar_z"]] = 0.02 * swing
    return _Plan(q, pel, hz)


def _set_hips(body: _Body, plan: _Plan, rows: np.ndarray | slice, hx: np.ndarray) -> None:
    """Place the hips at x = hx [m] (z, pelvis pitch already set) and the legs by planar IK, feet flat."""
    q, ankle_xz, l_th, l_sh = plan.q, body.ankle_xz, body.thigh_m, body.shank_m
    hip = np.stack([hx, q[rows, 2]], axis=1)
    reach = (l_th + l_sh) * 0.9999
    d = hip - ankle_xz
    too_far = np.linalg.norm(d, axis=1) > reach
    if too_far.any():
        hip[too_far, 0] = np.sign(d[too_far, 0]) * np.sqrt(np.maximum(reach**2 - d[too_far, 1] ** 2, 0.0))
    th, sh = _leg_ik(hip, np.zeros_like(hip) + ankle_xz, l_th, l_sh)
    p = plan.pelvis_pitch[rows]
    q[rows, 0] = hip[:, 0]
    for side in "lr":
        q[rows, body.jid[f"hip_{side}_y"]] = th - p
        q[rows, body.jid[f"knee_{side}_y"]] = sh - th
        q[rows, body.jid[f"ankle_{side}_y"]] = -sh


def _com_x(body: _Body, q: np.ndarray) -> float:
    """Whole-body COM x [m] at configuration q."""
    return float(pin.centerOfMass(body.model, body.data, q)[0])


def _roll_forward_on_seat(body: _Body, plan: _Plan, tl: _Timeline) -> tuple[int, tuple[float, float, float]]:
    """Legs before seat-off; the seat-off sample and the COM x, velocity, acceleration just before it [m, /s, /s^2]."""
    # before seat-off the pelvis rolls forward over the ischia: the hips move with the pelvic tilt
    dt = tl.dt
    k_so = int(np.searchsorted(tl.t, tl.seat_off))
    pre = slice(0, k_so)
    _set_hips(body, plan, pre, body.hip_seated_xz[0]
              + body.hip_above_seat_m * (np.sin(plan.pelvis_pitch[pre]) - np.sin(PELVIS_SEATED_RAD)))
    xs = np.array([_com_x(body, plan.q[k]) for k in range(k_so - 4, k_so)])   # one-sided 2nd-order differences
    x0 = xs[-1]
    v0 = (3 * xs[-1] - 4 * xs[-2] + xs[-3]) / (2 * dt)
    a0 = (2 * xs[-1] - 5 * xs[-2] + 4 * xs[-3] - xs[-4]) / dt**2
    return k_so, (x0, v0, a0)


def _com_path_after_seat_off(body: _Body, plan: _Plan, tl: _Timeline, k_so: int,
                             start: tuple[float, float, float]) -> np.ndarray:
    """The COM x path [m] from seat-off to standing over mid-foot, timed for the widest point-mass ZMP margin."""
    # its duration is chosen for the largest margin of the (point-mass) ZMP inside the feet
    t, dt, hz = tl.t, tl.dt, plan.hip_z
    heel_x, tip_x = foot_span_x(body.human)
    x1 = 0.035 * body.height_m / REFERENCE_STATURE_M
    post = np.arange(k_so, len(t))
    tp = t[post] - t[k_so - 1]   # the quintic starts where x0, v0, a0 were measured
    z_c = hz[post] + (float(pin.centerOfMass(body.model, body.data, plan.q[k_so - 1])[2]) - hz[k_so - 1])
    az = np.gradient(np.gradient(z_c, dt), dt)
    best = None
    for T in np.linspace(0.3, 1.0, 15) * (tl.rise_end - tl.seat_off):
        xc, _, ac = _quintic(tp, T, *start, x1)
        zmp = xc - z_c * ac / (G + az)
        margin = min(np.min(zmp - heel_x), np.min(tip_x - zmp))
        if best is None or margin > best[0]:
            best = (margin, T, xc)
    return best[2]


def _track_com_path(body: _Body, plan: _Plan, k_so: int, xc_target: np.ndarray) -> None:
    """Solve the hips x, sample by sample from seat-off, so that the COM x follows ``xc_target`` [m]."""
    hx = plan.q[k_so - 1, 0]
    for i, k in enumerate(np.arange(k_so, len(plan.q))):
        for _ in range(4):  # Newton on hip x: d(COM x)/d(hip x) is about 1 (a little less)
            _set_hips(body, plan, slice(k, k + 1), np.array([hx]))
            err = _com_x(body, plan.q[k]) - xc_target[i]
            if abs(err) < 1e-7:
                break
            _set_hips(body, plan, slice(k, k + 1), np.array([hx + 1e-4]))
            slope = (_com_x(body, plan.q[k]) - err - xc_target[i]) / 1e-4
            hx -= err / max(slope, 0.2)
        _set_hips(body, plan, slice(k, k + 1), np.array([hx]))


def _centroidal(body: _Body, q: np.ndarray, dt: float) -> _Centroidal:
    """COM motion and the external wrench F = m (a_com - g), M_O = c x F + dL_G/dt, by whole-body dynamics."""
    # velocities and accelerations by central differences (Pinocchio's tangent space)
    model, data = body.model, body.data
    n = len(q)
    v, a = plan_derivatives(model, q, dt)
    com = np.zeros((n, 3))
    vcom = np.zeros((n, 3))
    acom = np.zeros((n, 3))
    dL = np.zeros((n, 3))
    for k in range(n):
        pin.centerOfMass(model, data, q[k], v[k], a[k])
        com[k], vcom[k], acom[k] = data.com[0], data.vcom[0], data.acom[0]
        pin.computeCentroidalMomentumTimeVariation(model, data, q[k], v[k], a[k])
        dL[k] = data.dhg.angular
    force = body.human.total_mass * (acom + np.array([0.0, 0.0, G]))
    return _Centroidal(com, vcom, acom, force, np.cross(com, force) + dL)


OCCLUSION_S = (0.08, 0.40)
"""Occlusion gap lengths [s], drawn uniformly (8-39 frames at 100 Hz)."""
OCCLUDED_MARKERS = ("LASI", "RASI", "LHEE", "RHEE", "RFIN", "LWRB", "RWRB", "STRN", "LTHI", "RTIB")
"""Markers that the synthesised occlusion gaps may hide."""


def _markers(cfg: SynthConfig, rng: np.random.Generator, body: _Body,
             q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Marker positions [m] at the marker rate: plate-rate sample indices, (N, M, 3) with NaN gaps, validity."""
    human, data = body.human, body.data
    step = int(round(cfg.plate_rate_hz / cfg.marker_rate_hz))
    idx = np.arange(0, len(q), step)
    names = human.marker_names
    placement = rng.normal(0.0, cfg.marker_placement_sd_m, (len(names), 3))
    mk = np.zeros((len(idx), len(names), 3))
    for i, k in enumerate(idx):
        pin.framesForwardKinematics(body.model, data, q[k])
        for j, mname in enumerate(names):
            mk[i, j] = data.oMf[human.marker_frames[mname]].act(placement[j])
    mk += rng.normal(0.0, cfg.marker_noise_m, mk.shape)
    valid = np.ones(mk.shape[:2], bool)
    for _ in range(cfg.occlusion_gaps):
        j = names.index(OCCLUDED_MARKERS[rng.integers(len(OCCLUDED_MARKERS))])
        length = int(rng.integers(*(round(s * cfg.marker_rate_hz) for s in OCCLUSION_S)))
        start = int(rng.integers(0, len(idx) - length))
        valid[start:start + length, j] = False
    mk[~valid] = np.nan
    return idx, mk, valid


def _quintic(t: np.ndarray, T: float, x0: float, v0: float, a0: float, x1: float):
    """Position, velocity, acceleration of the quintic from (x0, v0, a0) at t = 0 to (x1, 0, 0) at t = T; x1 after."""
    s = np.clip(t, 0.0, T)
    c = np.array([x0, v0, a0 / 2.0, 0.0, 0.0, 0.0])
    d = x1 - x0 - v0 * T - a0 * T**2 / 2
    dv = -v0 - a0 * T
    da = -a0
    m = np.array([[T**3, T**4, T**5], [3 * T**2, 4 * T**3, 5 * T**4], [6 * T, 12 * T**2, 20 * T**3]])
    c[3:] = np.linalg.solve(m, np.array([d, dv, da]))
    pos = sum(c[i] * s**i for i in range(6))
    vel = sum(i * c[i] * s ** (i - 1) for i in range(1, 6))
    acc = sum(i * (i - 1) * c[i] * s ** (i - 2) for i in range(2, 6))
    return pos, vel, acc


def _check_limits(human: HumanModel, q: np.ndarray) -> None:
    """Raise ValueError naming the first joint whose synthesised angle [rad] leaves its range."""
    lo, hi = human.model.lowerPositionLimit[7:], human.model.upperPositionLimit[7:]
    bad = np.where((q[:, 7:] < lo - 1e-9) | (q[:, 7:] > hi + 1e-9))
    if len(bad[0]):
        j = bad[1][0]
        raise ValueError(f"synthesised motion leaves the range of joint {human.model.names[int(j) + 2]} "
                         f"({q[bad[0][0], int(j) + 7]:.3f} rad outside {lo[j]:.2f}..{hi[j]:.2f})")
