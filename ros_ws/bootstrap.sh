#!/usr/bin/env bash
# Set up everything sit2stand needs, idempotently: system tools (apt, only if missing), the .venv from pinned
# PyPI wheels (ROS 2 Jazzy included), the wheels' CMake paths fixed, msgs/ built with colcon into the venv, and
# the project's Python package installed (editable). Each step is skipped when its inputs have not changed.
#
#   ros_ws/bootstrap.sh            (what `make setup`, `make demo` and `make test` call)
#   PYTHON=python3.12 ros_ws/bootstrap.sh   (choose the interpreter; 3.11 or 3.12)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${SIT2STAND_VENV:-$ROOT/.venv}"
STAMPS="$VENV/.sit2stand-stamps"
say() { printf 'bootstrap: %s\n' "$*"; }
die() { printf 'bootstrap: error: %s\n' "$*" >&2; exit 1; }
t_start=$(date +%s)

# --- 1. An interpreter in 3.11..3.12 -------------------------------------------------------------------------
pick_python() {
  local cand
  for cand in "${PYTHON:-}" python3 python3.12 python3.11; do
    [ -n "$cand" ] || continue
    command -v "$cand" >/dev/null 2>&1 || continue
    if "$cand" -c 'import sys; sys.exit(0 if (3, 11) <= sys.version_info[:2] <= (3, 12) else 1)' 2>/dev/null; then
      command -v "$cand"; return 0
    fi
  done
  return 1
}
PY="$(pick_python)" || die "need Python 3.11 or 3.12 (ros-jazzy-* wheels exist for 3.10-3.12; the pinned numpy, scipy and mujoco have no 3.10 wheels); set PYTHON=..."

# --- 2. System tools, from apt only if missing -----------------------------------------------------------------
missing=()
command -v cmake >/dev/null 2>&1 || missing+=(cmake)
command -v g++ >/dev/null 2>&1 || missing+=(g++)
command -v make >/dev/null 2>&1 || missing+=(make)
"$PY" - <<'PY' || missing+=("python3-dev")
import os, sys, sysconfig
sys.exit(0 if os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h")) else 1)
PY
"$PY" -c 'import ensurepip, venv' 2>/dev/null || missing+=("python3-venv")
if [ ${#missing[@]} -gt 0 ]; then
  # Debian names the headers/venv packages after the interpreter's version (python3.11-dev).
  pyver="$("$PY" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')"
  pkgs=()
  for p in "${missing[@]}"; do
    case "$p" in python3-dev) pkgs+=("python${pyver}-dev");; python3-venv) pkgs+=("python${pyver}-venv");; *) pkgs+=("$p");; esac
  done
  command -v apt-get >/dev/null 2>&1 || die "missing ${pkgs[*]} and no apt-get to install them"
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  say "installing system packages: ${pkgs[*]}"
  $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${pkgs[@]}" >/dev/null
fi

# Offscreen rendering for the demo's frame strip (MuJoCo with MUJOCO_GL=egl): Mesa's EGL. Optional: without it the
# demo says so and skips the strip.
if ! ldconfig -p 2>/dev/null | grep -q "libEGL.so.1" && command -v apt-get >/dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  say "installing system packages: libegl1 libgl1-mesa-dri (offscreen rendering)"
  { $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libegl1 libgl1-mesa-dri \
      >/dev/null; } || say "could not install libegl1 (the demo will skip its rendered frames)"
fi

# --- 3. The virtual environment ----------------------------------------------------------------------------------
stamp_ok() { [ -f "$STAMPS/$1" ] && [ "$(cat "$STAMPS/$1")" = "$2" ]; }
stamp_set() { mkdir -p "$STAMPS"; printf '%s' "$2" > "$STAMPS/$1"; }
hash_of() { cat "$@" | sha256sum | cut -c1-16; }

want_py="$("$PY" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
if [ -x "$VENV/bin/python" ] && ! "$VENV/bin/python" -c "import sys; sys.exit(0 if '%d.%d' % sys.version_info[:2] == '$want_py' else 1)" 2>/dev/null; then
  say "removing $VENV (made with another Python)"; rm -rf "$VENV"
