#!/usr/bin/env bash
# The test command of visnav (README "Test", CI): what the tests need (scripts/setup.sh), the Rust
# tests of the workspace, then the Python package built with maturin into a venv and its pytest
# suite, which compares it with the visnav CLI on the shared data.
#
#   bash scripts/test.sh            # VISNAV_DATA / VISNAV_REQUIRE_DATA as for cargo test
#
# The venv is $CARGO_TARGET_DIR/py-venv (default target/py-venv), reused when present. The CLI the
# Python tests call is the one `cargo test` has just built for its own CLI tests
# (target/debug/visnav, test profile); the Python extension is built as `pip install ./python`
# builds it, with the `dev` profile (VISNAV_PY_PROFILE=release for the release one). Cargo's
# `test` profile cannot build it (`cargo rustc --profile test` makes a test harness), but `dev`
# has the same settings (Cargo.toml), so the build reuses every dependency `cargo test` compiled.
set -euo pipefail
cd "$(dirname "$0")/.."
root="$(pwd)"
target="${CARGO_TARGET_DIR:-$root/target}"
export CARGO_TARGET_DIR="$target"
profile="${VISNAV_PY_PROFILE:-dev}"

echo "== scripts/setup.sh (what the tests need: ffmpeg, Chromium, python3-venv)"
# idempotent and quick when all is installed; says what is missing when it cannot install it
bash scripts/setup.sh

echo "== cargo test --workspace"
cargo test --workspace

echo "== the visnav CLI the Python tests compare with"
# `cargo test --workspace` has just built it (fresh) for the CLI tests; a separate `cargo build`
# would compile the workspace again (without the dev-dependencies' features)
export VISNAV_BIN="$target/debug/visnav"
[ -x "$VISNAV_BIN" ] || cargo build -p visnav --bin visnav

echo "== Python venv $target/py-venv"
venv="$target/py-venv"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r python/requirements-test.txt

echo "== pip install ./python ($profile profile)"
# maturin is in the venv (on PATH for the build backend): no isolated build environment
PATH="$venv/bin:$PATH" MATURIN_PEP517_ARGS="--profile $profile" \
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-build-isolation \
  --force-reinstall --no-deps ./python

echo "== pytest python/tests"
# run from python/tests so that the installed package, not the source folder, is imported
cd "$root/python/tests"
"$venv/bin/python" -m pytest -q -p no:cacheprovider .
