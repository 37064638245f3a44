#!/usr/bin/env bash
# The real-time figures of visnav in one go, side by side with OpenCV on the same data
# (issue "Real time on a laptop CPU"): mono VO on the KITTI 00 clip, dense flow on a KITTI 2012
# pair, stereo VO on the KITTI 06 clip, the sphere2500 pose graph; OpenCV DIS (medium) on the
# same flow pair and a KLT + essential-matrix VO on the same clip. Prints a Markdown table for
# docs/benchmarks.md. Run it on an idle machine; wall times include PNG decoding; the CPU column
# is user time (less sensitive to other load than wall time); the load average is printed.
# Issue 51's rows: the real-time mono preset beside the KLT + essential baseline, and the fast
# flow beside OpenCV DIS (ultrafast, fast, medium; 1 and 2 threads; in one Python process with
# the visnav module, scripts/bench_fast_flow.py), each as a ratio to its peer of the same run.
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
# absolute: pip runs the maturin build hook from a temporary directory, where a relative PATH
# entry finds no maturin
VENV="$(realpath -m "${CARGO_TARGET_DIR:-target}/bench-venv")"
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet "opencv-python-headless>=4.8" numpy "maturin>=1.9,<2"
fi
if [ "$BUILD" = 1 ] || ! "$VENV/bin/python" -c "import visnav" 2> /dev/null; then
  # the visnav module, release build, for the in-process flow comparison
  PATH="$VENV/bin:$PATH" MATURIN_PEP517_ARGS="--profile release" "$VENV/bin/pip" install --quiet \
      --no-build-isolation --force-reinstall --no-deps ./python
fi
PY="$VENV/bin/python"
OUT="$(mktemp -d)"
trap 'rm -rf "$OUT"' EXIT
KITTI="$DATA/kitti/odometry"
PAIR="$DATA/flow/kitti2012/training/image_0/000045"
json() { python3 -c "import json,sys; d=json.load(open('$1')); print($2)"; }
best() { sort -g | head -1; }  # the fastest of the repeats
load() { cut -d' ' -f1 /proc/loadavg; }
# `timed NAME CMD...`: runs CMD under /usr/bin/time, appends "wall_s user_s" to $OUT/NAME.time
timed() {
  local name="$1"; shift
  /usr/bin/time -f "%e %U" -o "$OUT/$name.t" "$@"
  cat "$OUT/$name.t" >> "$OUT/$name.time"
}
# the fastest repeat's "wall user" of NAME, each divided by $2 (frames), times $3 (1000: ms)
fastest() { sort -g "$OUT/$1.time" | head -1 | awk -v n="$2" -v k="$3" '{printf "%.4g %.4g", k*$1/n, k*$2/n}'; }

LOAD_START=$(load)
mono_ms=(); rt_ms=(); stereo_ms=()
for _ in $(seq "$REPEAT"); do
  timed mono "$BIN" -q odometry --mode mono "$KITTI/sequences/00" --max-frames 300 --camera-height 1.7 \
      -o "$OUT/m00.txt" --json "$OUT/m00.json"
  mono_ms+=("$(json "$OUT/m00.json" "1e3 * d['wall_s'] / d['frames']")")
  timed rt "$BIN" -q odometry --mode mono "$KITTI/sequences/00" --max-frames 300 --camera-height 1.7 \
      --preset realtime -o "$OUT/rt00.txt" --json "$OUT/rt00.json"
  rt_ms+=("$(json "$OUT/rt00.json" "1e3 * d['wall_s'] / d['frames']")")
  # the stereo clip takes half a second: five runs a repeat, so that one burst of the VM's
  # noise (one run in several takes 30-50 % longer) does not decide the figure
  for _ in 1 2 3 4 5; do
    timed stereo "$BIN" -q odometry --mode stereo "$KITTI/sequences/06" -o "$OUT/s06.txt" --json "$OUT/s06.json"
    stereo_ms+=("$(json "$OUT/s06.json" "1e3 * d['wall_s'] / d['frames']")")
  done
  timed flow "$BIN" -q flow "${PAIR}_10.png" "${PAIR}_11.png" -o "$OUT/f.flo" --information "$OUT/i.pfm" > /dev/null
  timed graph "$BIN" -q posegraph "$DATA/posegraph/sphere2500.g2o" -o "$OUT/sphere.g2o" --json > "$OUT/g.json"
