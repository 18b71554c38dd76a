#!/usr/bin/env bash
# Cost against the length of the time axis (docs/scaling.md, "Time axis"). Renders
# fixtures/scenes/two_patches_single.json (8x8 lasers x 1 SPAD, all light paths) with Nt bins of
# 3 mm (10 ps) from t0 = 1 m — a window of 3 m at 10^3 bins to 3 km at 10^6, the scene always in
# its first 3 m — and times `vltm direct` over a 5x5x5 volume around the two patches, with the
# automatic crop (default) and without it (--no-crop, up to MAX_UNCROPPED bins). Prints a
# Markdown table: bins, seconds cropped, seconds uncropped, the crop and the path. Needs jq and
# /usr/bin/time (Debian: jq, time).
#
#   bash benches/time_axis.sh [THREADS] [MAX_UNCROPPED]   (defaults: all cores, 100000)
set -euo pipefail
cd "$(dirname "$0")/.."
threads="${1:-$(nproc)}"
max_uncropped="${2:-100000}"
for tool in jq /usr/bin/time; do
  command -v "$tool" >/dev/null || { echo "time_axis.sh needs $tool (apt-get install jq time)" >&2; exit 2; }
done
vltm="${VLTM:-}"
if [ -z "$vltm" ]; then
  cargo build -q --release -p vltm --bin vltm
  vltm="${CARGO_TARGET_DIR:-$PWD/target}/release/vltm"
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
vol="-0.5:0.5:5,-0.2:0.2:5,0.6:1.0:5"

# secs CAPTURE ARGS...: wall seconds of one `vltm direct`, and its crop/path lines in $work/log
secs() {
  local cap="$1"; shift
  /usr/bin/time -f '%e' -o "$work/time" "$vltm" direct "$cap" --volume "$vol" \
    --threads "$threads" --out "$work/out.npy" "$@" >"$work/log"
  cat "$work/time"
}

echo "| bins | window [m] | direct, cropped [s] | direct, --no-crop [s] | kept bins | path |"
echo "|---|---|---|---|---|---|"
for nt in 1000 3000 10000 30000 100000 300000 1000000; do
  jq ".setup.nt = $nt | .setup.dt = 0.003 | .pulse_sigma = 0.003" \
    fixtures/scenes/two_patches_single.json >"$work/s.json"
  "$vltm" simulate "$work/s.json" --out "$work/c.npz" --uncompressed --threads "$threads" >/dev/null
  cropped=$(secs "$work/c.npz")
  kept=$(grep -o 'bins [0-9]*\.\.[0-9]*' "$work/log" | head -1 | cut -d' ' -f2 || true)
  path=$(grep -o 'path [a-z]*' "$work/log" | head -1 | cut -d' ' -f2 || true)
  if [ "$nt" -le "$max_uncropped" ]; then
    full=$(secs "$work/c.npz" --no-crop)
  else
    full="(not run)"
  fi
  printf '| %s | %.0f | %s | %s | %s | %s |\n' "$nt" "$(echo "$nt * 0.003" | bc -l)" \
    "$cropped" "$full" "${kept:-all}" "${path:-?}"
done
