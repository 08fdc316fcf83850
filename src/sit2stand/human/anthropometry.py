"""Segment inertial parameters of an average adult, after de Leva (1996), and of children and adolescents.

Source: P. de Leva, "Adjustments to Zatsiorsky-Seluyanov's segment inertia parameters", J. Biomech. 29(9):1223-1230,
1996, Table 4 (male / female): segment mass as % of body mass, centre of mass (COM) position as % of segment length
from the named end, radii of gyration as % of segment length about the sagittal (x, antero-posterior), transverse
(y, medio-lateral) and longitudinal axes, and mean segment lengths [mm] with the mean stature (1741 mm male,
1735 mm female). The trunk's lower part (LPT, omphalion to mid-hip) is used as the pelvis segment; the torso is the
rest of the trunk (upper + middle trunk), whose COM and inertia follow from the whole trunk and the LPT by
composition, so that pelvis + torso reproduce the whole trunk exactly.

Children and adolescents (:func:`anthropometric_set`, chosen from the stature, or from an age when given): de Leva's
table is changed by growth factors, each segment's value multiplied by the children's value at that age over their
value at 18 years, so that the set is de Leva's exactly for adults and keeps his segment definitions.

- Mass fractions: R. K. Jensen, "Changes in segment inertia proportions between 4 and 20 years", J. Biomech.
  22(6-7):529-536, 1989 (12 boys, followed yearly; elliptical-zone photogrammetry). The head's (with neck) fraction
  of body mass is the paper's quadratic regression on age, 0.27881 - 0.021152 a + 0.00053168 a^2 (coefficients as
  listed by the AIST human-properties database, dhrt/properties/segment/k-13): 20.3 % at 4 years, 7.0 % at 18. The
  other segments (trunk, upper arm, forearm, hand, thigh, shank, foot) are the paper's mass proportions at 6 and at
  18 years (% of body mass, rounded to 0.1 %, as transcribed in github.com/wspr/body-segment-param,
  data/scaled-mass/jensen1989-6yr.csv and -18yr.csv), linearly interpolated in age between 6 and 18, held at the
  6-year values below 6, and rescaled so that they and the head make 100 %. The pelvis (de Leva's LPT) keeps its
  share of the trunk (assumed: only the whole trunk is used from Jensen). Jensen studied boys; girls get the same
  factors (assumed).
- Lengths (assumed growth proportions, not a transcribed table): the head (vertex to C7) scales with the classical
  head-to-stature canon (Robbins et al. 1928, "Growth", Yale; the often-redrawn figure of changing body proportions):
  1/5 of stature at 2 years, 1/6 at 6, 1/7 at 12, 1/8 adult (taken at 18), interpolated linearly in age; thigh and
  shank scale with the subischial leg length, 1 - sitting-height ratio, with approximate median sitting-height
  ratios of boys 0.56 at 4 years, 0.545 at 6, 0.53 at 9, 0.52 from 12 (read from the reference curves of Fredriks
  et al., Arch. Dis. Child. 90(8):807-812, 2005, rounded); the trunk (pelvis and torso alike) takes what is left of
  the stature; arms, hands, feet and the ankle height keep their adult fraction of stature (assumed).
- COM positions and radii of gyration (as % of segment length) stay de Leva's (assumed; Jensen 1986 and 1989 found
  them changing far less with age than the masses).
- Age from stature, when no age is given: median stature-for-age of boys (WHO 2006 standards to 5 years, WHO 2007
  reference from 5; rounded to 1 cm): 1.03 m at 4 years, 1.10 at 5, 1.16 at 6, 1.27 at 8, 1.38 at 10, 1.49 at 12,
  1.63 at 14, 1.73 at 16, 1.76 at 18. Jensen's range is 4 to 20 years: younger ages are taken as 4 (no
  extrapolation).
- Stature alone cannot tell a child from a small adult. From :data:`ADULT_STATURE_M` (1.45 m) up the set is de
  Leva's; below :data:`CHILD_STATURE_M` (1.30 m, ~8.5 years) it is the children's; in between, the two are blended
  linearly in stature (an assumed fade that keeps the model continuous in stature). With an age given, the stature
  plays no part.

Everything here is a pure function of stature [m], body mass [kg], sex ("male" / "female") and, optionally, age.
"""

from __future__ import annotations

from dataclasses import dataclass, field

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

ADULT_STATURE_M = 1.45
"""From this stature [m] up (no age given), de Leva's adult table is used unchanged."""
CHILD_STATURE_M = 1.30
"""Below this stature [m] (no age given), the children's set is used in full; in between, the two are blended."""
ADULT_AGE = 18.0
"""Age [years] at which the growth factors are 1: the children's set is de Leva's."""
MIN_AGE = 4.0
"""Youngest age [years] of Jensen's data; younger subjects get the 4-year set (no extrapolation)."""

BILATERAL = ("upper_arm", "forearm", "hand", "thigh", "shank", "foot")
"""Segments of the tables that come in pairs (counted twice in a body's total)."""

