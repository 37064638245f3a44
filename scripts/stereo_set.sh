#!/usr/bin/env bash
# The stereo evaluation set of issue #25: KITTI 06 (lengths 10..50 m) and rendered highway drives
# (devkit lengths 100..800 m), t_err % / r_err deg/100 m on one line; extra arguments go to every
# `visnav odometry` run (e.g. --config c.toml, --no-ba).
#
#   VISNAV_DATA=... HIGHWAYS="hw5 hw6 hw7" bash scripts/stereo_set.sh target/release/visnav [ARGS]
#
# The highway drives: VISNAV_HIGHWAY_SEED=6 VISNAV_HIGHWAY_OUT=hw6 cargo test --release \
#   -p visnav-odometry --test stereo_window write_highway -- --ignored   (seeds 5, 6, 7)
set -euo pipefail
bin=$1
shift
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
score() { # ground truth, estimate, lengths (or empty for the devkit's)
  local lengths=()
  [ -n "$3" ] && lengths=(--lengths "$3")
  "$bin" eval --json "$1" "$2" "${lengths[@]}" | python3 -c '
import json, sys
d = json.load(sys.stdin)
d = d["estimates"][0] if "estimates" in d else (d[0] if isinstance(d, list) else d)
print("%.4f/%.4f" % (d["t_err_percent"], d["r_err_deg_per_100m"]))'
}
seq06=$VISNAV_DATA/kitti/odometry/sequences/06
"$bin" -q odometry --mode stereo "$seq06" -o "$out/06.txt" "$@"
line="06 $(score "$VISNAV_DATA/kitti/odometry/poses/06.txt" "$out/06.txt" 10,20,30,40,50)"
for h in ${HIGHWAYS:-}; do
  "$bin" -q odometry --mode stereo "$h" -o "$out/h.txt" "$@"
  line="$line | $(basename "$h") $(score "$h/poses.txt" "$out/h.txt" "")"
done
echo "$line"
