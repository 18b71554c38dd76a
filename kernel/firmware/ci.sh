#!/usr/bin/env bash
# Embedded checks of vltm-kernel in QEMU: the fixture is up to date with the host kernel, the
# firmware on Cortex-M4F (mps2-an386) and Cortex-M0 (microbit) reproduces the host's numbers,
# the defmt firmware runs (and is decoded when defmt-print is installed), the lookup path's
# firmware is bit-identical to the host on both, the kernel's per-row paths link with
# panic-never on both ISAs (and a planted panic does not), the instruction counts of the real
# setup, and the sizes.
#
# Needs (installs nothing): qemu-system-arm (apt), rustup targets thumbv7em-none-eabihf and
# thumbv6m-none-eabi; the host's `vltm` binary (VLTM_BIN, else built in the root workspace) to
# render the fixture; optional: defmt-print (cargo install defmt-print --locked),
# arm-none-eabi-size (apt binutils-arm-none-eabi) or llvm-size (rustup component llvm-tools).
# Honours CARGO_TARGET_DIR (share it with other builds to save the host build scripts).
# Ends with "N passed, M failed: firmware"; exit status 1 if anything failed.
set -uo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cd "$here"
export CARGO_TERM_COLOR=never
tdir="${CARGO_TARGET_DIR:-$here/target}"
export CARGO_TARGET_DIR="$tdir"
M4=thumbv7em-none-eabihf M0=thumbv6m-none-eabi
passed=0 failed=0 failures=()

step() { # step NAME COMMAND...: runs COMMAND, counts it
  local name="$1"; shift
  local t0=$SECONDS
  echo "== $name"
  if "$@"; then passed=$((passed + 1)); echo "   ok ($((SECONDS - t0)) s)"
  else failed=$((failed + 1)); failures+=("$name"); echo "   FAILED: $name ($((SECONDS - t0)) s)"; fi
}

command -v qemu-system-arm >/dev/null || {
  echo "qemu-system-arm not found: apt-get install -y --no-install-recommends qemu-system-arm" >&2
  echo "0 passed, 1 failed: firmware"; exit 1; }
missing=$(comm -23 <(printf '%s\n' $M0 $M4) <(rustup target list --installed 2>/dev/null | sort))
[ -z "$missing" ] || {
  echo "missing rustup targets: $missing (rustup target add $M4 $M0)" >&2
  echo "0 passed, 1 failed: firmware"; exit 1; }

fw() { cargo build -q --release "$@"; }        # firmware build, in kernel/firmware
elf() { echo "$tdir/$1/release/$2"; }

fmt_check() { cargo fmt --check && (cd gen && cargo fmt --check); }
step "rustfmt (firmware, gen)" fmt_check
gen_tests() { (cd gen && cargo test -q --release); }
step "gen unit tests (state templates)" gen_tests

fixture_up_to_date() { # the host simulator renders fixture/scene.json, gen runs the kernel
  local out; out=$(mktemp -d)
  bash fixture/regenerate.sh "$out" 2>/dev/null || { rm -rf "$out"; return 1; }
  cmp "$out/scan.bin" fixture/scan.bin && cmp "$out/expected.txt" fixture/expected.txt || {
    echo "fixture/ is stale (the simulator's or the host kernel's numbers changed): regenerate" \
         "with 'bash kernel/firmware/fixture/regenerate.sh' and review the diff"
    diff "$out/expected.txt" fixture/expected.txt | head -20; rm -rf "$out"; return 1; }
  for f in state_direct.json state_column.json; do
    cmp "$out/$f" "fixture/$f" || {
      echo "fixture/$f is stale (the host's partial-state header changed): regenerate"
      diff "$out/$f" "fixture/$f" | head -5; rm -rf "$out"; return 1; }
  done
  cmp "$out/expected_fixed.txt" fixture/expected_fixed.txt || {
    echo "fixture/expected_fixed.txt is stale (the host's fixed-point numbers changed): regenerate"
    diff "$out/expected_fixed.txt" fixture/expected_fixed.txt | head -20; rm -rf "$out"; return 1; }
  cmp "$out/expected_lookup.txt" fixture/expected_lookup.txt || {
    echo "fixture/expected_lookup.txt is stale (the host's lookup-path numbers changed): regenerate"
    diff "$out/expected_lookup.txt" fixture/expected_lookup.txt | head -20; rm -rf "$out"; return 1; }
  rm -rf "$out"
}
step "fixture: host simulator + kernel (x86) reproduce scan.bin, expected.txt, expected_fixed.txt, expected_lookup.txt" fixture_up_to_date

