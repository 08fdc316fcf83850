"""Message types for bags: the ROS 2 Jazzy type store of `rosbags`, plus our own interfaces from msgs/.

rosbags (de)serialises CDR without a ROS install; it only needs each type's definition. Jazzy's standard types ship
with rosbags; ours are parsed from the ``.msg`` files of ``sit2stand_msgs``: the installed
``<prefix>/share/sit2stand_msgs/msg`` (the venv's, then each AMENT_PREFIX_PATH prefix's), else the source tree's
``msgs/``. Any other type can be added from an installed package's ``share`` folder with :func:`ensure_type`.
"""

from __future__ import annotations

import functools
import os
import sys
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore
from ..errors import Sit2StandError

OUR_PACKAGE = "sit2stand_msgs"


class UnknownMessageType(Sit2StandError, KeyError):
    """A message type whose definition is neither in the Jazzy store, nor in msgs/, nor in any share/ folder."""

    def __init__(self, msgtype: str, where: str = "") -> None:
        self.msgtype = msgtype
        super().__init__(f"unknown message type {msgtype!r}{' in ' + where if where else ''}: no definition in "
                         f"rosbags' Jazzy store, msgs/ or the share/ folders searched "
                         f"({', '.join(map(str, _share_dirs()))})")

    def __str__(self) -> str:  # KeyError quotes its message otherwise
        return str(self.args[0])


def _repo_msgs_dir() -> Path:
    """msgs/ of the source tree this module lives in (src/sit2stand/io/typestore.py -> <repo>/msgs): the fallback
    where sit2stand_msgs is not installed (an installed sit2stand has no such folder; the share/ copy is what the
    colcon build of msgs/ generated the live nodes' types from, so it comes first)."""
    return Path(__file__).resolve().parents[3] / "msgs"


def _share_dirs() -> list[Path]:
    """share/ folders to look in for ``<package>/msg/<Type>.msg``, most specific first."""
    dirs = [Path(sys.prefix) / "share"]
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share")
    return [d for d in dict.fromkeys(dirs) if d.is_dir()]


def _definition_file(msgtype: str) -> Path | None:
    """Where the ``.msg`` text of ``pkg/msg/Type`` is, or None."""
    pkg, kind, name = msgtype.split("/")
    candidates = [d / pkg / kind / f"{name}.msg" for d in _share_dirs()]
    if pkg == OUR_PACKAGE:
        candidates.append(_repo_msgs_dir() / pkg / kind / f"{name}.msg")
    return next((c for c in candidates if c.is_file()), None)


def our_message_types() -> list[str]:
    """Names (``sit2stand_msgs/msg/X``) of the messages defined in msgs/ (or the installed copy)."""
    for base in [d / OUR_PACKAGE / "msg" for d in _share_dirs()] + [_repo_msgs_dir() / OUR_PACKAGE / "msg"]:
        if base.is_dir():
            return sorted(f"{OUR_PACKAGE}/msg/{p.stem}" for p in base.glob("*.msg"))
    raise FileNotFoundError(f"no {OUR_PACKAGE}/msg folder in the share/ folders "
                            f"({', '.join(map(str, _share_dirs())) or 'none'}) nor in {_repo_msgs_dir()}: build msgs/ "
                            f"of the source repository with colcon into {sys.prefix}, or put the prefix it is "
                            f"installed in on AMENT_PREFIX_PATH")


def ensure_type(store: Typestore, msgtype: str) -> None:
    """Register ``msgtype`` (``pkg/msg/Type``) and the types it uses in ``store``, from their ``.msg`` files.

    Raises:
        UnknownMessageType: no definition found for it or one of its fields' types.
    """
    if msgtype in store.fielddefs:
        return
    if msgtype.count("/") != 2:
        raise UnknownMessageType(msgtype)
    path = _definition_file(msgtype)
    if path is None:
        raise UnknownMessageType(msgtype)
    types = get_types_from_msg(path.read_text(), msgtype)
    # Register dependencies first: field types named in the definition that the store lacks.
    for _name, (_consts, fields) in types.items():
        for _fname, fdesc in fields:
            for dep in _referenced_types(fdesc):
                if dep not in store.fielddefs and dep not in types:
                    ensure_type(store, dep)
    store.register(types)


def _referenced_types(fdesc) -> list[str]:
    """Type names referenced by one rosbags field description (nested, arrays and sequences)."""
    out = []
    kind, detail = fdesc
    if getattr(kind, "name", "") == "NAME":
        out.append(detail)
    elif getattr(kind, "name", "") in ("ARRAY", "SEQUENCE"):
        out += _referenced_types(detail[0])
    return out


@functools.lru_cache(maxsize=1)
def typestore() -> Typestore:
    """The shared type store: ROS 2 Jazzy standard types plus every message of sit2stand_msgs."""
    store = get_typestore(Stores.ROS2_JAZZY)
    for msgtype in our_message_types():
        ensure_type(store, msgtype)
    return store
