#!/usr/bin/env bash
# Builds the Python package in a fresh virtualenv and runs its pytest suite (API against the
# command line on the shared captures, errors, split/merge, a 2-worker Dask LocalCluster).
# Usage: host/python/ci.sh            (from anywhere; VENV=/path to choose the virtualenv)
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
"$venv/bin/pip" install -q maturin numpy pytest dask distributed h5py
# The command line, for the tests that compare against its .npy volumes.
(cd "$repo" && cargo build --release -q -p vltm-cli --bin vltm)
"$venv/bin/pip" install -q "$here"
export VLTM_BIN="$CARGO_TARGET_DIR/release/vltm"
cd "$repo"
set +e
"$venv/bin/python" -m pytest -q "$here/tests"
rc=$?
set -e
if [ "$rc" -eq 5 ]; then
    echo "host/python/ci.sh: pytest collected no tests" >&2
    exit 1
fi
exit "$rc"