done
LOAD_END=$(load)
"$BIN" -q eval "$KITTI/poses/00.txt" "$OUT/m00.txt" --lengths 100,200 --json > "$OUT/e00.json" 2> /dev/null
"$BIN" -q eval "$KITTI/poses/00.txt" "$OUT/rt00.txt" --lengths 100,200 --json > "$OUT/ert.json" 2> /dev/null
"$BIN" -q eval "$KITTI/poses/06.txt" "$OUT/s06.txt" --lengths 10,20,30,40,50 --json > "$OUT/e06.json" 2> /dev/null
"$BIN" -q flow-eval "$DATA/flow/kitti2012" --json > "$OUT/fk.json"
"$BIN" -q flow-eval "$DATA/flow/middlebury" --json > "$OUT/fm.json"
"$BIN" -q flow-eval "$DATA/flow/kitti2012" --method fast --json > "$OUT/ffk.json"
"$BIN" -q flow-eval "$DATA/flow/middlebury" --method fast --json > "$OUT/ffm.json"
MIMALLOC_PURGE_DELAY=-1 "$PY" scripts/bench_fast_flow.py "$PAIR" > "$OUT/fast.txt"
"$PY" scripts/opencv_vo.py "$KITTI/sequences/00" "$KITTI/poses/00.txt" --max-frames 300 \
    -o "$OUT/cv00.txt" > "$OUT/cv00.json"
"$BIN" -q eval "$KITTI/poses/00.txt" "$OUT/cv00.txt" --lengths 100,200 --json > "$OUT/ecv.json" 2> /dev/null
"$PY" scripts/compare_flow_opencv.py "$DATA/flow/kitti2012" --visnav "$BIN" > "$OUT/dis.txt"

m=$(printf '%s\n' "${mono_ms[@]}" | best); rt=$(printf '%s\n' "${rt_ms[@]}" | best); st=$(printf '%s\n' "${stereo_ms[@]}" | best)
st_median=$(printf '%s\n' "${stereo_ms[@]}" | sort -g | awk '{v[NR] = $1} END {print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2}')
read -r _ mono_user <<< "$(fastest mono 300 1000)"
read -r _ rt_user <<< "$(fastest rt 300 1000)"
read -r fl fl_user <<< "$(fastest flow 1 1000)"
read -r gr gr_user <<< "$(fastest graph 1 1)"
cv=$(json "$OUT/cv00.json" "d['ms_per_frame']")
echo "bench $(date -u '+%F %H:%M') UTC, $(git rev-parse --short HEAD), $(nproc) cores, load $LOAD_START at the start, $LOAD_END after the timed runs (best of $REPEAT)"
echo
echo "| figure | visnav | CPU (user) | target | OpenCV | visnav / OpenCV |"
echo "| --- | --- | --- | --- | --- | --- |"
printf '| mono VO, KITTI 00 clip, ms a frame (wall, report) | %.0f | %.0f | 150 | %.0f (KLT + essential, GT scale, 1 thread) | %.1fx |\n' "$m" "$mono_user" "$cv" "$(python3 -c "print($m / $cv)")"
printf '| mono VO t_err %% / r_err deg/100 m | %s | | 1.30 / 0.95 | %s | |\n' \
    "$(json "$OUT/e00.json" "'%.4f / %.4f' % (d['t_err_percent'], d['r_err_deg_per_100m'])")" \
    "$(json "$OUT/ecv.json" "'%.4f / %.4f' % (d['t_err_percent'], d['r_err_deg_per_100m'])")"