for t in $M4 $M0; do
  m=$([ $t = $M4 ] && echo m4f || echo m0)
  step "text firmware $t: build" fw --target $t --bin vltm-firmware
  step "text firmware on $m: verdict 0, numbers = host" ./run-qemu.sh $m text "$(elf $t vltm-firmware)"
done

# The fixed-point path (integer per-bin arithmetic, IEEE soft-float seeds): bit-identical to
# the host on both ISAs, hence VLTM_FW_RTOL=0.
for t in $M0 $M4; do
  m=$([ $t = $M4 ] && echo m4f || echo m0)
  step "fixed-point firmware $t: build" fw --target $t --features fixed --bin vltm-firmware-fixed
  step "fixed-point firmware on $m: verdict 0, bit-identical to host" env VLTM_FW_RTOL=0 \
    VLTM_FW_EXPECTED="$here/fixture/expected_fixed.txt" ./run-qemu.sh $m text "$(elf $t vltm-firmware-fixed)"
done

# The merged kernel's lookup and no-panic bins (33 KB and 10.4 KB of .bss, the lookup bin's
# mostly the structured slice's scratch, and the band transform's 1.5 KB of stack) overflow the
# microbit's 16 KB of RAM: their ARMv6-M code is linked for the mps2-an386 memory map and run
# there (its Cortex-M4 executes the M0's instruction stream unchanged). The microbit builds of
# the no-panic bins still prove the panic-never link.
m0big() { CARGO_TARGET_DIR="$tdir/an386-m0" VLTM_FW_BOARD=mps2-an386 fw --target $M0 "$@"; }
m0big_elf() { echo "$tdir/an386-m0/$M0/release/$1"; }

# The lookup path (src/lookup_pipeline.rs: the voxel list's probes and the structured slice):
# bit-identical to the host on both ISAs.
for t in $M4 $M0; do
  m=$([ $t = $M4 ] && echo m4f || echo m0)
  step "no-panic proof, lookup path, $t: links with panic-never" fw --target $t \
    --no-default-features --features nopanic --bin vltm-firmware-lookup-nopanic
  if [ $t = $M4 ]; then
    step "lookup firmware $t: build" fw --target $t --features lookup --bin vltm-firmware-lookup
    step "lookup firmware on m4f: verdict 0, bit-identical to host" env VLTM_FW_RTOL=0 \
      VLTM_FW_EXPECTED="$here/fixture/expected_lookup.txt" ./run-qemu.sh m4f text "$(elf $t vltm-firmware-lookup)"
    step "no-panic lookup firmware on m4f: exit 0" ./run-qemu.sh m4f status "$(elf $t vltm-firmware-lookup-nopanic)"
  else
    step "lookup firmware $t (mps2-an386 memory map): build" m0big --features lookup --bin vltm-firmware-lookup
    step "lookup firmware, M0 code: verdict 0, bit-identical to host" env VLTM_FW_RTOL=0 \
      VLTM_FW_EXPECTED="$here/fixture/expected_lookup.txt" ./run-qemu.sh m4f text "$(m0big_elf vltm-firmware-lookup)"
    step "no-panic lookup firmware $t (mps2-an386 memory map): build" m0big --no-default-features \
      --features nopanic --bin vltm-firmware-lookup-nopanic
    step "no-panic lookup firmware, M0 code: exit 0" ./run-qemu.sh m4f status "$(m0big_elf vltm-firmware-lookup-nopanic)"
  fi
done

# No soft f64 in the M4F's per-row and per-scan paths (src/bin/nof64.rs, no-f64.sh): no
# __aeabi_d* / f64 libm routine reachable from RowBuffer::load, the photon row, ColumnF32's
# push_row, finish and finish_lookup, LookupSlice::push_row, LookupProbe::push_row and
# finish_f32 (the set-up must reach some: teeth). Also a panic-never link.
step "no soft f64 reachable from load/push_row/finish, lookup slice and probe push_row (M4F disassembly), no-panic link" ./no-f64.sh $M4
step "no-f64 firmware on m4f: exit 0" ./run-qemu.sh m4f status "$(elf $M4 vltm-firmware-nof64)"

