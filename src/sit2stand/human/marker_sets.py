"""Marker sets as data: which segment each marker sits on, roughly where, and which markers define the pelvis.

A marker set is a YAML file. The packaged ones live in ``sit2stand/data/marker_sets/`` (``plug_in_gait``: Vicon
Plug-in-Gait full body, the default; ``plug_in_gait_lower``: its lower body, with an optional sacral marker;
``gait2392``: the OpenSim Gait2392 example subject's markers). A user's own file is passed by path. Format::

    name: my_set
    description: one line
    pelvis:                        # a frame's pelvis is defined by 3 valid markers of any_three_of,
      any_three_of: [LASI, RASI, LPSI, RPSI]
      asis: [LASI, RASI]           # or by both ASIS markers and one valid sacral marker
      sacral: [SACR]
    markers:                       # in this order the markers become frames of the skeleton
      LASI: {segment: pelvis, mm: [60, 120, 70], mm_length_scaled: yz}
      LTHI: {segment: thigh_l, mm: [15, 75, 0], of_length: [0, 0, -0.6]}

Each marker sits on one of the skeleton's segments (:data:`sit2stand.human.skeleton.SEGMENTS`) at an offset in that
segment's joint frame (REP-103 at the zero posture: x forward, y left, z up; the origin is the segment's proximal
joint, the pelvis's at the mid-hip point). Per axis the offset is, in metres,

    mm * 1e-3 * stature / 1.75 [* the segment's length factor, on the axes of ``mm_length_scaled``]
    + of_length * the segment's length + of_ankle_height * the ankle's height above the sole

``mm``: millimetres for a 1.75 m subject, scaled with the stature; ``of_length``: fractions of the segment's
length (de Leva's, times the subject's length factor; the toes use the foot's length; limbs hang along -z, so a
point down a limb has a negative fraction); ``of_ankle_height``: fractions of the ankle's height (feet only, so that
a heel marker stays on the sole). All three default to zero. On the head, ``mm`` also grows with the segment table's
head-to-stature factor (a child's head is larger for its stature; 1 for adults). The offsets are approximate: the
calibration (a marker placer, :mod:`sit2stand.human.calibration`) moves each marker to the data.

When a stream's names do not say which set they are, :func:`choose_marker_set` takes the packaged set that covers
most of them.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import yaml

from ..errors import Sit2StandError

DEFAULT_MARKER_SET = "plug_in_gait"
MIN_MARKERS = 8
"""Fewest markers of the set a stream (and a frame) needs, the pelvis's included."""
AXES = "xyz"
MARKER_KEYS = {"segment", "mm", "of_length", "of_ankle_height", "mm_length_scaled"}
PELVIS_KEYS = {"any_three_of", "asis", "sacral"}


class MarkerSetError(Sit2StandError, ValueError):
    """A marker set file that cannot be read, or a stream its markers cannot fit; the message names the file or
    the markers, what is missing and what would do."""


@dataclass(frozen=True)
class MarkerSpec:
    """One marker: its segment and the three parts of its offset (see the module docstring)."""

    name: str
    segment: str
    mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    of_length: tuple[float, float, float] = (0.0, 0.0, 0.0)
    of_ankle_height: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mm_length_scaled: str = ""

    def offset_m(self, mm_m: float, length_factor: float, length_m: float, ankle_height_m: float) -> list[float]:
        """The offset [m] in the segment's frame for a body whose 1 mm (at the reference stature) is ``mm_m``, whose
        segment has length factor ``length_factor`` and length ``length_m`` [m], and whose ankle is
        ``ankle_height_m`` [m] above the sole."""
        out = []
        for i, axis in enumerate(AXES):
            part = self.mm[i] * mm_m
            if axis in self.mm_length_scaled:
                part = part * length_factor
            out.append(part + self.of_length[i] * length_m + self.of_ankle_height[i] * ankle_height_m)
        return out


@dataclass(frozen=True)
class PelvisRule:
    """Which markers define the pelvis: 3 valid of ``any_three_of``, or both ``asis`` and 1 of ``sacral``."""

    any_three_of: tuple[str, ...] = ()
    asis: tuple[str, ...] = ()
    sacral: tuple[str, ...] = ()

    @property
    def markers(self) -> tuple[str, ...]:
        """Every marker the rule names, without repeats, in order."""
        return tuple(dict.fromkeys(self.any_three_of + self.asis + self.sacral))

    def defined_by(self, present: Iterable[str]) -> bool:
        """True if the markers ``present`` (valid in a frame, or carried by a stream) define the pelvis."""
        have = set(present)
        if sum(n in have for n in self.any_three_of) >= 3:
            return True
        return bool(self.asis) and all(n in have for n in self.asis) and any(n in have for n in self.sacral)

    def describe(self) -> str:
        """The rule in words, for error messages."""
        ways = []
        if self.any_three_of:
            ways.append(f"3 of {', '.join(self.any_three_of)}")
        if self.asis:
            ways.append(f"{' and '.join(self.asis)} with one of {', '.join(self.sacral)}")
        return " or ".join(ways)


