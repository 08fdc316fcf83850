"""Segment inertial parameters of an average adult, after de Leva (1996).

Source: P. de Leva, "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters", J. Biomech. 29(9):1223-1230,
1996, Table 4 (male / female): segment mass as % of body mass, centre of mass (COM) position as % of segment length
from the named end, radii of gyration as % of segment length about the sagittal (x, antero-posterior), transverse
(y, medio-lateral) and longitudinal axes, and mean segment lengths [mm] with the mean stature (1741 mm male,
1735 mm female). The trunk's lower part (LPT, omphalion to mid-hip) is used as the pelvis segment; the torso is the
rest of the trunk (upper + middle trunk), whose COM and inertia follow from the whole trunk and the LPT by
composition, so that pelvis + torso reproduce the whole trunk exactly.

Everything here is a pure function of stature [m], body mass [kg] and sex ("male" / "female").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from ..errors import InputError

STATURE_MM = {"male": 1741.0, "female": 1735.0}

# name: (mass %, COM % from the proximal/named end, (r_sag, r_trv, r_lon) %, length mm), per sex.
# Proximal ends: head from the vertex (VERT), trunk from C7 (CERV), LPT from the omphalion, upper arm from the
# shoulder joint centre, forearm from the elbow, hand from the wrist (to the third metacarpal), thigh from the hip
# joint centre, shank from the knee joint centre (to the lateral malleolus), foot from the heel (to the toe tip).
DE_LEVA = {
    "male": {
        "head":      (6.94, 59.76, (36.2, 37.6, 31.2), 242.9),
        "trunk":     (43.46, 44.86, (37.2, 34.7, 19.1), 603.3),
        "lpt":       (11.17, 61.15, (61.5, 55.1, 58.7), 145.7),
        "upper_arm": (2.71, 57.72, (28.5, 26.9, 15.8), 281.7),
        "forearm":   (1.62, 45.74, (27.6, 26.5, 12.1), 268.9),
        "hand":      (0.61, 79.00, (62.8, 51.3, 40.1), 86.2),
        "thigh":     (14.16, 40.95, (32.9, 32.9, 14.9), 422.2),
        "shank":     (4.33, 44.59, (25.5, 24.9, 10.3), 434.0),
        "foot":      (1.37, 44.15, (25.7, 24.5, 12.4), 258.1),
    },
    "female": {
        "head":      (6.68, 58.94, (33.0, 35.9, 31.8), 243.7),
        "trunk":     (42.57, 41.51, (35.7, 33.9, 17.1), 614.8),
        "lpt":       (12.47, 49.20, (43.3, 40.2, 44.4), 181.5),
        "upper_arm": (2.55, 57.54, (27.8, 26.0, 14.8), 275.1),
        "forearm":   (1.38, 45.59, (26.1, 25.7, 9.4), 264.3),
        "hand":      (0.56, 74.74, (53.1, 45.4, 33.5), 78.0),
        "thigh":     (14.78, 36.12, (36.9, 36.4, 16.2), 368.5),
        "shank":     (4.81, 44.16, (27.1, 26.7, 9.3), 432.3),
        "foot":      (1.29, 40.14, (29.9, 27.9, 13.9), 228.3),
    },
}

ANKLE_HEIGHT = 0.039
"""Lateral malleolus height above the sole, as a fraction of stature (not in de Leva; typical adult value)."""

TOE_MASS_FRACTION = 0.1
"""Share of de Leva's foot mass given to the toes segment (de Leva's foot includes the toes)."""


@dataclass(frozen=True)
class SegmentInertia:
    """One segment's length [m], mass [kg], COM distance from its proximal end along its long axis [m] and
    principal moments of inertia about its COM [kg m^2] in (sagittal x, transverse y, longitudinal) order."""

    length_m: float
    mass_kg: float
    com_from_proximal_m: float
    inertia_kgm2: tuple[float, float, float]


def check_subject(height_m: float, mass_kg: float, sex: str) -> None:
    """Raise ValueError for a subject outside what these tables describe (with the value named)."""
    if sex not in DE_LEVA:
        raise InputError(f"sex must be 'male' or 'female', not {sex!r}")
    if not 0.8 <= height_m <= 2.3:
        raise InputError(f"height {height_m:g} m is outside 0.8..2.3 m")
    if not 10.0 <= mass_kg <= 250.0:
        raise InputError(f"body mass {mass_kg:g} kg is outside 10..250 kg")


def vertical_length_factor(sex: str) -> float:
    """Factor making ankle height + shank + thigh + trunk + head equal the stature.

    de Leva's lengths are landmark distances, not all vertical; their sum overshoots the stature by ~1-2 %.
    """
    t = DE_LEVA[sex]
    total = ANKLE_HEIGHT * STATURE_MM[sex] + sum(t[s][3] for s in ("shank", "thigh", "trunk", "head"))
    return STATURE_MM[sex] / total


def segment_inertias(height_m: float, mass_kg: float, sex: str = "male") -> dict[str, SegmentInertia]:
    """de Leva's segments scaled to a subject: head, torso, pelvis, upper_arm, forearm, hand, thigh, shank, foot.

    Lengths scale with stature, masses with body mass; inertias are m (r L)^2. The torso and pelvis split the trunk
    (see the module docstring); their COM distances are from their lower ends (pelvis: mid-hip; torso: lumbar joint),
    the head's from C7, all others from the proximal joint.
    """
    check_subject(height_m, mass_kg, sex)
    t = DE_LEVA[sex]
    k = height_m * 1e3 / STATURE_MM[sex] * vertical_length_factor(sex)  # mm of the table -> this subject

    def seg(name: str) -> tuple[float, float, float, np.ndarray]:
        pct, com, radii, length_mm = t[name]
        length = length_mm * 1e-3 * k
        mass = pct / 100.0 * mass_kg
        r = np.array(radii) / 100.0 * length
        return length, mass, com / 100.0 * length, mass * r**2

    out: dict[str, SegmentInertia] = {}
    for name in ("upper_arm", "forearm", "hand", "thigh", "shank", "foot"):
        length, mass, com, inertia = seg(name)
        out[name] = SegmentInertia(length, mass, com, tuple(inertia))
    # head: COM given from the vertex; store it from C7 (the neck joint, its lower end)
    length, mass, com_from_vertex, inertia = seg("head")
    out["head"] = SegmentInertia(length, mass, length - com_from_vertex, tuple(inertia))

    # trunk = pelvis (LPT, omphalion -> mid-hip) + torso (C7 -> omphalion); heights above mid-hip
    l_tr, m_tr, com_tr_from_c7, i_tr = seg("trunk")
    l_lpt, m_lpt, com_lpt_from_omph, i_lpt = seg("lpt")
    z_tr = l_tr - com_tr_from_c7               # whole-trunk COM above mid-hip
    z_lpt = l_lpt - com_lpt_from_omph           # pelvis COM above mid-hip
    m_to = m_tr - m_lpt
    z_to = (m_tr * z_tr - m_lpt * z_lpt) / m_to
    # parallel-axis composition about the torso COM (x and y axes move; the long axis does not)
    shift_tr, shift_lpt = (z_tr - z_to) ** 2, (z_lpt - z_to) ** 2
    i_to = np.array([
        i_tr[0] + m_tr * shift_tr - i_lpt[0] - m_lpt * shift_lpt,
        i_tr[1] + m_tr * shift_tr - i_lpt[1] - m_lpt * shift_lpt,
        i_tr[2] - i_lpt[2],
    ])
    if np.any(i_to <= 0):
        raise AssertionError(f"torso inertia by composition is not positive: {i_to}")
    out["pelvis"] = SegmentInertia(l_lpt, m_lpt, z_lpt, tuple(i_lpt))
    out["torso"] = SegmentInertia(l_tr - l_lpt, m_to, z_to - l_lpt, tuple(i_to))
    return out


def ankle_height_m(height_m: float, sex: str = "male") -> float:
    """Ankle joint (lateral malleolus) height above the sole [m]."""
    return ANKLE_HEIGHT * height_m * vertical_length_factor(sex)
