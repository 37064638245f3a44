#!/usr/bin/env bash
# Installs what visnav needs on a fresh machine: the Rust components used by CI and Debian's
# Chromium for the headless-browser test of the HTML run report. Idempotent.
set -euo pipefail
if command -v rustup >/dev/null 2>&1; then
  rustup component list --installed 2>/dev/null | grep -q '^clippy' || rustup component add clippy
  rustup component list --installed 2>/dev/null | grep -q '^rustfmt' || rustup component add rustfmt
fi
# Headless Chromium renders `visnav report` pages in crates/visnav/tests/cli_report.rs.
if [ ! -x /usr/bin/chromium ]; then
  if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
    apt-get update
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends chromium
  else
    echo "setup.sh: /usr/bin/chromium is missing; install Debian's chromium package as root" >&2
  fi
fi
