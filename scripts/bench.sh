#!/usr/bin/env bash
# The real-time figures of visnav in one go, side by side with OpenCV on the same data
# (issue "Real time on a laptop CPU"): mono VO on the KITTI 00 clip, dense flow on a KITTI 2012
# pair, stereo VO on the KITTI 06 clip, the sphere2500 pose graph; OpenCV DIS (medium) on the
# same flow pair and a KLT + essential-matrix VO on the same clip. Prints a Markdown table for
# docs/benchmarks.md. Run it on an idle machine; wall times include PNG decoding.
#
#   VISNAV_DATA=../shared/data bash scripts/bench.sh [--skip-build] [--repeat N]
set -euo pipefail
cd "$(dirname "$0")/.."
DATA="$(cd "${VISNAV_DATA:-../shared/data}" && pwd)"
REPEAT=1
BUILD=1
while [ $# -gt 0 ]; do
  case "$1" in
    --skip-build) BUILD=0 ;;
    --repeat) REPEAT="$2"; shift ;;
    *) echo "unknown option $1" >&2; exit 2 ;;
  esac
  shift
done
[ "$BUILD" = 1 ] && cargo build --release -p visnav --quiet
BIN="${CARGO_TARGET_DIR:-target}/release/visnav"
VENV="${CARGO_TARGET_DIR:-target}/bench-venv"
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet "opencv-python-headless>=4.8" numpy
fi
PY="$VENV/bin/python"
OUT="$(mktemp -d)"
trap 'rm -rf "$OUT"' EXIT
KITTI="$DATA/kitti/odometry"
PAIR="$DATA/flow/kitti2012/training/image_0/000045"
json() { python3 -c "import json,sys; d=json.load(open('$1')); print($2)"; }
best() { sort -g | head -1; }  # the fastest of the repeats

mono_ms=(); stereo_ms=(); flow_ms=(); graph_s=()
for _ in $(seq "$REPEAT"); do
  "$BIN" -q odometry --mode mono "$KITTI/sequences/00" --max-frames 300 --camera-height 1.7 \
      -o "$OUT/m00.txt" --json "$OUT/m00.json"
  mono_ms+=("$(json "$OUT/m00.json" "1e3 * d['wall_s'] / d['frames']")")
  "$BIN" -q odometry --mode stereo "$KITTI/sequences/06" -o "$OUT/s06.txt" --json "$OUT/s06.json"
  stereo_ms+=("$(json "$OUT/s06.json" "1e3 * d['wall_s'] / d['frames']")")
  s=$(date +%s.%N)
  "$BIN" -q flow "${PAIR}_10.png" "${PAIR}_11.png" -o "$OUT/f.flo" --information "$OUT/i.pfm" > /dev/null
  flow_ms+=("$(python3 -c "print(1e3 * ($(date +%s.%N) - $s))")")
  s=$(date +%s.%N)
  "$BIN" -q posegraph "$DATA/posegraph/sphere2500.g2o" -o "$OUT/sphere.g2o" --json > "$OUT/g.json"
  graph_s+=("$(python3 -c "print($(date +%s.%N) - $s)")")
done
"$BIN" -q eval "$KITTI/poses/00.txt" "$OUT/m00.txt" --lengths 100,200 --json > "$OUT/e00.json" 2> /dev/null
"$BIN" -q eval "$KITTI/poses/06.txt" "$OUT/s06.txt" --lengths 10,20,30,40,50 --json > "$OUT/e06.json" 2> /dev/null
"$BIN" -q flow-eval "$DATA/flow/kitti2012" --json > "$OUT/fk.json"
"$BIN" -q flow-eval "$DATA/flow/middlebury" --json > "$OUT/fm.json"
"$PY" scripts/opencv_vo.py "$KITTI/sequences/00" "$KITTI/poses/00.txt" --max-frames 300 \
    -o "$OUT/cv00.txt" > "$OUT/cv00.json"
"$BIN" -q eval "$KITTI/poses/00.txt" "$OUT/cv00.txt" --lengths 100,200 --json > "$OUT/ecv.json" 2> /dev/null
"$PY" scripts/compare_flow_opencv.py "$DATA/flow/kitti2012" --visnav "$BIN" > "$OUT/dis.txt"

m=$(printf '%s\n' "${mono_ms[@]}" | best); st=$(printf '%s\n' "${stereo_ms[@]}" | best)
fl=$(printf '%s\n' "${flow_ms[@]}" | best); gr=$(printf '%s\n' "${graph_s[@]}" | best)
cv=$(json "$OUT/cv00.json" "d['ms_per_frame']")
echo "bench $(date -u +%F) $(git rev-parse --short HEAD) on $(nproc) cores, load $(cut -d' ' -f1 /proc/loadavg)"
echo
echo "| figure | visnav | target | OpenCV | visnav / OpenCV |"
echo "| --- | --- | --- | --- | --- |"
printf '| mono VO, KITTI 00 clip, ms a frame | %.0f | 150 | %.0f (KLT + essential, GT scale) | %.1fx |\n' "$m" "$cv" "$(python3 -c "print($m / $cv)")"
printf '| mono VO t_err %% / r_err deg/100 m | %s | 1.30 / 0.95 | %s | |\n' \
    "$(json "$OUT/e00.json" "'%.4f / %.4f' % (d['t_err_percent'], d['r_err_deg_per_100m'])")" \
    "$(json "$OUT/ecv.json" "'%.4f / %.4f' % (d['t_err_percent'], d['r_err_deg_per_100m'])")"
printf '| dense flow, KITTI 2012 pair, ms wall | %.0f | 250 | see DIS row | |\n' "$fl"
printf '| flow EPE px, KITTI 2012 / Middlebury | %s / %s | 0.56 / 0.54 | | |\n' \
    "$(json "$OUT/fk.json" "'%.3f' % d['summary']['mean_epe_px']")" \
    "$(json "$OUT/fm.json" "'%.3f' % d['summary']['mean_epe_px']")"
printf '| stereo VO, KITTI 06 clip, ms a frame | %.1f | 10 | | |\n' "$st"
printf '| stereo t_err %% / r_err deg/100 m | %s | 0.88 / 1.68 | | |\n' \
    "$(json "$OUT/e06.json" "'%.4f / %.4f' % (d['t_err_percent'], d['r_err_deg_per_100m'])")"
printf '| pose graph sphere2500, s wall | %.2f | 0.25 | | |\n' "$gr"
echo
echo "Flow against OpenCV DIS (medium, 1 thread) and Farneback, KITTI 2012 (scripts/compare_flow_opencv.py):"
echo
sed 's/^/    /' "$OUT/dis.txt"
exit 0
