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
#
#   bash benches/scaling.sh --efficiency [THREADS...]   (default: 1 2, and 4 8 16 up to nproc)
#
# prints instead the parallel-efficiency table on exh16 itself: wall time of the whole command
# for direct (auto path), column and indirect (defaults, leak correction) at each thread count
# (best of REPEAT runs, default 2), the speed-up T1/Tn, the efficiency T1/(n·Tn) and Amdahl's
# serial fraction f = (Tn/T1 − 1/n)/(1 − 1/n); then, from one run per probe at --threads 1 with
# VLTM_TIMINGS=1 (vltm::timings), the serial fraction measured inside the command and the
# speed-up on 16 threads it bounds. Needs only bash, awk and the binary (set VLTM to a prebuilt
# one to skip cargo, e.g. on a machine without a toolchain).
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${1:-}" = "--efficiency" ]; then
  shift
  counts=("$@")
  if [ ${#counts[@]} -eq 0 ]; then
    counts=(1 2)
    for n in 4 8 16; do [ "$n" -le "$(nproc)" ] && counts+=("$n"); done
  fi
  vltm="${VLTM:-}"
  if [ -z "$vltm" ]; then
    cargo build -q --release -p vltm-cli --bin vltm
    vltm="${CARGO_TARGET_DIR:-$PWD/target}/release/vltm"
  fi
  work="$(mktemp -d)"
  trap 'rm -rf "$work"' EXIT
  "$vltm" simulate benches/scenes/exh16.json --out "$work/exh16.npz" --uncompressed >/dev/null
  vol='-0.9375:0.9375:16,-0.9375:0.9375:16,0.5:1.25:24'
  common=(--volume "$vol" --wavelength 0.5 --sigma 0.5 --weights one --out "$work/o.npy")
  declare -A cmd=(
    [direct]="direct"
    [column]="column --focus=-0.4,0,0.75 --no-leak-correct"
    [indirect]="indirect"
  )
  calc() { awk "BEGIN { print $1 }"; }
  best() { # best N PROBE...: least wall seconds of REPEAT runs
    local n="$1"; shift
    local b=""
    for _ in $(seq "${REPEAT:-2}"); do
      local s e
      s=$(date +%s.%N)
      "$vltm" --threads "$n" "$@" "$work/exh16.npz" "${common[@]}" >/dev/null
      e=$(date +%s.%N)
      local t; t=$(calc "$e - $s")
      if [ -z "$b" ] || [ "$(calc "$t < $b")" = 1 ]; then b=$t; fi
    done
    echo "$b"
  }
  echo "| probe | threads | wall time [s] | speed-up | efficiency | serial fraction |"
  echo "|---|---|---|---|---|---|"
  for probe in direct column indirect; do
    read -r -a args <<<"${cmd[$probe]}"
    t1=""
    for n in "${counts[@]}"; do
      t=$(best "$n" "${args[@]}")
      [ -z "$t1" ] && t1=$t
      sp=$(calc "$t1 / $t")
      eff=$(calc "100 * $sp / $n")
      if [ "$n" -gt 1 ]; then
        f=$(calc "100 * ($t / $t1 - 1 / $n) / (1 - 1 / $n)")
        f=$(printf '%.1f %%' "$f")
      else
        f="-"
      fi
      printf '| %s | %s | %.3f | %.2f | %.0f %% | %s |\n' "$probe" "$n" "$t" "$sp" "$eff" "$f"
    done
  done
  # The serial fraction measured inside the command (vltm::timings, VLTM_TIMINGS=1) at one
  # thread: time in serial sections, and with the time outside any section (start-up,
  # planning, writing), over the whole command. Unlike the wall-clock table it does not
  # depend on what else the machine runs.
  echo
  echo "| probe | threads | wall time [s] | serial sections | outside any section | serial fraction (at most) | Amdahl bound on 16 threads |"
  echo "|---|---|---|---|---|---|---|"
  for probe in direct column indirect; do
    read -r -a args <<<"${cmd[$probe]}"
    log=$(VLTM_TIMINGS=1 "$vltm" --threads 1 "${args[@]}" "$work/exh16.npz" "${common[@]}" 2>&1 >/dev/null)
    total=$(grep -o 'timings (1 threads): [0-9.]* s' <<<"$log" | awk '{print $4}')
    line=$(grep 'serial sections' <<<"$log")
    ser=$(sed -E 's/.*serial sections ([0-9.]+) %.*/\1/' <<<"$line")
    out=$(sed -E 's/.*outside any section ([0-9.]+) %.*/\1/' <<<"$line")
    f=$(calc "($ser + $out) / 100")
    printf '| %s | 1 | %.3f | %.1f %% | %.1f %% | %.1f %% | %.1fx |\n' "$probe" "$total" "$ser" "$out" \
      "$(calc "100 * $f")" "$(calc "1 / ($f + (1 - $f) / 16)")"
  done
  exit 0
fi
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
  run "rows: $((n * n)) lasers" "$work/rows$n.npz" column "$(vol 16 24)" --focus "$focus" --no-leak-correct
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
