#!/usr/bin/env bash
# Create .venv, install every dependency from PyPI and build the interface packages (msg_defs/) into the venv.
# Idempotent: each step is skipped when its inputs have not changed since it last succeeded.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
VENV=$ROOT/.venv
PY=${PYTHON:-python3}
STAMPS=$VENV/.stamps

# System packages (Debian 12): compilers and cmake for the interface build (gcc also for the Q-Tree C kernel,
# qtree_task_planner/learning/kernel.py, which falls back to Python without it), Mesa EGL for
# MuJoCo's headless renderer (MUJOCO_GL=egl). Installed only when missing.
SYS_PKGS="cmake gcc g++ libegl1 libegl-mesa0 libgl1-mesa-dri libgles2 graphviz"  # graphviz: dot draws Fig. 3
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

# --no-compile: the wheels' .py files are byte-compiled when first imported, not all at install (25 s of 75 here).
pip_install() { "$VENV/bin/python" -m pip install -q --no-compile --disable-pip-version-check "$@"; }

step pip-upgrade scripts/setup_env.sh -- pip_install --upgrade "pip>=24"
step requirements requirements.txt requirements-build.txt -- pip_install -r requirements.txt -r requirements-build.txt
# The project itself, editable: the node executables in .venv/bin (task_planner, motion_planner, jaco2_sim_driver,
# perception, qtree) run this checkout's code and find config/ through relocation_common.paths.
install_project() {
  pip_install --no-deps -e . > "$STAMPS/project.log" 2>&1 || { tail -30 "$STAMPS/project.log"; exit 1; }
}
# The stamp holds the checkout the install points to: a venv shared with a git worktree (a symlink) that `./run`
# repointed there is pointed back at this checkout by its next `./run`.
[ "$(cat "$STAMPS/project" 2>/dev/null)" = "$ROOT" ] || rm -f "$STAMPS/project"
step project setup.py setup.cfg -- install_project
echo "$ROOT" > "$STAMPS/project"

# Interface packages under msg_defs/, each built with plain cmake (build dir build/<pkg>) and installed
# into the venv itself, so no environment setup is needed to import them:
#   qtree_relocation_msgs  this project's messages, services and actions
#   kinova_msgs            the kinova_msgs definitions of Kinova's kinova-ros driver that this project uses, unchanged
#   tf2_msgs               tf2_msgs/msg/TFMessage of ROS 2 Jazzy (there is no ros-jazzy-tf2-msgs wheel on PyPI)
# kinova_msgs is not built when QTREE_SKIP_KINOVA_MSGS=1 (a real kinova_msgs is installed), nor when
# `import kinova_msgs` already works from outside the venv (e.g. a sourced ROS 2 workspace); the types this
# project uses are then checked in the installed one.

# check_msgs PKG PYTHON_IMPORTS: the imports work and every imported type loads its C type support.
check_msgs() {
  "$VENV/bin/python" -c "$2
from rclpy.type_support import check_for_type_support
for _obj in list(globals().values()):
    if isinstance(_obj, type) and _obj.__module__.startswith('$1.'):
        check_for_type_support(_obj)"
}

# build_msgs PKG PYTHON_IMPORTS. CMAKE_BUILD_TYPE=None: no optimisation flags. The generated type support only
# (de)serializes this project's small messages; compiled with Release's -O3 it took 36 s instead of 24 s to build.
# QTREE_PYTHON_ONLY=ON: the C and Python generators only, for rclpy (msg_defs/cmake/python_only_generators.cmake).
build_msgs() {
  local pkg=$1 build=$ROOT/build/$1
  rm -rf "$build"; mkdir -p "$build"
  ( source "$VENV/bin/activate"
    export CMAKE_PREFIX_PATH=$VENV AMENT_PREFIX_PATH=$VENV
    cmake -S "$ROOT/msg_defs/$pkg" -B "$build" -DCMAKE_INSTALL_PREFIX="$VENV" -DBUILD_TESTING=OFF \
      -DPython3_EXECUTABLE="$VENV/bin/python" -DCMAKE_BUILD_TYPE=None -DQTREE_PYTHON_ONLY=ON > "$build/cmake.log" 2>&1 \
      || { tail -30 "$build/cmake.log"; exit 1; }
    cmake --build "$build" -j2 >> "$build/cmake.log" 2>&1 || { tail -30 "$build/cmake.log"; exit 1; }
    cmake --install "$build" >> "$build/cmake.log" 2>&1 || { tail -30 "$build/cmake.log"; exit 1; } )
  check_msgs "$pkg" "$2" || { echo "error: $pkg built but does not import" >&2; exit 1; }
}

# Inputs of a package's build step: its files, its directories (a file added or removed) and the wheels.
msgs_inputs() { echo msg_defs/$1 msg_defs/$1/* msg_defs/$1/*/* msg_defs/cmake/* requirements.txt requirements-build.txt; }

# The three packages are independent: their builds run side by side (each configure is one core's work), and a
# failure of any stops the set-up once all have ended.
build_pids=()
step msgs-qtree_relocation_msgs $(msgs_inputs qtree_relocation_msgs) -- build_msgs qtree_relocation_msgs \
  "from qtree_relocation_msgs.msg import ObjectState, ObjectArray
from qtree_relocation_msgs.srv import PlanFeasibility
from qtree_relocation_msgs.action import RelocateObject, TrainPlanner" &
build_pids+=($!)

KINOVA_MSGS_IMPORTS="from kinova_msgs.msg import JointVelocity, JointAngles, FingerPosition
from kinova_msgs.srv import HomeArm, Start, Stop
from kinova_msgs.action import SetFingersPosition, ArmJointAngles"
# Where `import kinova_msgs` resolves (empty: not importable).
kinova_at=$("$VENV/bin/python" -c 'import kinova_msgs; print(list(kinova_msgs.__path__)[0])' 2>/dev/null || true)
if [ "${QTREE_SKIP_KINOVA_MSGS:-0}" = 1 ] || { [ -n "$kinova_at" ] && [[ "$kinova_at" != "$VENV"/* ]]; }; then
  if [ -z "$kinova_at" ]; then
    echo "[setup] warning: QTREE_SKIP_KINOVA_MSGS=1 but kinova_msgs does not import here;" \
      "make it importable (source its workspace) before running the nodes" >&2
  else
    echo "[setup] kinova_msgs: not built, using the one at $kinova_at"
    check_msgs kinova_msgs "$KINOVA_MSGS_IMPORTS" \
      || { echo "error: the kinova_msgs at $kinova_at lacks types this project uses" >&2; exit 1; }
  fi
else
  step msgs-kinova_msgs $(msgs_inputs kinova_msgs) -- build_msgs kinova_msgs "$KINOVA_MSGS_IMPORTS" &
  build_pids+=($!)
fi

step msgs-tf2_msgs $(msgs_inputs tf2_msgs) -- build_msgs tf2_msgs "from tf2_msgs.msg import TFMessage" &
build_pids+=($!)
failed=0
for pid in "${build_pids[@]}"; do wait "$pid" || failed=1; done
[ $failed = 0 ] || { echo "error: an interface package failed to build (its log: build/<package>/cmake.log)" >&2; exit 1; }