printf '| mono VO real-time preset (#51), ms a frame (wall, report) | %.0f | %.0f | 3x OpenCV | %.0f (KLT + essential, GT scale, 1 thread) | %.2fx |\n' "$rt" "$rt_user" "$cv" "$(python3 -c "print($rt / $cv)")"
printf '| real-time preset t_err %% / r_err deg/100 m | %s | | 1.40 / 1.00 | %s | |\n' \
    "$(json "$OUT/ert.json" "'%.4f / %.4f' % (d['t_err_percent'], d['r_err_deg_per_100m'])")" \
    "$(json "$OUT/ecv.json" "'%.4f / %.4f' % (d['t_err_percent'], d['r_err_deg_per_100m'])")"
printf '| fast flow (#51) EPE px, KITTI 2012 / Middlebury | %s / %s | | DIS medium'"'"'s (0.568 / 0.604) | | |\n' \
    "$(json "$OUT/ffk.json" "'%.3f' % d['summary']['mean_epe_px']")" \
    "$(json "$OUT/ffm.json" "'%.3f' % d['summary']['mean_epe_px']")"
printf '| fast flow AUSE/EPE, 1-sigma %%, KITTI 2012 / Middlebury | %s / %s | | 0.30 | | |\n' \
    "$(json "$OUT/ffk.json" "'%.3f, %.1f' % (d['summary']['mean_ause_over_epe'], d['summary']['mean_sigma1_percent'])")" \
    "$(json "$OUT/ffm.json" "'%.3f, %.1f' % (d['summary']['mean_ause_over_epe'], d['summary']['mean_sigma1_percent'])")"
printf '| dense flow, KITTI 2012 pair, ms (process wall) | %.0f | %.0f | 250 | see the DIS table | |\n' "$fl" "$fl_user"
printf '| flow EPE px, KITTI 2012 / Middlebury | %s / %s | | 0.56 / 0.54 | | |\n' \
    "$(json "$OUT/fk.json" "'%.3f' % d['summary']['mean_epe_px']")" \
    "$(json "$OUT/fm.json" "'%.3f' % d['summary']['mean_epe_px']")"
printf '| flow AUSE/EPE, certain half, KITTI 2012 / Middlebury | %s / %s | | not worse | | |\n' \
    "$(json "$OUT/fk.json" "'%.3f, %.3f' % (d['summary']['mean_ause_over_epe'], d['summary']['mean_half_over_all_epe'])")" \
    "$(json "$OUT/fm.json" "'%.3f, %.3f' % (d['summary']['mean_ause_over_epe'], d['summary']['mean_half_over_all_epe'])")"
printf '| stereo VO, KITTI 06 clip, ms a frame (wall, report; best of %d runs, median %.1f) | %.1f | | 10 | | |\n' "${#stereo_ms[@]}" "$st_median" "$st"
printf '| stereo t_err %% / r_err deg/100 m | %s | | 0.88 / 1.68 | | |\n' \
    "$(json "$OUT/e06.json" "'%.4f / %.4f' % (d['t_err_percent'], d['r_err_deg_per_100m'])")"
printf '| pose graph sphere2500, s (process wall) | %.2f | %.2f | 0.25 | | |\n' "$gr" "$gr_user"
printf '| sphere2500 objective (GTSAM error, optimum 675.70) | %s | | same | | |\n' \
    "$(json "$OUT/g.json" "'%.6f' % d['objective_after']['gtsam_error']")"
echo
echo "Flow against OpenCV DIS (medium, 1 thread) and Farneback, KITTI 2012 (scripts/compare_flow_opencv.py):"
echo
sed 's/^/    /' "$OUT/dis.txt"
echo
echo "The fast flow against OpenCV DIS in one process, PNG decoding included, warm, median of 9 (scripts/bench_fast_flow.py, KITTI 2012 000045):"
echo
cat "$OUT/fast.txt"
exit 0
