#!/usr/bin/env bash
# Builds the Python package's abi3 wheel once, installs the built file in a fresh virtualenv
# and runs its pytest suite (every probe against the command line on the path-traced captures of fixtures/ytal, bad
# input, xarray/netCDF round trips, split/merge, a 2-worker Dask LocalCluster) and the example
# script.
# Usage: host/python/ci.sh            (from anywhere; VENV=/path to choose the virtualenv;
#        VLTM_BIN=/path/to/vltm to compare against a command line already built, e.g. the one
#        `cargo test --release --workspace` built in .ci/run, instead of building it here)
# Exits non-zero on any failure, including "no tests collected" (pytest exit code 5).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
venv="${VENV:-$repo/target/py-venv}"
python="${PYTHON:-python3}"
# Reuse the workspace's build of vltm (same release profile) unless told otherwise.
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$repo/target}"

rm -rf "$venv"
"$python" -m venv "$venv"
"$venv/bin/pip" install -q --upgrade pip
"$venv/bin/pip" install -q maturin numpy pytest dask distributed h5py xarray h5netcdf matplotlib
# The command line, for the tests that compare against its outputs: the one given, or built
# here. (Building it here after `cargo test --release --workspace` compiled it again: the
# test build unifies the dev-dependencies' features — hdf5-pure's deflate — into
# vltm, so `-p vltm-cli` alone hashes differently and rebuilt hdf5-pure, vltm and the CLI.)
if [ -n "${VLTM_BIN:-}" ] && [ -x "$VLTM_BIN" ]; then
    echo "host/python/ci.sh: comparing against $VLTM_BIN"
else
    (cd "$repo" && cargo build --release -q -p vltm-cli --bin vltm)
    VLTM_BIN="$CARGO_TARGET_DIR/release/vltm"
fi
# One wheel for every CPython >= 3.10 (abi3), built once; pip installs the built file.
wheels="$CARGO_TARGET_DIR/wheels"
rm -rf "$wheels"
(cd "$here" && "$venv/bin/maturin" build --release -i "$venv/bin/python" -o "$wheels")
shopt -s nullglob
built=("$wheels"/vltm-*-cp310-abi3-*.whl)
if [ "${#built[@]}" -ne 1 ]; then
    echo "host/python/ci.sh: expected one cp310-abi3 wheel in $wheels, found: $(ls "$wheels")" >&2
    exit 1
fi
"$venv/bin/pip" install -q "${built[0]}"
export VLTM_BIN
cd "$repo"
set +e
"$venv/bin/python" -m pytest -q "$here/tests"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then
    echo "host/python/ci.sh: pytest collected no tests" >&2
    exit 1
fi
[ "$rc" -eq 0 ] || exit "$rc"
# The example: opens a path-traced capture, plots, runs the same on a Dask cluster.
"$venv/bin/python" "$here/examples/two_patches.py" --png "$CARGO_TARGET_DIR/python-example.png"