negative() { # a host value changed by 1.1e-6 of its maximum must be reported
  local bad; bad=$(mktemp)
  sed 's/^\(RESULT voxel=5 diag=\)3\.0739841152957463e8/\13.0739876e8/' fixture/expected.txt >"$bad"
  ! cmp -s "$bad" fixture/expected.txt || { rm -f "$bad"; return 1; }
  if VLTM_FW_EXPECTED="$bad" ./run-qemu.sh m4f text "$(elf $M4 vltm-firmware)" >/dev/null 2>&1; then
    rm -f "$bad"; echo "run-qemu.sh accepted a wrong value"; return 1; fi
  rm -f "$bad"
}
step "run-qemu.sh rejects a value off by 1.1e-6" negative

defmt_note=""
command -v defmt-print >/dev/null || defmt_note=" (defmt-print not installed: exit status only)"
for t in $M4 $M0; do
  m=$([ $t = $M4 ] && echo m4f || echo m0)
  step "defmt firmware $t: build" env DEFMT_LOG=debug cargo build -q --release --target $t \
    --features defmt --bin vltm-firmware-defmt
  step "defmt firmware on $m$defmt_note" ./run-qemu.sh $m defmt "$(elf $t vltm-firmware-defmt)"
done

for t in $M4 $M0; do
  m=$([ $t = $M4 ] && echo m4f || echo m0)
  step "no-panic proof $t: links with panic-never" fw --target $t --no-default-features \
    --features nopanic --bin vltm-firmware-nopanic
  if [ $t = $M4 ]; then
    step "no-panic firmware on m4f: exit 0" ./run-qemu.sh m4f status "$(elf $t vltm-firmware-nopanic)"
  else
    step "no-panic firmware $t (mps2-an386 memory map): build" m0big --no-default-features \
      --features nopanic --bin vltm-firmware-nopanic
    step "no-panic firmware, M0 code: exit 0" ./run-qemu.sh m4f status "$(m0big_elf vltm-firmware-nopanic)"
  fi
done
for t in $M4 $M0; do
  m=$([ $t = $M4 ] && echo m4f || echo m0)
  step "no-panic proof, fixed-point path, $t: links with panic-never" fw --target $t \
    --no-default-features --features nopanic --bin vltm-firmware-fixed-nopanic
  if [ $t = $M4 ]; then
    step "no-panic fixed-point firmware on m4f: exit 0" ./run-qemu.sh m4f status "$(elf $t vltm-firmware-fixed-nopanic)"
  else
    # 12.1 KB of .bss (band and lookup probes side by side) leave the microbit ~4 KB of stack,
    # which the lookup column's soft-float calls exceed: run its M0 code on the an386 map.
    step "no-panic fixed-point firmware $t (mps2-an386 memory map): build" m0big --no-default-features \
      --features nopanic --bin vltm-firmware-fixed-nopanic
    step "no-panic fixed-point firmware, M0 code: exit 0" ./run-qemu.sh m4f status "$(m0big_elf vltm-firmware-fixed-nopanic)"
  fi
done
no_fmt() { # the no-panic ELFs hold no core::fmt symbol; the text firmware (teeth) does
  local nm e n
  nm=$(command -v arm-none-eabi-nm || true)
  [ -n "$nm" ] || nm="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin/llvm-nm"
  [ -x "$nm" ] || { echo "no arm-none-eabi-nm or llvm-nm"; return 1; }
  for e in "$(elf $M4 vltm-firmware-nopanic)" "$(elf $M0 vltm-firmware-nopanic)" \
           "$(elf $M4 vltm-firmware-fixed-nopanic)" "$(elf $M0 vltm-firmware-fixed-nopanic)" \
           "$(elf $M4 vltm-firmware-lookup-nopanic)" "$(elf $M0 vltm-firmware-lookup-nopanic)"; do
    n=$("$nm" -C "$e" | grep -c 'core::fmt' || true)
    [ "$n" -eq 0 ] || { echo "$e: $n core::fmt symbols"; "$nm" -C "$e" | grep 'core::fmt' | head -5; return 1; }
  done
  n=$("$nm" -C "$(elf $M4 vltm-firmware)" | grep -c 'core::fmt' || true)
  [ "$n" -gt 0 ] || { echo "the check finds no core::fmt even in the text firmware"; return 1; }
}
step "no-panic ELFs (M4F, M0; float, fixed, lookup) hold no core::fmt" no_fmt

