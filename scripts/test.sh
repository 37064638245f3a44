#!/usr/bin/env bash
# The test command of visnav (README "Test", CI): the Rust tests of the workspace, then the
# Python package built with maturin into a venv and its pytest suite, which compares it with the
# visnav CLI on the shared data.
#
#   bash scripts/test.sh            # VISNAV_DATA / VISNAV_REQUIRE_DATA as for cargo test
#
# The venv is $CARGO_TARGET_DIR/py-venv (default target/py-venv), reused when present. The Python
# extension and the CLI the tests call are built with Cargo's `test` profile, the one
# `cargo test --workspace` has just compiled everything with, so they reuse its artifacts
# instead of a second (release) build of the whole workspace; VISNAV_PY_PROFILE=release builds
# the extension as `pip install ./python` does.
set -euo pipefail
cd "$(dirname "$0")/.."
root="$(pwd)"
target="${CARGO_TARGET_DIR:-$root/target}"
export CARGO_TARGET_DIR="$target"
profile="${VISNAV_PY_PROFILE:-test}"

echo "== cargo test --workspace"
cargo test --workspace

echo "== the visnav CLI the Python tests compare with ($profile profile)"
cargo build --profile "$profile" -p visnav --bin visnav
case "$profile" in
  test | dev) bin_dir=debug ;;
  *) bin_dir="$profile" ;;
esac
export VISNAV_BIN="$target/$bin_dir/visnav"

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
# run from python/tests' parent so that the installed package, not the source folder, is imported
cd "$root/python/tests"
"$venv/bin/python" -m pytest -q -p no:cacheprovider .
