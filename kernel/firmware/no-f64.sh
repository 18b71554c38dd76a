#!/usr/bin/env bash
# No soft f64 in the M4F's per-row and per-scan paths: builds bin vltm-firmware-nof64
# (src/bin/nof64.rs: the set-up in main, the paths in the #[inline(never)] functions per_row
# and per_scan), disassembles it and follows every direct call, branch and address literal
# (`<symbol>` operands) from those two functions (per_row includes LookupSlice::push_row and
# LookupProbe::push_row, per_scan LookupProbe::finish_f32).
# Fails if a soft-double routine (`__aeabi_d*`, `__aeabi_*2d`, `__*df2`/`__*df3`, …) or an
# f64 libm function (a `libm::math::` symbol whose name does not end in `f`) is reachable,
# printing the call chain;
# also fails if a reachable function makes an indirect call (`blx rN`), which this check
# cannot follow. Teeth: main (the set-up) must reach some of them, or the check is blind.
# Usage: ./no-f64.sh [TARGET]   (default thumbv7em-none-eabihf)
set -euo pipefail
cd "$(dirname "$0")"
t="${1:-thumbv7em-none-eabihf}"
dir="${CARGO_TARGET_DIR:-$PWD/target}"
cargo build -q --release --no-default-features --features nopanic --bin vltm-firmware-nof64 --target "$t"
elf="$dir/$t/release/vltm-firmware-nof64"
objdump=$(command -v arm-none-eabi-objdump || echo "$(rustc --print sysroot)/lib/rustlib/x86_64-unknown-linux-gnu/bin/llvm-objdump")
reach() { # reach ROOT-REGEX: prints "reachable N", then "F64 chain" lines and "INDIRECT fn" lines
  "$objdump" -d -C --no-show-raw-insn "$elf" | awk -v roots="$1" '
    /^[0-9a-f]+ <.*>:$/ { cur = $0; sub(/^[0-9a-f]+ </, "", cur); sub(/>:$/, "", cur); fns[cur] = 1; next }
    /^ *[0-9a-f]+:\t/ && cur != "" {
      if ($0 ~ /\tblx?\tr[0-9]+|\tbx\tr([0-9]|1[0-2])\b/) indirect[cur] = 1
      s = $0
      while (match(s, /<[^<>]+>/)) {
        sym = substr(s, RSTART + 1, RLENGTH - 2); s = substr(s, RSTART + RLENGTH)
        sub(/\+0x[0-9a-f]+$/, "", sym)
        if (sym != cur) edges[cur] = edges[cur] SUBSEP sym
      }
    }
    function bad(f) {
      return f ~ /^__aeabi_(d|[a-z0-9]*2d$)/ || f ~ /^(compiler_builtins::.*::)?__[a-z]*(df[23]|dfsi|dfdi|sidf|didf|sfdf|dfsf)/ ||
             (f ~ /^libm::math::/ && f !~ /f$/)
    }
    END {
      n = 0
      for (f in fns) if (f ~ roots) { seen[f] = 1; queue[n++] = f; parent[f] = "" }
      for (i = 0; i < n; i++) {
        f = queue[i]; k = split(edges[f], e, SUBSEP)
        for (j = 2; j <= k; j++) if (!(e[j] in seen) && (e[j] in fns)) { seen[e[j]] = 1; parent[e[j]] = f; queue[n++] = e[j] }
      }
      printf "reachable %d\n", n
      for (i = 0; i < n; i++) {
        f = queue[i]
        if (bad(f)) { c = f; p = parent[f]; while (p != "") { c = p " -> " c; p = parent[p] }; print "F64 " c }
        if (f in indirect) print "INDIRECT " f
      }
    }'
}
out=$(reach 'nof64::per_(row|scan)$')
echo "per_row, per_scan: $(grep -m1 '^reachable' <<<"$out" | cut -d' ' -f2) functions reachable"
teeth=$(reach 'nof64::run$|nof64::__cortex_m_rt_main$' | grep -c '^F64' || true)
[ "$teeth" -gt 0 ] || { echo "the set-up reaches no f64 routine: the check is blind"; exit 1; }
if grep -qE '^(F64|INDIRECT)' <<<"$out"; then
  grep -E '^(F64|INDIRECT)' <<<"$out"
  echo "FAIL: soft f64 (or an unfollowable call) reachable from the per-row/per-scan paths"; exit 1
fi
echo "ok: no soft-double routine or f64 libm function reachable from per_row/per_scan ($teeth reachable from the set-up)"
