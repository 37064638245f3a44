#!/usr/bin/env bash
# Installs what visnav needs on a fresh machine: the Rust components used by CI, Debian's ffmpeg
# (video input: `visnav odometry --camera camera.yaml VIDEO`) and Debian's Chromium (the
# headless-browser test of the HTML run report) and Python's venv module (scripts/test.sh builds the
# Python package into a venv). Idempotent and quick when everything is there (scripts/test.sh and
# .ci/run both call it): installs only what is missing. Never fails the caller: without root (or
# apt-get, or a network) it says what is missing and how to install it, and the tests that need
# it skip or fail with their own message.
set -euo pipefail
if command -v rustup >/dev/null 2>&1; then
  for c in clippy rustfmt; do
    rustup component list --installed 2>/dev/null | grep -q "^$c" || rustup component add "$c" ||
      echo "setup.sh: could not add the Rust component $c (rustup component add $c)" >&2
  done
fi
missing=()
command -v ffmpeg >/dev/null 2>&1 || missing+=(ffmpeg)
[ -x /usr/bin/chromium ] || missing+=(chromium)
command -v python3 >/dev/null 2>&1 || missing+=(python3)
python3 -c 'import venv, ensurepip' >/dev/null 2>&1 || missing+=(python3-venv)
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
    if ! { apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}"; }; then
      echo "setup.sh: could not install ${missing[*]} (apt-get failed)" >&2
    fi
  else
    echo "setup.sh: missing ${missing[*]}; install them as root (Debian/Ubuntu: apt-get install ${missing[*]})" >&2
  fi
fi
