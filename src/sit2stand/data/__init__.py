"""The files shipped inside the package: plants (``plants/*.yaml``), graphs (``graphs/*.yaml``), ROS parameter
files (``params/*.yaml``), robot profiles (``robots/*.yaml``) and Foxglove layouts (``layouts/*.json``), found with
:mod:`importlib.resources` so that an installed copy finds them too.

Each lookup takes a packaged file's name (``"default"``, ``"standup"``; ``.yaml`` optional) or a path: a name
resolves to the packaged file, an existing file is returned as it is, anything else raises
:class:`DataFileNotFound`, whose message lists the names there are::

    plant_path()                  # .../sit2stand/data/plants/default.yaml
    plant_path("heavy_front")     # .../sit2stand/data/plants/heavy_front.yaml
    plant_path("my/plant.yaml")   # Path("my/plant.yaml"), if that file exists
    graph_path("standup")         # .../sit2stand/data/graphs/standup.yaml
    params_path("recorder")       # .../sit2stand/data/params/recorder.yaml
"""

from __future__ import annotations

import atexit
import contextlib
import os
from importlib import resources
from pathlib import Path

from ..errors import Sit2StandError

KINDS = ("plants", "graphs", "params", "layouts", "robots")
SUFFIXES = (".yaml", ".yml")


class DataFileNotFound(Sit2StandError, FileNotFoundError):
    """Neither a packaged file's name nor an existing file; the message lists the packaged names."""

    def __str__(self) -> str:  # FileNotFoundError would format (errno, strerror) otherwise
        return str(self.args[0])


_extracted = contextlib.ExitStack()
atexit.register(_extracted.close)


def folder(kind: str) -> Path:
    """The packaged folder of ``kind`` (``plants``, ``graphs`` or ``params``) on the file system."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind of data file {kind!r} (known: {', '.join(KINDS)})")
    root = resources.files(__name__) / kind
    if isinstance(root, Path):          # an ordinary installed or source package
        return root
    # a zipped package: extract once for the life of the process (nodes and launchers need real files)
    return _extracted.enter_context(resources.as_file(root))


def names(kind: str) -> list[str]:
    """The names of the packaged files of ``kind``, without ``.yaml``."""
    return sorted(p.stem for p in folder(kind).iterdir() if p.suffix in SUFFIXES)


def _looks_like_path(text: str) -> bool:
    return os.sep in text or (os.altsep is not None and os.altsep in text) or text.endswith(SUFFIXES)


def find(kind: str, name_or_path: str | os.PathLike) -> Path:
    """A packaged file of ``kind`` by name, or an existing file by path (see the module's docstring).

    Raises:
        DataFileNotFound: neither; the message names what was asked for and the packaged names.
    """
    text = os.fspath(name_or_path)
    given = Path(text)
    if given.is_file():
        # an existing path as is; but a bare name ("default") means the packaged file even where a file of that
        # name happens to be in the working directory
        if _looks_like_path(text) or not (folder(kind) / f"{text}.yaml").is_file():
            return given
    if text and given.name == text:                     # a bare name: "default" or "default.yaml"
        for candidate in (text, *(f"{text}{suffix}" for suffix in SUFFIXES)):
            packaged = folder(kind) / candidate
            if packaged.suffix in SUFFIXES and packaged.is_file():
                return packaged
    singular = {"plants": "plant", "graphs": "graph", "params": "parameter", "robots": "robot profile"}[kind]
    raise DataFileNotFound(f"{text!r}: no such {singular} file, nor a packaged {singular} file's name "
                           f"(packaged: {', '.join(names(kind)) or 'none'})")


def plant_path(name_or_path: str | os.PathLike = "default") -> Path:
    """A plant file: a packaged plant's name (``default``, ``heavy_front``, ``cad``) or a path."""
    return find("plants", name_or_path)


def graph_path(name_or_path: str | os.PathLike) -> Path:
    """A graph file for ``sit2stand launch``: a packaged graph's name (``standup``, ``roundtrip``, ...) or a path."""
    return find("graphs", name_or_path)


def params_path(name_or_path: str | os.PathLike) -> Path:
    """A ROS parameter file: a packaged one's name (``recorder``, ``replayer``, ``human_com``) or a path."""
    return find("params", name_or_path)
