#!/usr/bin/env bash
# Runs a vltm firmware ELF under qemu-system-arm (with a timeout) and checks it.
#
#   run-qemu.sh MACHINE MODE ELF
#     MACHINE  m4f = mps2-an386 (Cortex-M4F, thumbv7em-none-eabihf)
#              m0  = microbit   (Cortex-M0,  thumbv6m-none-eabi)
#     MODE     text    exit status 0 and the RESULT/REPORT lines equal fixture/expected.txt
#                      (numbers within VLTM_FW_RTOL, default 1e-6, relative to each
#                      quantity's largest value; REPORT lines exactly)
#              defmt   as text, but the output is defmt frames decoded by defmt-print; when
#                      defmt-print is not installed only the exit status is checked
#              status  exit status 0 only (the nopanic firmware)
#              cycles  -icount shift=0 (1 ns of virtual time per instruction); prints the
#                      CYCLES lines; exit status 0
# Environment: VLTM_FW_TIMEOUT (s, default 120), VLTM_FW_RTOL, VLTM_FW_EXPECTED (another
# expected.txt, for the script's own negative test).
# Exit status: 0 = passed; the firmware's own status if it failed; 1 = mismatch; 124 = timeout.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
machine="${1:?machine: m4f|m0}" mode="${2:?mode: text|defmt|status|cycles}" elf="${3:?ELF}"
timeout_s="${VLTM_FW_TIMEOUT:-120}"
rtol="${VLTM_FW_RTOL:-1e-6}"
expected="${VLTM_FW_EXPECTED:-$here/fixture/expected.txt}"

case "$machine" in
  m4f) qemu=(qemu-system-arm -machine mps2-an386 -cpu cortex-m4) ;;
  m0) qemu=(qemu-system-arm -machine microbit) ;;
  *) echo "unknown machine $machine" >&2; exit 2 ;;
esac
qemu+=(-nographic -semihosting-config enable=on,target=native)
[ "$mode" = cycles ] && qemu+=(-icount shift=0,align=off,sleep=off)
qemu+=(-kernel "$elf")

out=$(mktemp) err=$(mktemp)
trap 'rm -f "$out" "$err"' EXIT
rc=0
if [ "$mode" = defmt ] && command -v defmt-print >/dev/null; then
  # Frames go straight into the decoder; pipefail keeps QEMU's (the firmware's) status.
  (set -o pipefail; timeout "$timeout_s" "${qemu[@]}" 2>"$err" \
    | defmt-print -e "$elf" --log-format '{s}' >"$out") || rc=$?
elif [ "$mode" = defmt ]; then
  echo "note: defmt-print not installed (cargo install defmt-print --locked): decoding skipped, exit status only"
  timeout "$timeout_s" "${qemu[@]}" >/dev/null 2>"$err" || rc=$?
  mode=status
else
  timeout "$timeout_s" "${qemu[@]}" >"$out" 2>"$err" || rc=$?
fi
if [ "$rc" -ne 0 ]; then
  echo "FAIL: $(basename "$elf") on $machine exited with $rc$([ "$rc" -eq 124 ] && echo ' (timeout)')" >&2
  cat "$out" "$err" >&2
  exit "$rc"
fi

case "$mode" in
  status) echo "ok: $(basename "$elf") on $machine: exit status 0"; exit 0 ;;
  cycles) grep '^CYCLES' "$out"; exit 0 ;;
esac

# text / defmt: compare the RESULT lines numerically and the REPORT lines exactly.
awk -v rtol="$rtol" -v what="$(basename "$elf") on $machine" '
  function fields(line, arr,   i, n, kv, parts) {
    n = split(line, parts, " ")
    for (i = 2; i <= n; i++) { split(parts[i], kv, "="); arr[kv[1]] = kv[2] }
  }
  FNR == NR {                                   # expected.txt
    if ($1 == "RESULT") {
      delete e; fields($0, e); v = e["voxel"]; nv++
      for (k in e) if (k != "voxel") {
        exp_[v, k] = e[k] + 0; raw[v, k] = e[k]
        if (e[k] < 0 ? -e[k] : e[k] > big[k]) big[k] = (e[k] < 0 ? -e[k] : e[k])
      }
    } else if ($1 == "REPORT") { rep[$0] = 1; nrep++ }
    next
  }
  $1 == "RESULT" {
    delete g; fields($0, g); v = g["voxel"]
    for (k in g) if (k != "voxel") {
      if (!((v, k) in exp_)) { printf "unexpected %s for voxel %s\n", k, v; bad++; continue }
      d = g[k] - exp_[v, k]; if (d < 0) d = -d
      r = (big[k] > 0) ? d / big[k] : d
      if (r > worst) worst = r
      if (d == 0) same++
      if (!(r <= rtol)) { printf "MISMATCH voxel %s %s: firmware %s, host %s (%.3g of max)\n", v, k, g[k], raw[v, k], r; bad++ }
      seen[v, k] = 1; n++
    }
    next
  }
  $1 == "REPORT" { if ($0 in rep) gotrep++; else { printf "REPORT differs: %s\n", $0; bad++ } }
  END {
    for (key in exp_) if (!(key in seen)) { split(key, p, SUBSEP); printf "missing voxel %s %s\n", p[1], p[2]; bad++ }
    printf "%s: %d values vs host, %d bit-identical, max |diff|/max %.3g (tolerance %s); %d REPORT lines matched\n", what, n, same, worst, rtol, gotrep
    exit bad > 0
  }' "$expected" "$out" || { echo "FAIL: $(basename "$elf") on $machine differs from fixture/expected.txt" >&2; exit 1; }
