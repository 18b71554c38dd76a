"""Paths for the vltm pytest suite: the repository, its fixtures (the path-traced y-tal
captures of `fixtures/ytal`, checked against `fixtures/SHA256SUMS` before use) and the `vltm`
command line (`VLTM_BIN`, default `target/release/vltm`)."""

import hashlib
import os
import pathlib
import subprocess

import numpy as np
import pytest

REPO = pathlib.Path(__file__).resolve().parents[3]
TWO_PATCHES = REPO / "fixtures" / "ytal" / "two_patches" / "two_patches.hdf5"
FIXTURE = REPO / "fixtures" / "two_patches.npz"


def checked_fixture(path: pathlib.Path) -> pathlib.Path:
    """`path` (under `fixtures/`), failing with a message that names it and says how to
    restore it when it is missing or its SHA-256 differs from `fixtures/SHA256SUMS`."""
    rel = path.relative_to(REPO / "fixtures").as_posix()
    restore = (f"restore it with `git checkout -- fixtures/{rel}` "
               "(fixtures/README.md says how it is made)")
    if not path.is_file():
        pytest.fail(f"fixture fixtures/{rel} is missing: {restore}", pytrace=False)
    sums = {}
    for line in (REPO / "fixtures" / "SHA256SUMS").read_text().splitlines():
        if line.strip():
            digest, name = line.split("  ", 1)
            sums[name.strip()] = digest
    want = sums.get(rel)
    if want is not None:
        got = hashlib.sha256(path.read_bytes()).hexdigest()
        if got != want:
            pytest.fail(f"fixture fixtures/{rel} is damaged (SHA-256 {got}, "
                        f"fixtures/SHA256SUMS says {want}): {restore}", pytrace=False)
    return path
GRID = "-0.75:0.75:16,-0.75:0.75:16,0.4:1.35:20"
FOCUS = (-0.25, 0.15, 0.7)


def vltm_bin() -> pathlib.Path:
    b = pathlib.Path(os.environ.get("VLTM_BIN", REPO / "target" / "release" / "vltm"))
    if not b.exists():
        raise RuntimeError(f"the vltm command line is not built: {b} (cargo build --release)")
    return b


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(vltm_bin()), *args], capture_output=True, text=True)


def cli_volume(tmp: pathlib.Path, *args: str) -> np.ndarray:
    out = tmp / "cli.npy"
    r = cli(*args, "--out", str(out), "--png", str(tmp / "cli.png"))
    assert r.returncode == 0, r.stderr
    return np.load(out)


@pytest.fixture(scope="session")
def two_patches() -> pathlib.Path:
    return checked_fixture(TWO_PATCHES)


KEYWORDS = {"from": "from_", "no-leak-correct": "leak_correct", "partial": "rows",
            "max-memory": "vltm.set_max_memory()", "threads": "vltm.set_threads()"}


def as_python(stderr: str) -> str:
    """A command-line error line as the Python API words it: `vltm: ` dropped, every
    `--flag` spelled as its keyword argument (`--t-min` → `t_min`)."""
    import re

    msg = stderr.strip()
    assert msg.startswith("vltm: "), msg
    msg = msg[len("vltm: "):]
    return re.sub(r"(?<![\w-])--([a-z][a-z0-9-]*)",
                  lambda m: KEYWORDS.get(m.group(1), m.group(1).replace("-", "_")), msg)


SMALL = "-0.6:0.6:6,-0.6:0.6:6,0.5:1.2:4"
MAT = REPO / "fixtures" / "mat" / "stanford_v73.mat"
SCENE = REPO / "fixtures" / "sim" / "small_scene.json"
