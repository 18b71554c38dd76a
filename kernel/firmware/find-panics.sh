#!/usr/bin/env bash
# Lists the panicking branches that make the no-panic link fail: builds the nopanic bin with
# a plain panic handler (feature find-panics), disassembles it with line info and prints,
# for every call into core's panic functions, the function and the last source line of this
# workspace (kernel/src or firmware/src) and the (inlined) core function before the call.
# Usage: ./find-panics.sh [TARGET]   (default thumbv7em-none-eabihf)
set -euo pipefail
cd "$(dirname "$0")"
t="${1:-thumbv7em-none-eabihf}"
dir="${CARGO_TARGET_DIR:-$PWD/target}"
cargo build -q --release --no-default-features --features nopanic,find-panics \
  --bin "${VLTM_NOPANIC_BIN:-vltm-firmware-nopanic}" --target "$t"
elf="$dir/$t/release/${VLTM_NOPANIC_BIN:-vltm-firmware-nopanic}"
objdump=$(command -v arm-none-eabi-objdump || echo "$(rustc --print sysroot)/lib/rustlib/x86_64-unknown-linux-gnu/bin/llvm-objdump")
"$objdump" -d -C -l --no-show-raw-insn "$elf" | awk '
  /^[0-9a-f]+ <.*>:$/ { fn = $0; next }
  /^[^ \t\/0-9].*:$/ { inl = $0 }
  /^\/.*\.rs:[0-9]+/ { if ($0 !~ /^\/rustc\// && $0 !~ /\.cargo\/registry/) ours = $0 }
  /\tbl?(\.w)?\t[0-9a-f]+ <core::(panicking|slice::index|option::|result::unwrap_failed|cell::panic)/ {
    n++; sub(/^[ \t]+/, ""); printf "%s\n    in %s\n    from %s\n    last workspace line: %s\n", $0, fn, inl, ours }
  END { printf "%d call(s) into core panic functions\n", n }'