@dataclass(frozen=True)
class MarkerSet:
    """A marker set: its markers in order, the pelvis rule, and where it came from."""

    name: str
    markers: tuple[MarkerSpec, ...]
    pelvis: PelvisRule
    description: str = ""
    source: str = ""

    @property
    def names(self) -> list[str]:
        """The marker names, in the set's order."""
        return [m.name for m in self.markers]

    def covered(self, stream_names: Iterable[str]) -> list[str]:
        """The names of ``stream_names`` this set carries, in the stream's order."""
        mine = set(self.names)
        return [n for n in stream_names if n in mine]

    def fits(self, stream_names: Iterable[str]) -> bool:
        """True if a stream with these names can be fitted: :data:`MIN_MARKERS` of the set's, the pelvis defined."""
        known = self.covered(stream_names)
        return len(known) >= MIN_MARKERS and self.pelvis.defined_by(known)

    def check_stream(self, stream_names: list[str]) -> list[str]:
        """The stream's names this set carries; raises :class:`MarkerSetError` naming what is missing (and the
        packaged set that would do) when the stream cannot be fitted."""
        known = self.covered(stream_names)
        if self.fits(stream_names):
            return known
        shown = ", ".join(known[:12]) + (", ..." if len(known) > 12 else "") or "none"
        missing = [n for n in self.pelvis.markers if n not in known]
        hint = _suggestion(stream_names, exclude=self.name)
        raise MarkerSetError(
            f"{len(known)} of the stream's {len(stream_names)} markers are markers of marker set {self.name!r} "
            f"({shown}); at least {MIN_MARKERS} are needed, including {self.pelvis.describe()}"
            + (f" (missing: {', '.join(missing)})" if missing else "") + hint)


def _vector(value, where: str, key: str) -> tuple[float, float, float]:
    """Three numbers from a YAML value; MarkerSetError naming ``where`` and ``key`` otherwise."""
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise MarkerSetError(f"{where}: {key} must be three numbers, got {value!r}") from None
    if len(out) != 3:
        raise MarkerSetError(f"{where}: {key} must be three numbers, got {value!r}")
    return out  # type: ignore[return-value]


def _marker(name: str, entry, where: str) -> MarkerSpec:
    """One marker entry of a marker set file."""
    here = f"{where}: marker {name}"
    if not isinstance(entry, dict) or "segment" not in entry:
        raise MarkerSetError(f"{here}: needs a mapping with a segment (e.g. {{segment: pelvis, mm: [60, 120, 70]}})")
    unknown = set(entry) - MARKER_KEYS
    if unknown:
        raise MarkerSetError(f"{here}: unknown key(s) {', '.join(sorted(unknown))} (known: "
                             f"{', '.join(sorted(MARKER_KEYS))})")
    scaled = str(entry.get("mm_length_scaled", "") or "")
    if set(scaled) - set(AXES):
        raise MarkerSetError(f"{here}: mm_length_scaled must name axes among x, y, z, got {scaled!r}")
    zero = (0, 0, 0)
    return MarkerSpec(str(name), str(entry["segment"]), _vector(entry.get("mm", zero), here, "mm"),
                      _vector(entry.get("of_length", zero), here, "of_length"),
                      _vector(entry.get("of_ankle_height", zero), here, "of_ankle_height"), scaled)