canary() { # the same bin with one panicking index must fail to link, with panic-never's message
  local log; log=$(mktemp)
  if cargo build -q --release --target $M4 --no-default-features --features nopanic,panic-canary \
       --bin vltm-firmware-nopanic >"$log" 2>&1; then
    rm -f "$log"; echo "the panic canary linked: the no-panic check is not working"; return 1; fi
  grep -q 'panic-never' "$log" || { cat "$log"; rm -f "$log"; return 1; }
  rm -f "$log"
  fw --target $M4 --no-default-features --features nopanic --bin vltm-firmware-nopanic # restore
}
step "no-panic self-test: a planted panic fails to link" canary

readme_example() { # the README's minimal firmware is src/bin/minimal.rs, verbatim
  awk '/^plus a `memory.x`/ {on=1} on && /^```rust$/ {code=1; next} code && /^```$/ {exit} code' \
    README.md | diff - src/bin/minimal.rs
}
step "README's minimal firmware = src/bin/minimal.rs" readme_example
for t in $M4 $M0; do
  m=$([ $t = $M4 ] && echo m4f || echo m0)
  step "minimal firmware (README) $t: build" fw --target $t --no-default-features \
    --features minimal --bin vltm-firmware-minimal
  step "minimal firmware on $m: exit 0" ./run-qemu.sh $m status "$(elf $t vltm-firmware-minimal)"
done

step "cycles firmware $M4: build" fw --target $M4 --features cycles --bin vltm-firmware-cycles
step "instruction counts, real setup, on m4f (-icount), per-row budgets enforced" ./run-qemu.sh m4f cycles "$(elf $M4 vltm-firmware-cycles)"
# The M0's fixed-point path: its ARMv6-M code linked for the mps2-an386 (the microbit's 16 KB
# of RAM cannot hold the real setup), in its own target dir (another memory map). Reported.
m0_an386() { CARGO_TARGET_DIR="$tdir/an386-m0" VLTM_FW_BOARD=mps2-an386 fw --target $M0 \
  --features cycles --bin vltm-firmware-fixed-cycles; }
step "fixed-point cycles firmware $M0 (mps2-an386 memory map): build" m0_an386
step "instruction counts, fixed-point path (M0 code), real setup (-icount), reported" \
  ./run-qemu.sh m4f cycles "$tdir/an386-m0/$M0/release/vltm-firmware-fixed-cycles"

