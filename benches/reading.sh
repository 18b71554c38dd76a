#!/usr/bin/env bash
# Reading speed (docs/performance.md, "Reading y-tal HDF5"): wall time of one `vltm column`
# on the same capture stored three ways, the variants interleaved in one loop so that they
# share the machine's load, medians and ranges over RUNS runs, plus CPU (user + sys) and peak
# resident memory. Needs /usr/bin/time (Debian: time); no Python.
#
#   bash benches/reading.sh NPZ TAL_CONTIGUOUS TAL_GZIP [RUNS]     (default 7 runs)
#
# The captures: `vltm simulate benches/scenes/exh16.json --uncompressed --out exh16.npz`,
# written in tal's layout (time-first T_Lx_Ly_Sx_Sy, contiguous) by y-tal's
# `tal.io.write_capture`, and an h5py copy of that file with `H` gzip-4 in chunks of
# (16, 4, 4, 16, 16). Any number of files can follow the first three; each is one column.
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 3 ] || { sed -n 2,12p "$0" >&2; exit 2; }
command -v /usr/bin/time >/dev/null || { echo "reading.sh needs /usr/bin/time (apt-get install time)" >&2; exit 2; }
runs=7
if [ $# -ge 4 ] && [[ "${!#}" =~ ^[0-9]+$ ]]; then runs="${!#}"; set -- "${@:1:$(($# - 1))}"; fi
cargo build -q --release -p vltm-cli --bin vltm
vltm="${CARGO_TARGET_DIR:-$PWD/target}/release/vltm"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
args=(--focus=-0.4,0,0.75 --volume=-0.9375:0.9375:16,-0.9375:0.9375:16,0.5:1.2:24
  --wavelength 0.5 --sigma 0.5 --weights one --no-leak-correct)
echo "load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
for f in "$@"; do "$vltm" column "$f" "${args[@]}" --out "$work/warm.npy" >/dev/null 2>&1; done
for ((i = 0; i < runs; i++)); do
  k=0
  for f in "$@"; do
    /usr/bin/time -f "%e %U %S %M" -o "$work/t$k" -a \
      "$vltm" column "$f" "${args[@]}" --out "$work/o$k.npy" >/dev/null 2>&1
    k=$((k + 1))
  done
done
echo "load average after: $(cut -d' ' -f1-3 /proc/loadavg)"
echo
echo "| capture | wall median (min–max) | ratio to first | CPU user+sys median | peak RSS |"
echo "|---|---|---|---|---|"
k=0
base=""
for f in "$@"; do
  # median of a sorted column: sorted values on stdin
  median() { awk '{v[NR]=$1} END {printf "%.2f", (NR%2 ? v[(NR+1)/2] : (v[NR/2]+v[NR/2+1])/2)}'; }
  med=$(cut -d' ' -f1 "$work/t$k" | sort -g | median)
  lo=$(cut -d' ' -f1 "$work/t$k" | sort -g | head -1)
  hi=$(cut -d' ' -f1 "$work/t$k" | sort -g | tail -1)
  cpu=$(awk '{print $2 + $3}' "$work/t$k" | sort -g | median)
  rss=$(awk '$4 > m {m = $4} END {printf "%.1f", m / 1024}' "$work/t$k")
  [ -n "$base" ] || base="$med"
  ratio=$(awk -v a="$med" -v b="$base" 'BEGIN {printf "%.2f", a / b}')
  echo "| $(basename "$f") | $med s ($lo–$hi) | $ratio | $cpu s | $rss MB |"
  k=$((k + 1))
done
k=1
for f in "${@:2}"; do
  cmp -s "$work/o0.npy" "$work/o$k.npy" && s="identical" || s="DIFFERENT"
  echo "output of $(basename "$f"): $s to $(basename "$1")'s"
  k=$((k + 1))
done