def parse_marker_set(doc, source: str) -> MarkerSet:
    """A :class:`MarkerSet` from a loaded YAML document; errors name ``source`` and the field."""
    if not isinstance(doc, dict) or not isinstance(doc.get("markers"), dict) or not doc["markers"]:
        raise MarkerSetError(f"{source}: not a marker set (needs a 'markers' mapping and a 'pelvis' rule)")
    markers = tuple(_marker(str(n), e, source) for n, e in doc["markers"].items())
    pel = doc.get("pelvis")
    if not isinstance(pel, dict) or set(pel) - PELVIS_KEYS:
        raise MarkerSetError(f"{source}: pelvis must be a mapping of {', '.join(sorted(PELVIS_KEYS))}, got {pel!r}")
    rule = PelvisRule(*(tuple(str(n) for n in (pel.get(k) or ())) for k in ("any_three_of", "asis", "sacral")))
    names = {m.name for m in markers}
    undefined = [n for n in rule.markers if n not in names]
    if undefined:
        raise MarkerSetError(f"{source}: the pelvis rule names markers the set lacks: {', '.join(undefined)}")
    if len(rule.any_three_of) < 3 and not (len(rule.asis) == 2 and rule.sacral):
        raise MarkerSetError(f"{source}: the pelvis needs any_three_of with 3 or more markers, or asis with 2 "
                             f"markers and sacral with 1 or more")
    name = str(doc.get("name") or Path(source).stem)
    return MarkerSet(name, markers, rule, str(doc.get("description", "")), source)


def packaged_folder() -> Path:
    """The folder of the packaged marker sets."""
    return Path(str(resources.files("sit2stand.data") / "marker_sets"))


def packaged_names() -> list[str]:
    """The names of the packaged marker sets (file stems)."""
    return sorted(p.stem for p in packaged_folder().glob("*.yaml"))


_CACHE: dict[str, MarkerSet] = {}
_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
"""libyaml's safe loader where PyYAML has it: the packaged sets in ~10 ms instead of ~0.1 s."""


def load_marker_set(name_or_path: str | os.PathLike | MarkerSet | None = None) -> MarkerSet:
    """A marker set: a packaged set's name (``plug_in_gait``, ``gait2392``...), a YAML file's path, or a
    :class:`MarkerSet` as it is; None is the default (Plug-in-Gait). Files are read once per process.

    Raises:
        MarkerSetError: no such packaged set or file, or a file that is not a marker set.
    """
    if isinstance(name_or_path, MarkerSet):
        return name_or_path
    text = os.fspath(name_or_path) if name_or_path is not None else DEFAULT_MARKER_SET
    path = Path(text)
    if not path.is_file():
        packaged = packaged_folder() / f"{Path(text).stem}.yaml"
        if path.name != text or not packaged.is_file():
            raise MarkerSetError(f"{text!r}: no such marker set file, nor a packaged marker set's name "
                                 f"(packaged: {', '.join(packaged_names())})")
        path = packaged
    key = str(path.resolve())
    if key not in _CACHE:
        try:
            doc = yaml.load(path.read_text(), Loader=_YAML_LOADER)
        except (OSError, yaml.YAMLError) as err:
            raise MarkerSetError(f"{path}: cannot read the marker set: {err}") from None
        _CACHE[key] = parse_marker_set(doc, str(path))
    return _CACHE[key]


def load_packaged_marker_sets() -> list[MarkerSet]:
    """Every packaged marker set, read now (a live node reads them at start-up, not at its first frame)."""
    return [load_marker_set(n) for n in packaged_names()]


def rank_marker_sets(stream_names: list[str]) -> list[tuple[MarkerSet, int]]:
    """The packaged sets with how many of ``stream_names`` each covers, best first (ties: the default first)."""
    sets = load_packaged_marker_sets()
    scored = [(s, len(s.covered(stream_names))) for s in sets]
    return sorted(scored, key=lambda sc: (-sc[1], sc[0].name != DEFAULT_MARKER_SET, len(sc[0].markers)))


def _suggestion(stream_names: list[str], exclude: str = "") -> str:
    """'; marker set X covers N of the names and would do' for the best packaged set that fits, or ''."""
    for s, n in rank_marker_sets(stream_names):
        if s.name != exclude and s.fits(stream_names):
            return f"; marker set {s.name!r} covers {n} of the stream's names and would do"
    return ""


def choose_marker_set(stream_names: list[str], given: str | os.PathLike | MarkerSet | None = None) -> MarkerSet:
    """The marker set for a stream: ``given`` (checked against the names), else the packaged set that covers most
    of the names and fits them.

    Raises:
        MarkerSetError: the given set does not fit the stream, or no packaged set does; the message names what is
            missing.
    """
    if given is not None:
        chosen = load_marker_set(given)
        chosen.check_stream(stream_names)
        return chosen
    ranked = rank_marker_sets(stream_names)
    for s, _ in ranked:
        if s.fits(stream_names):
            return s
    best, n = ranked[0]
    try:
        best.check_stream(stream_names)
    except MarkerSetError as err:
        raise MarkerSetError(f"no packaged marker set fits the stream's markers (best: {best.name!r}, {n} of "
                             f"{len(stream_names)} names): {err}; write a marker set file for them "
                             f"(see sit2stand.human.marker_sets)") from None
    return best