# Firmware to host: the MCU folds the scan's last rows and writes its state in vltm's
# partial-state format (semihosting files); the host folds the other rows, `vltm merge` adds
# both and must give the host's whole run (direct light and the column T(P1, ·)). A state
# with a flipped byte, overlapping rows or other parameters must be refused.
vltm_bin="${VLTM_BIN:-$here/../../target/release/vltm}"
gen() { (cd "$here/gen" && cargo run -q --release -- "$@"); }
state_merge() { # state_merge MACHINE ELF
  local m="$1" elf="$2" t; t=$(mktemp -d)
  [ -x "$vltm_bin" ] || { echo "no vltm binary at $vltm_bin (set VLTM_BIN)"; return 1; }
  local qemu=(qemu-system-arm -machine mps2-an386 -cpu cortex-m4)
  [ "$m" = m0 ] && qemu=(qemu-system-arm -machine microbit)
  (cd "$t" && timeout 120 "${qemu[@]}" -nographic -semihosting-config enable=on,target=native \
    -kernel "$elf") || { echo "state firmware on $m failed"; rm -rf "$t"; return 1; }
  local pts focus wl rows ok=0
  pts=$(gen volume) focus=$(gen focus) wl=$(gen wavelength) rows=$(gen host-rows)
  "$vltm_bin" simulate fixture/scene.json --out "$t/scene.npz" --uncompressed >/dev/null 2>&1
  local -a d=(direct "$t/scene.npz" --volume "$pts" --wavelength "$wl" --path band)
  local -a c=(column "$t/scene.npz" --focus="$focus" --volume "$pts" --wavelength "$wl" --no-leak-correct)
  for p in d c; do
    local -n args=$p
    local fw="$t/fw_direct.vltmpart"; [ $p = c ] && fw="$t/fw_column.vltmpart"
    "$vltm_bin" "${args[@]}" --rows "$rows" --partial "$t/host_$p.part" >/dev/null 2>&1 &&
    "$vltm_bin" merge "$t/host_$p.part" "$fw" --out "$t/merged_$p.npy" >/dev/null 2>&1 &&
    "$vltm_bin" "${args[@]}" --out "$t/whole_$p.npy" >/dev/null 2>&1 &&
    gen compare "$t/merged_$p.npy" "$t/whole_$p.npy" 1e-6 || ok=1
    # Teeth: a flipped payload byte (CRC), the firmware's rows twice, other parameters.
    cp "$fw" "$t/bad"; printf '\xff' | dd of="$t/bad" bs=1 seek=$(( $(stat -c %s "$fw") - 3 )) conv=notrunc 2>/dev/null
    ! "$vltm_bin" merge "$t/host_$p.part" "$t/bad" --out "$t/x.npy" >/dev/null 2>&1 || { echo "corrupt state merged"; ok=1; }
    ! "$vltm_bin" merge "$fw" "$fw" --out "$t/x.npy" >/dev/null 2>&1 || { echo "overlapping rows merged"; ok=1; }
    "$vltm_bin" "${args[@]}" --rows "$rows" --partial "$t/other.part" --sigma 0.08 >/dev/null 2>&1
    ! "$vltm_bin" merge "$t/other.part" "$fw" --out "$t/x.npy" >/dev/null 2>&1 || { echo "other parameters merged"; ok=1; }
    unset -n args
  done
  # `vltm live --resume` on the firmware's states: the host folds rows 0..8 as they are
  # replayed, and the result equals the host's whole run.
  "$vltm_bin" live "$t/scene.npz" --replay-rate 1000 --volume "$pts" --wavelength "$wl" \
      --focus="$focus" --resume "$t/fw_direct.vltmpart" --resume "$t/fw_column.vltmpart" \
      --no-indirect --out "$t/live.npy" >/dev/null 2>&1 &&
    gen compare "$t/live.npy" "$t/whole_d.npy" 1e-6 &&
    gen compare "$t/live.column0.npy" "$t/whole_c.npy" 1e-6 ||
    { echo "vltm live --resume from the firmware's states failed or differs"; ok=1; }
  rm -rf "$t"; return $ok
}
for t in $M4 $M0; do
  m=$([ $t = $M4 ] && echo m4f || echo m0)
  step "state firmware $t: build" fw --target $t --features state --bin vltm-firmware-state
  step "firmware state (rows 8..16, $m) + host part (rows 0..8) merged, and live --resume, = host's whole run" \
    state_merge $m "$(elf $t vltm-firmware-state)"
done

size=$(command -v arm-none-eabi-size || true)
[ -n "$size" ] || size="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin/llvm-size"
if [ -x "$size" ]; then
  echo "== sizes ($(basename "$size"); text = flash incl. the 16 KB scan, bss = static RAM)"
  for t in $M4 $M0; do
    for b in vltm-firmware vltm-firmware-defmt vltm-firmware-nopanic vltm-firmware-fixed vltm-firmware-fixed-nopanic \
             vltm-firmware-lookup vltm-firmware-lookup-nopanic; do
      e="$(elf $t $b)"
      # The M0's lookup bin is linked for the mps2-an386 memory map only (a microbit ELF
      # left in the target dir by an older build would be stale).
      [ $t = $M0 ] && [ $b = vltm-firmware-lookup ] && e="$(m0big_elf $b)" && b="$b (an386)"
      [ -f "$e" ] && "$size" "$e" | tail -1 | awk -v t=$t -v b="$b" '{printf "   %-22s %-22s text %7d data %5d bss %6d\n", t, b, $1, $2, $3}'
    done
  done
else
  echo "== sizes: skipped (no arm-none-eabi-size or llvm-size)"
fi

[ ${#failures[@]} -eq 0 ] || printf 'failed: %s\n' "${failures[@]}"
echo "$passed passed, $failed failed: firmware"
[ "$failed" -eq 0 ]