fi
if [ ! -x "$VENV/bin/python" ]; then
  say "creating $VENV with $PY ($want_py)"
  "$PY" -m venv "$VENV"
fi
VPY="$VENV/bin/python"

req_hash="$(hash_of "$ROOT/ros_ws/requirements.txt" "$ROOT/ros_ws/constraints.txt" "$ROOT/ros_ws/requirements-nodeps.txt")"
if ! stamp_ok requirements "$req_hash"; then
  say "installing pinned wheels (ros_ws/requirements.txt, constraints.txt)"
  "$VPY" -m pip install -q --disable-pip-version-check -r "$ROOT/ros_ws/requirements.txt" -c "$ROOT/ros_ws/constraints.txt"
  "$VPY" -m pip install -q --disable-pip-version-check --no-deps -r "$ROOT/ros_ws/requirements-nodeps.txt"
  "$VPY" "$ROOT/ros_ws/fix_wheel_paths.py"
  rm -f "$STAMPS/msgs"          # rebuilt interfaces against the new wheels
  stamp_set requirements "$req_hash"
fi

# --- 4. The interface packages (sit2stand_msgs, tf2_msgs), built with colcon into the venv -----------------------
msgs_hash="$(cd "$ROOT" && find msgs -type f | sort | xargs cat | sha256sum | cut -c1-16)"
if ! stamp_ok msgs "$msgs_hash" || ! "$VPY" -c 'import sit2stand_msgs.msg, tf2_msgs.msg' 2>/dev/null; then
  say "building msgs/ with colcon (install base: $VENV)"
  ( cd "$ROOT/ros_ws" && PATH="$VENV/bin:$PATH" "$VENV/bin/colcon" --log-base log build \
      --base-paths "$ROOT/msgs" --build-base build --install-base "$VENV" --merge-install \
      --event-handlers console_cohesion- summary+ \
      --cmake-args -DBUILD_TESTING=OFF "-DPython3_EXECUTABLE=$VPY" ) > "$ROOT/ros_ws/colcon-build.log" 2>&1 \
    || { tail -40 "$ROOT/ros_ws/colcon-build.log"; die "colcon build of msgs/ failed (full log: ros_ws/colcon-build.log)"; }
  "$VPY" -c 'import sit2stand_msgs.msg, sit2stand_msgs.srv, tf2_msgs.msg' \
    || die "built msgs/ but cannot import sit2stand_msgs or tf2_msgs"
  stamp_set msgs "$msgs_hash"
fi

# --- 5. The project's Python package (editable) --------------------------------------------------------------------
# pyproject.toml makes pip build an editable wheel (PEP 660) with the venv's setuptools (pinned; no download), so
# the console scripts land in $VENV/bin whatever the pip version (setup.cfg's lib/sit2stand is for colcon only).
pkg_hash="$(hash_of "$ROOT/src/pyproject.toml" "$ROOT/src/setup.py" "$ROOT/src/setup.cfg" "$ROOT/src/package.xml")"
if ! stamp_ok package "$pkg_hash" || ! "$VPY" -c 'import sit2stand' 2>/dev/null; then
  say "installing the sit2stand package (editable, from src/)"
  "$VPY" -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e "$ROOT/src"
  stamp_set package "$pkg_hash"
fi

# --- 6. The compiled IK kernels (sit2stand.native: C99, the host's cc; cached by a hash of the source) -------------
# Built here once, not inside the first IK call; without a C compiler the IK keeps its NumPy path, and says so.
"$VPY" -c 'import sys; from sit2stand import native; sys.exit(native.kernels() is None)' \
  || say "no compiled IK kernels (no C compiler as \$CC or cc, or the build failed): the IK runs its NumPy path"

say "ready in $(( $(date +%s) - t_start )) s: $VENV ($("$VPY" -c 'import sys; print(sys.version.split()[0])'))"
