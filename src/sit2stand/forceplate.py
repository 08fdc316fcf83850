"""Force-plate and foot-sensor algebra: moving wrenches between points, centre of pressure (COP), plate geometry.

Conventions: all vectors in the lab frame (REP-103: x forward, y left, z up), forces [N], moments [N m], points [m].
Arrays may carry a leading sample axis: ``force_n`` of shape (3,) or (K, 3).

The COP of a wrench (F, M_p) given about a point p, on a plane through p with unit normal n, is the point on the
plane about which the moment has no component in the plane:

    r = (n x M_p) / (n . F),    COP = p + r,    free moment  tau = n . (M_p - r x F)

(for n = z this is the familiar x = -M_y / F_z, y = M_x / F_z).
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .vectors import cross

DEFAULT_COP_THRESHOLD_N = 20.0
"""Normal force below which a plate counts as unloaded and its COP as undefined (Vicon Nexus' default)."""

PLATE_CORNERS_KEY = "plate_corners_m"
"""A bag's ``custom_data`` key for its plates' corners: JSON, plate name -> four [x, y, z] in the lab [m] (the
plate messages carry wrenches and COPs, not where the plates are)."""


@dataclass
class PlateSeries:
    """One force plate's samples: the reaction wrench on the body in lab axes, its moment about the lab origin.

    The one plate type of sit2stand: the C3D importer, the synthesiser, the bag reader, the COM estimators and the
    nodes all pass plates as this. Optional fields are what a source may lack (a bag carries no plate corners).

    Attributes:
        name: the plate's role (``chair``, ``feet``) or ``plate<i>``; its topic is ``/force_plate/<name>``.
        t_s: (K,) sample times [s].
        force_n: (K, 3) force on the body [N].
        moment_origin_nm: (K, 3) moment about the lab origin [N m], so that plates' wrenches add.
        cop_m: (K, 3) centre of pressure on the plate surface [m], NaN where invalid.
        cop_valid: (K,) the COP is defined (normal force above the threshold).
        free_moment_nm: (K,) free moment about the surface normal [N m].
        corners_m: (4, 3) the plate's corners in the lab [m].
        index: 0-based index in the source file (C3D ``FORCE_PLATFORM``), -1 if it has none.
    """

    name: str
    t_s: np.ndarray
    force_n: np.ndarray
    moment_origin_nm: np.ndarray
    cop_m: np.ndarray | None = None
    cop_valid: np.ndarray | None = None
    free_moment_nm: np.ndarray | None = None
    corners_m: np.ndarray | None = None
    index: int = -1

    @property
    def rate_hz(self) -> float:
        """Median sample rate [Hz] (to 1e-6 Hz: sample times carry float rounding)."""
        return round(1.0 / float(np.median(np.diff(self.t_s))), 6) if len(self.t_s) > 1 else float("nan")

    def between(self, t_from_s: float, t_to_s: float) -> PlateSeries:
        """The wrench samples with ``t_from_s <= t < t_to_s`` (COP fields dropped)."""
        lo, hi = np.searchsorted(self.t_s, [t_from_s, t_to_s])
        return PlateSeries(self.name, self.t_s[lo:hi], self.force_n[lo:hi], self.moment_origin_nm[lo:hi],
                           index=self.index)


def shift_moment(moment_nm: np.ndarray, force_n: np.ndarray, from_point_m: np.ndarray,
                 to_point_m: np.ndarray) -> np.ndarray:
    """Moment about ``to_point_m`` of a wrench whose moment about ``from_point_m`` is ``moment_nm``.

    M_to = M_from + (from - to) x F.
    """
    arm = np.asarray(from_point_m, float) - np.asarray(to_point_m, float)
    return np.asarray(moment_nm, float) + cross(arm, force_n)


def plate_surface(corners_m: np.ndarray, up: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Centre [m] and unit normal (pointing along ``up``, default +z) of a plate's top surface from its 4 corners
    (4, 3)."""
    up = np.array([0.0, 0.0, 1.0]) if up is None else up
    corners = np.asarray(corners_m, float)
    if corners.shape != (4, 3):
        raise InputError(f"plate corners must have shape (4, 3), got {corners.shape}")
    centre = corners.mean(axis=0)
    normal = np.cross(corners[2] - corners[0], corners[3] - corners[1])
    norm = np.linalg.norm(normal)
    if norm < 1e-12:
        raise InputError(f"plate corners are degenerate (collinear or repeated): {corners.tolist()}")
    normal /= norm
    if normal @ np.asarray(up, float) < 0:
        normal = -normal
    return centre, normal


def center_of_pressure(force_n: np.ndarray, moment_nm: np.ndarray, point_m: np.ndarray, normal: np.ndarray,
                       threshold_n: float = DEFAULT_COP_THRESHOLD_N) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """COP [m], validity and free moment [N m] of wrenches given about ``point_m`` on a plane with ``normal``.

    Args:
        force_n: (3,) or (K, 3) reaction force on the body.
        moment_nm: same shape, moment about ``point_m``.
        point_m: (3,) a point of the contact plane (e.g. the plate's surface centre).
        normal: (3,) unit normal of the plane, pointing up (into the body).
        threshold_n: minimum normal force for a valid COP.

    Returns:
        cop_m (…, 3) with NaN where invalid; valid (…,) bool; free_moment_nm (…,) about the normal, NaN where invalid.
    """
    if np.ndim(force_n) == 1:
        return _center_of_pressure_one(np.asarray(force_n, float), np.asarray(moment_nm, float),
                                       np.asarray(point_m, float), np.asarray(normal, float), threshold_n)
    force = np.atleast_2d(np.asarray(force_n, float))
    moment = np.atleast_2d(np.asarray(moment_nm, float))
    n = np.asarray(normal, float)
    fn = force @ n
    valid = np.isfinite(fn) & (fn > threshold_n) & np.all(np.isfinite(moment), axis=1)
    r = np.full_like(force, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        r[valid] = cross(n, moment[valid]) / fn[valid, None]
    cop = np.asarray(point_m, float) + r
    tau = np.full(len(force), np.nan)
    tau[valid] = np.einsum("ij,j->i", moment[valid] - cross(r[valid], force[valid]), n)
    return cop, valid, tau


def _center_of_pressure_one(force: np.ndarray, moment: np.ndarray, point: np.ndarray, n: np.ndarray,
                            threshold_n: float) -> tuple[np.ndarray, bool, float]:
    """:func:`center_of_pressure` of one wrench (the per-frame and per-command case, without the masking)."""
    fn = float(force @ n)
    if not (np.isfinite(fn) and fn > threshold_n and np.all(np.isfinite(moment))):
        return np.full(3, np.nan), False, float("nan")
    r = cross(n, moment) / fn
    return point + r, True, float((moment - cross(r, force)) @ n)


@dataclass
class LabWrench:
    """One plate's samples in lab axes: force [N], moment about the lab origin [N m], COP [m] (NaN where invalid)
    and its validity, free moment [N m]; the plate's corners [m] and surface normal."""

    force_n: np.ndarray
    moment_origin_nm: np.ndarray
    cop_m: np.ndarray
    cop_valid: np.ndarray
    free_moment_nm: np.ndarray
    corners_m: np.ndarray
    normal: np.ndarray


def wrench_in_lab(force_n: np.ndarray, moment_centre_nm: np.ndarray, corners_m: np.ndarray, rotation: np.ndarray,
                  threshold_n: float = DEFAULT_COP_THRESHOLD_N) -> LabWrench:
    """A plate's wrench given in the capture system's axes, moment about the plate's surface centre, rotated into
    the lab (``v_lab = rotation @ v``), its moment moved to the lab origin and its COP found on the surface.

    The one home of this arithmetic: the C3D importer and the live capture bridge both call it, so a live stream
    and an imported file of the same recording give the same samples."""
    force = np.asarray(force_n, float) @ rotation.T
    corners = np.asarray(corners_m, float) @ rotation.T
    centre, normal = plate_surface(corners, np.array([0.0, 0.0, 1.0]))
    moment_c = np.asarray(moment_centre_nm, float) @ rotation.T
    cop, cop_valid, tau = center_of_pressure(force, moment_c, centre, normal, threshold_n)
    return LabWrench(force, shift_moment(moment_c, force, centre, np.zeros(3)), cop, cop_valid, tau, corners, normal)


def combined_cop(forces_n: list[np.ndarray], moments_origin_nm: list[np.ndarray], height_m: float = 0.0,
                 threshold_n: float = DEFAULT_COP_THRESHOLD_N) -> tuple[np.ndarray, np.ndarray]:
    """COP of several plates together, on the horizontal plane z = ``height_m``.

    Moments must be about the lab origin (as in sit2stand_msgs/ForcePlateSample), so they simply add.
    Returns (cop_m, valid) with the shapes of :func:`center_of_pressure`.
    """
    force = np.sum([np.asarray(f, float) for f in forces_n], axis=0)
    moment = np.sum([np.asarray(m, float) for m in moments_origin_nm], axis=0)
    point = np.array([0.0, 0.0, height_m])
    moment_at_point = shift_moment(moment, force, np.zeros(3), point)
    cop, valid, _ = center_of_pressure(force, moment_at_point, point, np.array([0.0, 0.0, 1.0]), threshold_n)
    return cop, valid


def point_in_polygon(points_xy: np.ndarray, polygon_xy: np.ndarray, margin_m: float = 0.0) -> np.ndarray:
    """True where a 2-D point lies inside a convex polygon (vertices in order), at least ``margin_m`` from its edges.

    Args:
        points_xy: (2,) or (K, 2).
        polygon_xy: (V, 2) vertices of a convex polygon, clockwise or counter-clockwise.
    """
    pts = np.atleast_2d(np.asarray(points_xy, float))
    poly = np.asarray(polygon_xy, float)
    edges = np.roll(poly, -1, axis=0) - poly
    sign = np.sign(np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1]))
    rel = pts[:, None, :] - poly[None, :, :]
    cross = edges[None, :, 0] * rel[:, :, 1] - edges[None, :, 1] * rel[:, :, 0]
    dist = sign * cross / np.linalg.norm(edges, axis=1)[None, :]
    inside = np.all(dist >= margin_m, axis=1) & np.all(np.isfinite(pts), axis=1)
    return inside[0] if np.ndim(points_xy) == 1 else inside


def plate_corners_json(plates: list[PlateSeries]) -> str:
    """The :data:`PLATE_CORNERS_KEY` entry of ``plates`` (those whose corners are known), rounded to 0.1 mm."""
    return json.dumps({p.name: np.round(p.corners_m, 4).tolist() for p in plates if p.corners_m is not None})


def plate_corners_from(custom_data: dict[str, str]) -> dict[str, np.ndarray]:
    """Plate name -> (4, 3) corners [m] from a bag's ``custom_data`` (empty when it does not say)."""
    text = custom_data.get(PLATE_CORNERS_KEY)
    if not text:
        return {}
    try:
        corners = {name: np.asarray(c, float).reshape(4, 3) for name, c in json.loads(text).items()}
    except (ValueError, TypeError, AttributeError) as err:
        raise InputError(f"custom_data {PLATE_CORNERS_KEY!r}: not plate name -> four [x, y, z]: {err}") from None
    return corners
