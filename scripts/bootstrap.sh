#!/usr/bin/env bash
# One idempotent set-up step: .venv with pinned dependencies, the
# defgg_interfaces package built into it, defgg_ros installed editable.
# Each stage is skipped when the stamp of its inputs is unchanged, so a second
# run takes seconds.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv"
stamps="$venv/.defgg_stamps"
py="${PYTHON:-python3.11}"

say() { printf '[bootstrap] %s\n' "$*"; }
stamp_of() { cat "$@" | sha256sum | cut -c1-16; }
fresh() { [ -f "$stamps/$1" ] && [ "$(cat "$stamps/$1")" = "$2" ]; }
mark() { mkdir -p "$stamps"; echo "$2" > "$stamps/$1"; }

command -v "$py" >/dev/null || { echo "bootstrap: $py not found (Python 3.11 is required)" >&2; exit 1; }
if [ ! -x "$venv/bin/python" ]; then
  say "creating $venv"
  "$py" -m venv "$venv"
fi

req_stamp=$(stamp_of "$root/requirements.lock")
if ! fresh requirements "$req_stamp"; then
  say "installing pinned dependencies (first run: a few minutes)"
  "$venv/bin/python" -m pip install -q --upgrade pip
  # torch==2.13.0 resolves to the CPU wheel on disk; see README.
  "$venv/bin/python" -m pip install -q -r "$root/requirements.lock"
  mark requirements "$req_stamp"
fi

# The rosidl wheels export two build-machine paths that do not exist here;
# point them at this interpreter's headers and numpy (idempotent rewrite).
"$venv/bin/python" "$root/scripts/fix_rosidl_paths.py" "$venv"

# Build one ament_cmake interface package from $1 (a folder of the repo) into the venv.
build_interfaces() {
  local src="$root/$1" name; name=$(basename "$1")
  local build="$venv/build/$name"
  say "building $1 ($name) into the venv"
  rm -rf "$build"; mkdir -p "$build"
  AMENT_PREFIX_PATH="$venv" cmake -S "$src" -B "$build" \
    -DCMAKE_PREFIX_PATH="$venv" -DCMAKE_INSTALL_PREFIX="$venv" \
    -DPython3_EXECUTABLE="$venv/bin/python" -DBUILD_TESTING=OFF > "$build.log" 2>&1 \
    || { tail -30 "$build.log"; exit 1; }
  AMENT_PREFIX_PATH="$venv" make -C "$build" -j2 >> "$build.log" 2>&1 || { tail -30 "$build.log"; exit 1; }
  # Installed through a staging folder, each file renamed over the old one: `make install` rewrites a file in
  # place (same inode), which can crash a running process that has the old shared library mapped; a renamed-over
  # file leaves it the old inode.
  local stage="$build/stage"
  AMENT_PREFIX_PATH="$venv" make -C "$build" install DESTDIR="$stage" >> "$build.log" 2>&1 \
    || { tail -30 "$build.log"; exit 1; }
  (cd "$stage$venv" && find . \( -type f -o -type l \) -print) | while IFS= read -r file; do
    mkdir -p "$(dirname "$venv/$file")"
    cp -P --preserve=mode,timestamps "$stage$venv/$file" "$venv/$file.new.$$"
    mv -f "$venv/$file.new.$$" "$venv/$file"
  done
  rm -rf "$stage"
}

msg_stamp=$(cd "$root" && stamp_of msg_defs/CMakeLists.txt msg_defs/package.xml msg_defs/*/*)
if ! fresh interfaces "$msg_stamp" || ! "$venv/bin/python" -c "import defgg_interfaces.msg" 2>/dev/null; then
  build_interfaces msg_defs
  mark interfaces "$msg_stamp"
fi

# The real cell's interface packages (franka_msgs, control_msgs, controller_manager_msgs, tf2_msgs) are not on
# PyPI: their definitions in vendor_interfaces/ are built here for the venv only (colcon ignores that folder,
# a ROS install uses the real packages; see vendor_interfaces/README.md).
vendor_stamp=$(cd "$root" && stamp_of vendor_interfaces/*/CMakeLists.txt vendor_interfaces/*/package.xml \
  vendor_interfaces/*/*/*)
if ! fresh vendor_interfaces "$vendor_stamp" \
    || ! "$venv/bin/python" -c "from franka_msgs.action import ErrorRecovery, Grasp; from control_msgs.action \
import FollowJointTrajectory, GripperCommand; from controller_manager_msgs.srv import SwitchController; \
from tf2_msgs.msg import TFMessage" 2>/dev/null; then
  for package in tf2_msgs control_msgs controller_manager_msgs franka_msgs; do
    build_interfaces "vendor_interfaces/$package"
  done
  mark vendor_interfaces "$vendor_stamp"
fi

pkg_stamp=$(cd "$root" && stamp_of setup.py setup.cfg package.xml)
if ! fresh package "$pkg_stamp"; then
  say "installing defgg_ros (editable)"
  "$venv/bin/python" -m pip install -q --no-deps --no-build-isolation -e "$root"
  mark package "$pkg_stamp"
fi
say "ready: $venv"
