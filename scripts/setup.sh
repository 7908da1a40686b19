#!/usr/bin/env bash
# Idempotent set-up, sourced by scripts/main.sh and scripts/test.sh:
#   - Debian's Mesa EGL (headless MuJoCo rendering) and FFmpeg libraries, and Chromium for the dashboard's
#     browser tests (installed when missing and root),
#   - a Python 3.12 (on PATH, or pyenv's installed 3.12),
#   - .venv with this project installed (editable, with the dev, ur5, dashboard and ray extras, which the
#     tests need); re-installed only when
#     pyproject.toml changed since the last install.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
# apt's and pip's own output (setuptools warnings, download lines) goes here, not to the console.
SETUP_LOG="$ROOT/outputs/logs/setup.log"
mkdir -p "$(dirname "$SETUP_LOG")"
quietly() {  # run a set-up step with its output in the log; show the log's tail if it fails
  if ! "$@" >>"$SETUP_LOG" 2>&1; then
    echo "[setup] FAILED: $* (last lines of $SETUP_LOG below)" >&2
    tail -n 30 "$SETUP_LOG" >&2
    exit 1
  fi
}

# Mesa EGL for headless MuJoCo rendering; FFmpeg's libraries for torchcodec, LeRobot's fast video
# decoder (without them LeRobot falls back to PyAV with a long warning).
system_libs_present() {
  ldconfig -p 2>/dev/null | grep -q "libEGL_mesa.so" && ldconfig -p | grep -q "libgbm.so" \
    && ldconfig -p | grep -q "libavutil.so" && [ -x /usr/bin/chromium ]
}
if ! system_libs_present; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null; then
    echo "[setup] installing Debian packages: Mesa EGL (headless rendering), FFmpeg (video decoding)," \
      "Chromium (dashboard tests); log: $SETUP_LOG"
    quietly apt-get update -qq
    quietly env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
      libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1 ffmpeg chromium
  else
    echo "[setup] WARNING: missing system libraries and not root:" \
      "apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1 ffmpeg chromium" >&2
  fi
fi

find_python() {
  for candidate in python3.12 python3; do
    if command -v "$candidate" >/dev/null && "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 12))' 2>/dev/null; then
      command -v "$candidate"; return 0
    fi
  done
  local pyenv_root="${PYENV_ROOT:-$HOME/.pyenv}"
  command -v pyenv >/dev/null && pyenv_root="$(pyenv root)"
  for p in "$pyenv_root"/versions/3.12.*/bin/python3; do
    [ -x "$p" ] && { echo "$p"; return 0; }
  done
  return 1
}

if [ ! -x .venv/bin/python ]; then
  PY="$(find_python)" || { echo "[setup] ERROR: no Python 3.12 found (LeRobot 0.6.1 needs >= 3.12)" >&2; exit 1; }
  echo "[setup] creating .venv with $PY"
  "$PY" -m venv .venv
fi

stamp=".venv/.installed-$(sha256sum pyproject.toml | cut -c1-16)"
if [ ! -f "$stamp" ]; then
  echo "[setup] installing the project into .venv (pyproject.toml changed or first run: up to several GB and minutes); log: $SETUP_LOG"
  quietly .venv/bin/python -m pip install --upgrade pip
  quietly .venv/bin/python -m pip install -e ".[dev,ur5,dashboard,ray,onnx]"
  rm -f .venv/.installed-*
  touch "$stamp"
fi
export MUJOCO_GL=egl
export PATH="$ROOT/.venv/bin:$PATH"