JENSEN_HEAD_FRACTION = (0.27881, -0.021152, 0.00053168)
"""Jensen (1989): head (with neck) mass as a fraction of body mass = c0 + c1 age + c2 age^2 (age in years)."""
JENSEN_AGES = (6.0, 18.0)
JENSEN_MASS_PCT = {
    "trunk": (43.0, 44.6), "upper_arm": (2.4, 3.6), "forearm": (1.3, 1.9), "hand": (0.8, 0.9),
    "thigh": (8.5, 11.4), "shank": (4.6, 4.8), "foot": (1.9, 1.7),
}
"""Jensen (1989): segment mass [% of body mass] at the ages :data:`JENSEN_AGES` (6 and 18 years)."""

HEAD_STATURE_DIVISOR = ((2.0, 6.0, 12.0, 18.0), (5.0, 6.0, 7.0, 8.0))
"""(ages [years], stature / head length): the classical canon, adult 1/8 taken at 18 years (approximate)."""
SITTING_HEIGHT_RATIO = ((4.0, 6.0, 9.0, 12.0, 18.0), (0.56, 0.545, 0.53, 0.52, 0.52))
"""(ages [years], sitting height / stature): approximate medians of boys (module docstring)."""
STATURE_FOR_AGE = ((4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0, 16.0, 17.0, 18.0),
                   (1.03, 1.10, 1.16, 1.22, 1.27, 1.33, 1.38, 1.43, 1.49, 1.56, 1.63, 1.69, 1.73, 1.75, 1.76))
"""(ages [years], median stature of boys [m]): WHO 2006 / 2007, rounded (module docstring)."""


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


def _vertical_factor(t: dict, sex: str) -> float:
    """Factor making ankle height + shank + thigh + trunk + head of table ``t`` equal the stature."""
    total = ANKLE_HEIGHT * STATURE_MM[sex] + sum(t[s][3] for s in ("shank", "thigh", "trunk", "head"))
    return STATURE_MM[sex] / total


def vertical_length_factor(sex: str) -> float:
    """Factor making ankle height + shank + thigh + trunk + head equal the stature.

    de Leva's lengths are landmark distances, not all vertical; their sum overshoots the stature by ~1-2 %.
    """
    return _vertical_factor(DE_LEVA[sex], sex)


def _mass_total(pct: dict[str, float]) -> float:
    """Whole-body total of per-segment masses (head, trunk, and each bilateral segment twice)."""
    return pct["head"] + pct["trunk"] + sum(2 * pct[n] for n in BILATERAL)


def jensen_mass_pct(age_years: float) -> dict[str, float]:
    """Jensen's (1989) segment masses [% of body mass] of a boy of ``age_years`` (clipped to 4..18): the head by his
    regression, the others interpolated between his 6- and 18-year proportions and rescaled to make 100 %."""
    a = float(np.clip(age_years, MIN_AGE, ADULT_AGE))
    c0, c1, c2 = JENSEN_HEAD_FRACTION
    head = 100.0 * (c0 + c1 * a + c2 * a * a)
    rest = {n: float(np.interp(a, JENSEN_AGES, v)) for n, v in JENSEN_MASS_PCT.items()}
    k = (100.0 - head) / (_mass_total({"head": 0.0, **rest}))
    return {"head": head, **{n: v * k for n, v in rest.items()}}


def growth_mass_factors(age_years: float) -> dict[str, float]:
    """Per segment of de Leva's table: Jensen's mass fraction at ``age_years`` over his fraction at 18 years (the
    pelvis, de Leva's LPT, takes the trunk's)."""
    now, adult = jensen_mass_pct(age_years), jensen_mass_pct(ADULT_AGE)
    out = {n: now[n] / adult[n] for n in now}
    out["lpt"] = out["trunk"]
    return out


def growth_length_factors(age_years: float, sex: str = "male") -> dict[str, float]:
    """Per segment of de Leva's table: its length relative to the stature at ``age_years`` (clipped to 4..18) over
    the adult's (module docstring): head by the head canon, thigh and shank by the subischial leg length, the trunk
    filling the rest of the stature, the others 1."""
    a = float(np.clip(age_years, MIN_AGE, ADULT_AGE))
    t = DE_LEVA[sex]
    head = HEAD_STATURE_DIVISOR[1][-1] / float(np.interp(a, *HEAD_STATURE_DIVISOR))
    leg = (1.0 - float(np.interp(a, *SITTING_HEIGHT_RATIO))) / (1.0 - SITTING_HEIGHT_RATIO[1][-1])
    trunk = (t["trunk"][3] + (1.0 - leg) * (t["shank"][3] + t["thigh"][3]) + (1.0 - head) * t["head"][3]) \
        / t["trunk"][3]
    out = {n: 1.0 for n in t}
    out.update(head=head, thigh=leg, shank=leg, trunk=trunk, lpt=trunk)
    return out


def age_from_stature(height_m: float) -> float:
    """Age [years] at which boys' median stature is ``height_m`` (:data:`STATURE_FOR_AGE`; 4..18 at the ends)."""
    ages, statures = STATURE_FOR_AGE
    return float(np.interp(height_m, statures, ages))


