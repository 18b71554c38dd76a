#!/usr/bin/env bash
# How vltm's time and memory grow with laser rows, SPADs, voxels and bins (docs/performance.md,
# "Scaling"). Renders variants of benches/scenes/exh16.json with `vltm simulate
# --uncompressed` (streamed row by row by `vltm direct` / `vltm column`), then runs each probe
# once per variant under /usr/bin/time and prints a Markdown table: wall time, peak resident
# memory, and the evaluation path vltm chose. Needs jq and /usr/bin/time (Debian: jq, time);
# no Python. Takes about a minute on 2 cores.
#
#   bash benches/scaling.sh [THREADS]        (default: all cores)
#
# The variants change one size at a time from the exh16 setup (16x16 lasers x 16x16 SPADs,
# 800 bins of 6 mm, λ = σ = 0.5 m, volume 16x16x24 at the SPAD pitch):
#   rows    lasers 4x4, 8x8, 16x16          (memory must not grow: rows are streamed)
#   SPADs   SPADs 8x8, 16x16 on the same wall (volume pitch = SPAD pitch, so planar applies)
#   voxels  6, 12, 24 slices of the volume
#   bins    400, 800, 1600 bins over the same 4.8 m window (Δt = 12, 6, 3 mm)
set -euo pipefail
cd "$(dirname "$0")/.."
threads="${1:-$(nproc)}"
for tool in jq /usr/bin/time; do
  command -v "$tool" >/dev/null || { echo "scaling.sh needs $tool (apt-get install jq time)" >&2; exit 2; }
done
cargo build -q --release -p vltm-cli --bin vltm
vltm="${CARGO_TARGET_DIR:-$PWD/target}/release/vltm"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
base=benches/scenes/exh16.json
wave=(--wavelength 0.5 --sigma 0.5 --weights one --threads "$threads")

# scene NAME JQ-FILTER: renders a variant of exh16 into $work/NAME.npz
scene() {
  jq "$2" "$base" >"$work/$1.json"
  "$vltm" simulate "$work/$1.json" --out "$work/$1.npz" --uncompressed >/dev/null
}

# run LABEL CAPTURE PROBE VOLUME [ARGS...]: one timed run, one table row
run() {
  local label="$1" cap="$2" probe="$3" vol="$4"; shift 4
  local log="$work/log"
  /usr/bin/time -f '%e %M' -o "$work/time" \
    "$vltm" "$probe" "$cap" --volume "$vol" "${wave[@]}" --out "$work/out.npy" "$@" >"$log"
  read -r secs kb <"$work/time"
  local path
  path=$(grep -o 'path [a-z]*' "$log" | head -1 | cut -d' ' -f2 || true)
  printf '| %s | %s | %.2f | %.1f | %s |\n' "$label" "$probe" "$secs" "$(echo "$kb / 1024" | bc -l)" "${path:-?}"
}

# The volume at the SPAD pitch over the SPAD grid (nx = ny = SPADs per side: the grid's end
# points are the wall's edges, ±0.9375 m), nz slices over z = 0.5..1.25 m (side_by_side.py's V16).
vol() { # vol N_SIDE NZ
  printf -- '-0.9375:0.9375:%d,-0.9375:0.9375:%d,0.5:1.25:%d' "$1" "$1" "$2"
}
focus="-0.4,0,0.75"

echo "| variant | probe | wall time [s] | peak RSS [MB] | path |"
echo "|---|---|---|---|---|"
for n in 4 8 16; do
  scene "rows$n" ".setup.lasers.grid = [$n, $n]"
  run "rows: $((n * n)) lasers" "$work/rows$n.npz" direct "$(vol 16 24)"
  run "rows: $((n * n)) lasers" "$work/rows$n.npz" column "$(vol 16 24)" --focus "$focus"
done
# 16x16 SPADs is rows16 above.
scene spads8 '.setup.spads.grid = [8, 8]'
run "SPADs: 64" "$work/spads8.npz" direct "$(vol 8 24)"
run "SPADs: 256" "$work/rows16.npz" direct "$(vol 16 24)"
for nz in 6 12 24; do
  run "voxels: 16x16x$nz" "$work/rows16.npz" direct "$(vol 16 "$nz")"
done
for nt in 400 1600; do
  dt=$(echo "4.8 / $nt" | bc -l)
  scene "bins$nt" ".setup.nt = $nt | .setup.dt = $dt | .pulse_sigma = 0.006"
  run "bins: $nt (Δt $(printf '%.1f' "$(echo "$dt * 1000" | bc -l)") mm)" "$work/bins$nt.npz" direct "$(vol 16 24)"
done
run "bins: 800 (Δt 6.0 mm)" "$work/rows16.npz" direct "$(vol 16 24)"
