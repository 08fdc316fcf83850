"""Meshes that MuJoCo and Rerun can read: a URDF's COLLADA files (``.dae``: iCub's, Romeo's, many ROS robots'),
which neither decodes, converted once to Wavefront OBJ.

The conversion keeps the file's triangles as its scene places them (its nodes' transforms applied), scaled to metres
by its ``<unit meter=...>`` and turned so that its ``<up_axis>`` is z, as RViz shows such a file: iCub's meshes are
``Y_UP``, and only turned do they lie along their links (a thigh from hip to knee). Polygons are fanned into
triangles. The OBJ files go to a cache folder (``$SIT2STAND_CACHE``, else ``~/.cache/sit2stand``), named after the
source file's path, size and time stamp, and are written whole or not at all.
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
import warnings
from pathlib import Path

import collada
import numpy as np

from .. import cache
from ..errors import Sit2StandError
from .packages import MESH_FILENAME

UP_AXIS_TO_Z = {"X_UP": np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
                "Y_UP": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
                "Z_UP": np.eye(3)}
"""The rotation that takes a COLLADA file's up axis to z (COLLADA's default is Y_UP)."""
CONVERTED_SUFFIXES = (".dae",)
CONVERSION = 2
"""Part of a converted file's name: raised when the conversion changes, so that no older file is reused."""
"""Mesh formats converted to OBJ (MuJoCo reads STL, OBJ and MSH; Rerun STL, OBJ, glTF and GLB)."""


UNCOLOURED_RGBA = np.array([0.8, 0.8, 0.8, 1.0])
"""How a mesh its URDF leaves transparent or black is shown (iCub's file colours every mesh black, which vanishes
against the viewers' dark backgrounds)."""


def shown_rgba(rgba) -> np.ndarray:
    """A URDF mesh colour as the viewers show it: itself, or :data:`UNCOLOURED_RGBA` for a transparent or black one."""
    rgba = np.clip(np.asarray(rgba, float), 0.0, 1.0)
    return rgba if rgba[3] > 0 and rgba[:3].any() else UNCOLOURED_RGBA.copy()


class MeshError(Sit2StandError, ValueError):
    """A mesh file that cannot be read or converted (the message names it)."""


def cache_folder() -> Path:
    """Where converted meshes are kept."""
    return cache.cache_folder("meshes")


def readable_mesh(path: Path) -> Path:
    """``path`` itself, or for a COLLADA file its OBJ conversion (made on first use)."""
    path = Path(path)
    if path.suffix.lower() not in CONVERTED_SUFFIXES:
        return path
    stat = path.stat()
    key = hashlib.sha1(f"{CONVERSION}|{path.resolve()}|{stat.st_size}|{stat.st_mtime_ns}".encode()).hexdigest()[:16]
    out = cache_folder() / f"{path.stem}-{key}.obj"
    if not out.is_file():
        vertices, faces = collada_triangles(path)
        write_obj(out, vertices, faces, source=path)
    return out


def readable_mesh_files(urdf_text: str) -> str:
    """The URDF (its mesh filenames absolute paths already) with each COLLADA mesh replaced by its OBJ."""
    def readable(match: re.Match) -> str:
        path = Path(match.group(2))
        if path.suffix.lower() not in CONVERTED_SUFFIXES or not path.is_file():
            return match.group(0)
        return f'{match.group(1)}"{readable_mesh(path)}"'
    return re.sub(MESH_FILENAME + r'"([^"]+)"', readable, urdf_text)


def collada_triangles(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of a COLLADA file: vertices (N, 3) [m] and faces (M, 3) (vertex indices).

    Raises:
        MeshError: naming the file, when it cannot be parsed or holds no triangles.
    """
    with warnings.catch_warnings():       # pycollada 0.9 builds numpy.matrix objects, which numpy warns about
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        return _triangles(path)


def _triangles(path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        doc = collada.Collada(str(path), ignore=[collada.common.DaeUnsupportedError,
                                                 collada.common.DaeBrokenRefError])
    except Exception as err:  # noqa: BLE001 - pycollada raises many kinds on a broken file
        raise MeshError(f"{path}: not a readable COLLADA file: {err}") from None
    unit = float(getattr(doc.assetInfo, "unitmeter", None) or 1.0)
    up = UP_AXIS_TO_Z.get(str(getattr(doc.assetInfo, "upaxis", None) or "Y_UP"), UP_AXIS_TO_Z["Y_UP"])
    geometries = doc.scene.objects("geometry") if doc.scene is not None else \
        [g.bind(np.identity(4), {}) for g in doc.geometries]
    vertices, faces, n = [], [], 0
    for geometry in geometries:
        for primitive in geometry.primitives():
            if hasattr(primitive, "triangleset"):          # polylists and polygons: fanned into triangles
                primitive = primitive.triangleset()
            if not hasattr(primitive, "vertex_index") or primitive.vertex is None or not len(primitive.vertex_index):
                continue                                    # lines and points carry no surface
            vertices.append(np.asarray(primitive.vertex, float).reshape(-1, 3))
            faces.append(np.asarray(primitive.vertex_index, int).reshape(-1, 3) + n)
            n += len(vertices[-1])
    if not faces:
        raise MeshError(f"{path}: no triangles in this COLLADA file")
    return np.vstack(vertices) @ (unit * up).T, np.vstack(faces)


def write_obj(out: Path, vertices: np.ndarray, faces: np.ndarray, source: Path | None = None) -> None:
    """A Wavefront OBJ of ``vertices`` (N, 3) and ``faces`` (M, 3), written to a temporary file and renamed."""
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile("w", dir=out.parent, suffix=".tmp", delete=False) as f:
        if source is not None:
            f.write(f"# converted by sit2stand from {source}\n")
        np.savetxt(f, vertices, fmt="v %.7g %.7g %.7g")
        np.savetxt(f, faces + 1, fmt="f %d %d %d")
    os.replace(f.name, out)
