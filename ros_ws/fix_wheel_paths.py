"""Point the ROS 2 wheels' CMake exports at this interpreter instead of the manylinux build container.

The ``ros-jazzy-*`` wheels were built under ``/opt/python/cp3XX-cp3XX``; their CMake config files and ament
resource index still name that prefix, so ``colcon build`` of an interface package fails on a normal machine.
This rewrites, inside the virtual environment only:

* ``/opt/python/cp3XX-cp3XX/include/python3.X``     -> the interpreter's include directory,
* ``.../site-packages/numpy/_core/include``           -> ``numpy.get_include()``,
* ``/opt/python/cp3XX-cp3XX`` (any other use)        -> the virtual environment's prefix.

Run it with the venv's interpreter; it is idempotent and prints how many files it changed.
"""

from __future__ import annotations

import re
import sys
import sysconfig
from pathlib import Path

import numpy

BUILD_PREFIX = re.compile(r"/opt/python/cp3\d+-cp3\d+")


def rewrite_text(text: str, prefix: str, include_dir: str, numpy_include: str) -> str:
    """Return ``text`` with the manylinux build paths replaced by this environment's."""
    text = re.sub(BUILD_PREFIX.pattern + r"/include/python3\.\d+", include_dir, text)
    text = re.sub(BUILD_PREFIX.pattern + r"/lib/python3\.\d+/site-packages/numpy/_core/include", numpy_include, text)
    return BUILD_PREFIX.sub(prefix, text)


def main() -> int:
    prefix = Path(sys.prefix)
    include_dir = sysconfig.get_paths()["include"]
    if not (Path(include_dir) / "Python.h").exists():
        print(f"fix_wheel_paths: {include_dir}/Python.h is missing; install the interpreter's headers "
              f"(Debian: python3-dev)", file=sys.stderr)
        return 1
    changed = 0
    roots = [prefix / "share"]
    for root in roots:
        for path in root.rglob("*"):
            if not path.is_file() or path.stat().st_size > 2_000_000:
                continue
            try:
                text = path.read_text()
            except (UnicodeDecodeError, PermissionError):
                continue
            if "/opt/python/cp3" not in text:
                continue
            new = rewrite_text(text, str(prefix), include_dir, numpy.get_include())
            if new != text:
                path.write_text(new)
                changed += 1
    print(f"fix_wheel_paths: rewrote {changed} file(s) under {prefix}/share")
    return 0


if __name__ == "__main__":
    sys.exit(main())
