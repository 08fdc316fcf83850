"""Where sit2stand keeps what it derives once and reuses: converted meshes, compiled kernels.

``$SIT2STAND_CACHE``, else ``~/.cache/sit2stand``; each kind of file in a folder of its own, named after inputs'
hashes, so that a changed input makes a new file and no file is ever stale.
"""

from __future__ import annotations

import os
from pathlib import Path


def cache_folder(kind: str) -> Path:
    """The cache folder for one kind of derived file (``meshes``, ``native``)."""
    root = os.environ.get("SIT2STAND_CACHE") or Path.home() / ".cache" / "sit2stand"
    return Path(root) / kind
