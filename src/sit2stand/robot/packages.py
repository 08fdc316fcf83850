"""Files that robot descriptions name by URI: ``package://PACKAGE/PATH`` of a package installed from PyPI (no ROS
install, no ``ROS_PACKAGE_PATH``), ``file://`` paths and plain paths; the URDF's mesh URIs rewritten either way, and
a package's meshes served by URI (the ``foxglove`` node's asset fetching).
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

PACKAGE_SHARES = {"example-robot-data": ("cmeel.prefix", "share", "example-robot-data")}
"""Packages whose ``package://`` URIs resolve here without a ROS install: the folder under a ``sys.path`` entry."""


def package_share(package: str) -> Path | None:
    """The installed folder that ``package://<package>/`` means, or None."""
    parts = PACKAGE_SHARES.get(package)
    for base in map(Path, sys.path):
        d = base.joinpath(*parts) if parts else None
        if d is not None and d.is_dir():
            return d
    return None


def package_folder(package: str, near: Path | None = None) -> Path | None:
    """The folder ``package://<package>/`` means: an installed one (:func:`package_share`); else one named so
    among ``near``'s ancestors or their children (a description repository's layout: unitree_ros's
    ``robots/h1_description/urdf/h1.urdf`` names ``package://h1_description/meshes/...``); else one under an entry of
    ``ROS_PACKAGE_PATH`` or ``AMENT_PREFIX_PATH`` (``share/<package>``). None where none is."""
    share = package_share(package)
    if share is not None:
        return share
    here = Path(near).resolve() if near is not None else None
    for base in [here, *here.parents] if here is not None else []:
        if base.name == package:
            return base
        if (base / package).is_dir():
            return base / package
    for var, sub in (("ROS_PACKAGE_PATH", ()), ("AMENT_PREFIX_PATH", ("share",))):
        for entry in filter(None, os.environ.get(var, "").split(os.pathsep)):
            d = Path(entry).joinpath(*sub, package)
            if d.is_dir():
                return d
    return None


def resolve_uri(uri: str, relative_to: Path | None = None) -> Path:
    """A file path of a ``package://`` URI (:func:`package_folder`, searched from ``relative_to`` too), a ``file://``
    URI or a path (relative paths: to ``relative_to``)."""
    if uri.startswith("package://"):
        package, _, rest = uri[len("package://"):].partition("/")
        folder = package_folder(package, relative_to)
        if folder is None:
            raise FileNotFoundError(f"{uri}: package {package!r} is neither installed here (known: "
                                    f"{', '.join(PACKAGE_SHARES)}) nor a folder beside the file that names it, nor "
                                    "in ROS_PACKAGE_PATH or AMENT_PREFIX_PATH")
        return folder / rest
    if uri.startswith("file://"):
        return Path(uri[len("file://"):])
    p = Path(os.path.expanduser(uri))
    return p if p.is_absolute() or relative_to is None else relative_to / p


MESH_FILENAME = r'(<mesh\b[^>]*?\bfilename=)'
"""A ``<mesh filename=`` attribute up to its value (other ``filename`` attributes, such as Gazebo plugins', are no
URIs to resolve)."""
MESH_SUFFIXES = (".stl", ".dae", ".obj", ".glb", ".gltf", ".ply", ".png", ".jpg", ".jpeg")
"""What :func:`package_asset` serves: meshes and their textures."""


def package_uris(urdf_text: str) -> str:
    """The URDF with every ``file://`` mesh URI inside a package of :data:`PACKAGE_SHARES` written back as
    ``package://PACKAGE/...`` (what a Foxglove client fetches through the live connection); others as they are."""
    shares = {pkg: share for pkg in PACKAGE_SHARES if (share := package_share(pkg)) is not None}

    def relative(match: re.Match) -> str:
        path = Path(match.group(2))
        for pkg, share in shares.items():
            if path.is_relative_to(share):
                return f'{match.group(1)}"package://{pkg}/{path.relative_to(share).as_posix()}"'
        return match.group(0)
    return re.sub(MESH_FILENAME + r'"file://([^"]+)"', relative, urdf_text)


def package_asset(uri: str) -> bytes | None:
    """The bytes of a mesh (or texture) a ``package://`` or ``file://`` URI names inside a package of
    :data:`PACKAGE_SHARES`; None for anything else (no other file of this machine is served)."""
    try:
        path = resolve_uri(uri).resolve()
    except FileNotFoundError:
        return None
    if path.suffix.lower() not in MESH_SUFFIXES or not path.is_file():
        return None
    shares = [share.resolve() for pkg in PACKAGE_SHARES if (share := package_share(pkg)) is not None]
    if not any(path.is_relative_to(share) for share in shares):
        return None
    return path.read_bytes()


def mesh_uris_to_files(urdf_text: str, urdf_path: Path) -> str:
    """The URDF with every mesh URI (``package://``, relative) an absolute file path of this machine. A mesh found
    nowhere is a :class:`FileNotFoundError` naming the URDF and the URI."""
    def absolute(match: re.Match) -> str:
        uri = match.group(2)
        try:
            path = resolve_uri(uri, urdf_path.parent)
        except FileNotFoundError as e:
            raise FileNotFoundError(f"{urdf_path}: mesh {e}") from None
        if not path.is_file():
            raise FileNotFoundError(f"{urdf_path}: mesh {uri}: no file {path}")
        return f'{match.group(1)}"{path}"'
    return re.sub(MESH_FILENAME + r'"([^"]+)"', absolute, urdf_text)
