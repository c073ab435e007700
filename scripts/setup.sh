#!/usr/bin/env bash
# Set up sbsc from nothing on a Debian machine with Python >= 3.11:
# the Debian library open3d needs (libusb-1.0-0), a virtualenv in .venv, the package and its
# test tools. With --browser also Debian's Chromium for the browser tests. Idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
want_browser=0
for arg in "$@"; do [ "$arg" = "--browser" ] && want_browser=1; done

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi; }
apt_updated=0
apt_install() {
  command -v apt-get >/dev/null 2>&1 || { echo "setup: apt-get not found; install $* by hand" >&2; return 1; }
  if [ "$apt_updated" = 0 ]; then as_root apt-get update -qq >/dev/null; apt_updated=1; fi
  DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq "$@" >/dev/null
}

if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  echo "setup: installing libusb-1.0-0 (needed by open3d)"
  apt_install libusb-1.0-0
fi
if [ "$want_browser" = 1 ] && ! command -v chromium >/dev/null 2>&1; then
  echo "setup: installing Debian chromium (browser tests)"
  apt_install chromium || echo "setup: chromium could not be installed; browser tests will be skipped" >&2
fi

PY="${PYTHON:-python3}"
"$PY" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' \
  || { echo "setup: Python >= 3.11 is needed ($PY is $("$PY" -V 2>&1))" >&2; exit 1; }
# a .venv whose python has no pip is one whose making was interrupted: make it again
if ! { [ -x .venv/bin/python ] && .venv/bin/python -m pip --version >/dev/null 2>&1; }; then
  "$PY" -m venv --clear .venv
fi
stamp=.venv/.sbsc-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "setup: installing Python packages into .venv (first time takes a few minutes)"
  .venv/bin/python -m pip install -q --upgrade pip
  .venv/bin/python -m pip install -q -e ".[test]"
  touch "$stamp"
fi
