#!/usr/bin/env bash
# Create .venv, install every dependency from PyPI and build the interface package into the venv.
# Idempotent: each step is skipped when its inputs have not changed since it last succeeded.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
VENV=$ROOT/.venv
PY=${PYTHON:-python3}
STAMPS=$VENV/.stamps

# System packages (Debian 12): compilers and cmake for the interface build (gcc also for the Q-Tree C kernel,
# qtree_task_planner/kernel.py, which falls back to Python without it), Mesa EGL for
# MuJoCo's headless renderer (MUJOCO_GL=egl). Installed only when missing.
SYS_PKGS="cmake gcc g++ libegl1 libegl-mesa0 libgl1-mesa-dri libgles2"
missing=$(for p in $SYS_PKGS; do dpkg -s "$p" >/dev/null 2>&1 || echo "$p"; done | tr '\n' ' ')
if [ -n "${missing// /}" ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "[setup] apt-get install $missing"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $missing >/dev/null
  else
    echo "error: missing system packages: $missing (install them with apt-get as root)" >&2; exit 1
  fi
fi
"$PY" -c 'import venv, ensurepip' 2>/dev/null || {
  echo "error: $PY lacks venv/ensurepip (Debian: apt-get install python3-venv)" >&2; exit 1; }

if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11), "Python 3.11 is required (ros-jazzy wheels are cp311)"' \
    || { echo "error: $PY is not Python 3.11; set PYTHON=/path/to/python3.11" >&2; exit 1; }
  echo "[setup] creating $VENV"
  "$PY" -m venv "$VENV"
fi
mkdir -p "$STAMPS"

# step NAME INPUT... -- CMD...: run CMD unless the stamp is newer than every input.
step() {
  local name=$1; shift
  local inputs=()
  while [ "$1" != "--" ]; do inputs+=("$1"); shift; done; shift
  local stamp=$STAMPS/$name
  if [ -f "$stamp" ]; then
    local stale=0
    for f in "${inputs[@]}"; do [ "$f" -nt "$stamp" ] && stale=1; done
    [ $stale = 0 ] && return 0
  fi
  echo "[setup] $name"
  "$@"
  touch "$stamp"
}

pip_install() { "$VENV/bin/python" -m pip install -q --disable-pip-version-check "$@"; }

step pip-upgrade scripts/setup_env.sh -- pip_install --upgrade "pip>=24"
step requirements requirements.txt requirements-build.txt -- pip_install -r requirements.txt -r requirements-build.txt

build_msgs() {
  local build=$ROOT/build/qtree_relocation_msgs
  rm -rf "$build"; mkdir -p "$build"
  ( source "$VENV/bin/activate"
    export CMAKE_PREFIX_PATH=$VENV AMENT_PREFIX_PATH=$VENV
    cmake -S "$ROOT/msg_defs" -B "$build" -DCMAKE_INSTALL_PREFIX="$VENV" -DBUILD_TESTING=OFF \
      -DPython3_EXECUTABLE="$VENV/bin/python" -DCMAKE_BUILD_TYPE=Release > "$build/cmake.log" 2>&1 \
      || { tail -30 "$build/cmake.log"; exit 1; }
    cmake --build "$build" -j2 >> "$build/cmake.log" 2>&1 || { tail -30 "$build/cmake.log"; exit 1; }
    cmake --install "$build" >> "$build/cmake.log" 2>&1 || { tail -30 "$build/cmake.log"; exit 1; } )
  "$VENV/bin/python" -c "from qtree_relocation_msgs.srv import PlanFeasibility" \
    || { echo "error: qtree_relocation_msgs built but does not import" >&2; exit 1; }
}
step msgs msg_defs/CMakeLists.txt msg_defs/package.xml msg_defs/msg/* msg_defs/srv/* msg_defs/action/* requirements.txt -- build_msgs

