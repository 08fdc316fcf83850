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


def resolve_uri(uri: str, relative_to: Path | None = None) -> Path:
    """A file path of a ``package://`` URI, a ``file://`` URI or a path (relative paths: to ``relative_to``)."""
    if uri.startswith("package://"):
        package, _, rest = uri[len("package://"):].partition("/")
        share = package_share(package)
        if share is None:
            raise FileNotFoundError(f"{uri}: package {package!r} is not installed here (known: "
                                    f"{', '.join(PACKAGE_SHARES)})")
        return share / rest
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
    """The URDF with every mesh URI (``package://``, relative) an absolute file path of this machine."""
    def absolute(match: re.Match) -> str:
        uri = match.group(2)
        try:
            path = resolve_uri(uri, urdf_path.parent)
        except FileNotFoundError:
            return match.group(0)
        return f'{match.group(1)}"{path}"'
    return re.sub(MESH_FILENAME + r'"([^"]+)"', absolute, urdf_text)
