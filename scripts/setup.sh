#!/usr/bin/env bash
# Installs what visnav needs on a fresh machine: the Rust components used by CI. Idempotent.
set -euo pipefail
if command -v rustup >/dev/null 2>&1; then
  rustup component list --installed 2>/dev/null | grep -q '^clippy' || rustup component add clippy
  rustup component list --installed 2>/dev/null | grep -q '^rustfmt' || rustup component add rustfmt
fi
# ffmpeg decodes video input (`visnav odometry --camera camera.yaml VIDEO`); install only when missing.
if ! command -v ffmpeg >/dev/null 2>&1; then
  if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
    apt-get update
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends ffmpeg
  else
    echo "setup.sh: ffmpeg is missing; install it (Debian/Ubuntu: apt-get install ffmpeg) to read video files" >&2
  fi
fi