def child_weight(height_m: float) -> float:
    """Weight of the children's set for a stature (no age given): 1 below :data:`CHILD_STATURE_M`, 0 from
    :data:`ADULT_STATURE_M` up, linear in between."""
    return float(np.clip((ADULT_STATURE_M - height_m) / (ADULT_STATURE_M - CHILD_STATURE_M), 0.0, 1.0))


@dataclass(frozen=True)
class AnthropometricSet:
    """The segment table a subject gets. ``table`` is laid out as one sex of :data:`DE_LEVA`; ``age_years``: the age
    of its growth factors (None for de Leva's adults); ``child_weight``: 0 for de Leva's table, 1 for the children's
    set at that age, blended in between; ``age_from_stature``: the age was read from the stature, not given;
    ``length_factors``: each segment's length relative to the stature over de Leva's (exactly 1 for adults), e.g.
    for marker offsets given on an adult's head."""

    sex: str
    table: dict
    age_years: float | None = None
    child_weight: float = 0.0
    age_from_stature: bool = True
    length_factors: dict[str, float] = field(default_factory=lambda: {n: 1.0 for n in DE_LEVA["male"]})

    @property
    def is_adult(self) -> bool:
        return self.child_weight == 0.0

    def describe(self) -> str:
        """One line naming the set, for notes and summaries."""
        if self.is_adult:
            return f"segment table: de Leva (1996), adult {self.sex}"
        source = "from the stature" if self.age_from_stature else "given"
        text = (f"segment table: children's (Jensen 1989 mass fractions, growth length proportions) at "
                f"{self.age_years:.1f} years ({source})")
        if self.child_weight < 1.0:
            text += f", blended {100 * self.child_weight:.0f} % with de Leva's adult table"
        return text


def _child_table(sex: str, age_years: float, weight: float) -> tuple[dict, dict[str, float]]:
    """de Leva's table of ``sex`` with the growth factors at ``age_years``, blended by ``weight`` (module docstring):
    masses rescaled to de Leva's own total, the vertical chain kept at the stature; and the length factors used."""
    t = DE_LEVA[sex]
    mf = growth_mass_factors(age_years)
    lf = {n: 1.0 + weight * (f - 1.0) for n, f in growth_length_factors(age_years, sex).items()}
    grown = {n: t[n][0] * mf[n] for n in t}
    k = _mass_total({n: v[0] for n, v in t.items()}) / _mass_total(grown)
    table = {n: (pct + weight * (grown[n] * k - pct), com, radii, length * lf[n])
             for n, (pct, com, radii, length) in t.items()}
    return table, lf


def anthropometric_set(height_m: float, sex: str = "male", age_years: float | None = None) -> AnthropometricSet:
    """The segment table for a subject: de Leva's for adults, the children's set for children, a blend in between
    (module docstring). With ``age_years`` given, it decides alone (under 18: the children's set at that age)."""
    if sex not in DE_LEVA:
        raise InputError(f"sex must be 'male' or 'female', not {sex!r}")
    if age_years is not None:
        if not age_years >= 0:
            raise InputError(f"age {age_years:g} years is not a non-negative number")
        weight, age, from_stature = (1.0 if age_years < ADULT_AGE else 0.0), float(age_years), False
    else:
        weight, age, from_stature = child_weight(height_m), age_from_stature(height_m), True
    if weight == 0.0:
        return AnthropometricSet(sex, DE_LEVA[sex], None, 0.0, from_stature)
    age = float(np.clip(age, MIN_AGE, ADULT_AGE))
    table, length_factors = _child_table(sex, age, weight)
    return AnthropometricSet(sex, table, age, weight, from_stature, length_factors)


def segment_inertias(height_m: float, mass_kg: float, sex: str = "male",
                     age_years: float | None = None) -> dict[str, SegmentInertia]:
    """The segment table's segments scaled to a subject: head, torso, pelvis, upper_arm, forearm, hand, thigh, shank,
    foot. The table is :func:`anthropometric_set`'s: de Leva's for adults, the children's set for children.

    Lengths scale with stature, masses with body mass; inertias are m (r L)^2. The torso and pelvis split the trunk
    (see the module docstring); their COM distances are from their lower ends (pelvis: mid-hip; torso: lumbar joint),
    the head's from C7, all others from the proximal joint.
    """
    check_subject(height_m, mass_kg, sex)
    t = anthropometric_set(height_m, sex, age_years).table
    k = height_m * 1e3 / STATURE_MM[sex] * _vertical_factor(t, sex)  # mm of the table -> this subject

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


def ankle_height_m(height_m: float, sex: str = "male", age_years: float | None = None) -> float:
    """Ankle joint (lateral malleolus) height above the sole [m] (with :func:`anthropometric_set`'s table)."""
    return ANKLE_HEIGHT * height_m * _vertical_factor(anthropometric_set(height_m, sex, age_years).table, sex)
