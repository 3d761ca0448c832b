#!/usr/bin/env bash
# Idempotent set-up: .venv/ with the locked requirements, the ROS wheel workarounds, and a
# colcon build of src/ into install/. Quick when nothing changed (stamp files).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null || PY=python3
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-42}

# System libraries: headless EGL rendering needs Mesa's libEGL (Debian: libegl1 libgl1-mesa-dri);
# open3d (Poisson meshing of real plant clouds) needs libusb-1.0; iproute2 for the cross-host test;
# chromium + chromium-driver for the viewer's browser test.
# (grep reads the whole list: `grep -q` would stop early, ldconfig would die of SIGPIPE and
# pipefail would report the library missing)
missing=()
libs=$(ldconfig -p 2>/dev/null || true)
grep 'libEGL.so.1' >/dev/null <<<"$libs" || missing+=(libegl1 libgl1-mesa-dri libgles2)
grep 'libusb-1.0.so.0' >/dev/null <<<"$libs" || missing+=(libusb-1.0-0)
# the cross-host test (tests/test_across_hosts.py) builds network namespaces with iproute2 as root
# (it skips for other users, so only root is asked to install it)
if [ "$(id -u)" = 0 ] && ! command -v ip >/dev/null; then missing+=(iproute2); fi
# the viewer's browser test drives Debian's chromium headless through chromedriver (nothing is
# downloaded at test time; it skips with a reason where they are missing and the user is not root)
if [ "$(id -u)" = 0 ] && { ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; }; then
  missing+=(chromium chromium-driver)
fi
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "[setup] installing system libraries: ${missing[*]}"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
  else
    echo "[setup] warning: missing system libraries; run: sudo apt-get install ${missing[*]}" >&2
  fi
fi

# 1. Virtual environment with the locked requirements.
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv with $($PY --version)"
  "$PY" -m venv .venv
fi
if [ ! -f .venv/.requirements.stamp ] || [ requirements.txt -nt .venv/.requirements.stamp ]; then
  echo "[setup] installing requirements.txt into .venv (first time: a few minutes)"
  # (pip's "Location ... is ignored" lines come from this machine's local index mirrors: noise)
  .venv/bin/python -m pip install --quiet -r requirements.txt 2> >(grep -v '^WARNING: Location' >&2)
  rm -f .venv/.cmake-patched.stamp
  touch .venv/.requirements.stamp
fi

# 2. ROS wheel workaround: exported CMake files name the wheel builder's Python and numpy
#    include dirs (/opt/python/cp311-cp311/...); point them at this interpreter's.
if [ ! -f .venv/.cmake-patched.stamp ]; then
  echo "[setup] rewriting the ROS wheels' exported CMake include paths"
  .venv/bin/python - <<'PYEOF'
import pathlib, sys, sysconfig
import numpy
share = pathlib.Path(sys.prefix) / 'share'
py_inc = sysconfig.get_paths()['include']
np_inc = numpy.get_include()
n = 0
for f in share.rglob('*.cmake'):
    text = f.read_text(errors='surrogateescape')
    if 'cp311-cp311' not in text:
        continue
    new = text.replace('/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include', np_inc)
    new = new.replace('/opt/python/cp311-cp311/include/python3.11', py_inc)
    if new != text:
        f.write_text(new, errors='surrogateescape')
        n += 1
print(f'[setup] rewrote {n} CMake files')
PYEOF
  touch .venv/.cmake-patched.stamp
fi

# 3. Build the workspace when a source file is newer than the last build.
stamp=install/.build.stamp
if [ ! -f "$stamp" ] || [ -n "$(find src colcon.meta -newer "$stamp" -type f -print -quit)" ]; then
  echo "[setup] colcon build"
  # shellcheck disable=SC1091
  . .venv/bin/activate
  export AMENT_PREFIX_PATH=$VIRTUAL_ENV CMAKE_PREFIX_PATH=$VIRTUAL_ENV
  mkdir -p log
  if ! colcon --log-base log build --base-paths src --build-base build --install-base install \
      --event-handlers console_cohesion+ status- summary+ \
      --cmake-args -DBUILD_TESTING=OFF -DPython3_EXECUTABLE="$VIRTUAL_ENV/bin/python" >log/setup-build.log 2>&1; then
    cat log/setup-build.log >&2
    echo "[setup] colcon build failed (log above, also in log/setup-build.log)" >&2
    exit 1
  fi
  touch "$stamp"
fi
echo "[setup] ready: . .venv/bin/activate && . install/setup.bash"
