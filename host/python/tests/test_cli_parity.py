"""The command line's remaining options and commands against their Python counterparts:
``crop=False`` (``--no-crop``) on every probe, the configuration each summary line reports
(J of ``indirect`` is pass 2's), ``vltm.info`` (``vltm info``'s text, line for line),
``vltm.demo`` (``vltm demo``), and the memory budget over the arrays the wrapper makes."""

import re
import tracemalloc

import numpy as np
import pytest

import vltm
from conftest import FOCUS, MAT, SMALL, as_python, cli

F = ",".join(map(str, FOCUS))
# Voxels near the wall: their paths end before the capture's window does, so `direct` crops
# the time axis (bins 0..362 of 400) and shrinks its DFT period to their paths: J = 32, not 42.
NEAR = "-0.3:0.3:5,-0.3:0.3:5,0.5:0.8:4"
PAT = "-0.25,0.15,0.7,1;0.25,0,0.9,0.5"


def summary(stdout: str, probe: str) -> dict:
    """λ, σ and J of a probe's summary line."""
    line = next(x for x in stdout.splitlines() if x.startswith(f"{probe}:") and "J = " in x)
    lam, sig, j = re.search(r"λ = ([\d.]+) m, σ = ([\d.]+) m, J = (\d+)", line).groups()
    return {"wavelength": float(lam), "sigma": float(sig), "bins": int(j)}


def run_cli(tmp, *args):
    out = tmp / "cli.npy"
    r = cli(*args, "--out", str(out))
    assert r.returncode == 0, r.stderr
    return np.load(out), r.stdout


def same(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype == np.float32
    assert np.abs(a).max() > 0
    np.testing.assert_array_equal(a, b)


PROBES = {
    "direct": ((), []),
    "column": ((FOCUS,), ["--focus", F]),
    "indirect": ((), []),
    "relight": ((PAT,), ["--pattern", PAT]),
    "row": (((0.25, 0.0, 0.9),), ["--focus", "0.25,0,0.9"]),
}


@pytest.mark.parametrize("probe", sorted(PROBES))
@pytest.mark.parametrize("crop", [True, False])
def test_crop_and_the_summary_configuration(two_patches, tmp_path, probe, crop):
    """`crop=False` is `--no-crop` (same volume, bit for bit); the report's λ, σ and J are
    the summary line's, with and without cropping (indirect: pass 2's J)."""
    args, flags = PROBES[probe]
    extra = [] if crop else ["--no-crop"]
    want, stdout = run_cli(tmp_path, probe, str(two_patches), "--volume", NEAR, *flags, *extra)
    got, rep = getattr(vltm, probe)(two_patches, NEAR, *args, crop=crop, report=True)
    same(want, got)
    s = summary(stdout, probe)
    assert rep["bins"] == s["bins"], (rep["bins"], s["bins"])
    assert f"{rep['wavelength']:.4f}" == f"{s['wavelength']:.4f}"
    assert f"{rep['sigma']:.4f}" == f"{s['sigma']:.4f}"
    # The part of the time axis kept: the command line's `<probe>: time axis cropped` line.
    line = [x for x in stdout.splitlines() if x.startswith(f"{probe}: time axis cropped")]
    assert rep["crop"] == (line[0][len(probe) + 2:] if line else None), (rep["crop"], line)
    if not crop:
        assert rep["crop"] is None and rep["crop_bins"] is None
    if probe == "direct":
        # The crop is not ignored: it changes the time axis and shrinks the DFT period to the
        # voxels' paths (J 42 -> 32; at the kernel's period the cropped axis would give 40).
        assert (rep["crop_bins"], rep["bins"]) == (((0, 362, 400), 32) if crop else (None, 42))


def test_matrix_no_crop(two_patches, tmp_path):
    h5py = pytest.importorskip("h5py")
    out = tmp_path / "m.h5"
    frm, to = "-0.25,0.15,0.7;0.25,0,0.9", "-0.6:0.6:4,-0.6:0.6:4,0.5:1.2:3"
    r = cli("matrix", str(two_patches), "--from", frm, "--to", to, "--no-crop", "--out", str(out))
    assert r.returncode == 0, r.stderr
    m = vltm.matrix(two_patches, frm, to, crop=False)
    with h5py.File(out, "r") as f:
        np.testing.assert_array_equal(f["intensity"][:], m.intensities)


def test_crop_is_checked(two_patches):
    with pytest.raises(vltm.ArgumentError, match="argument `crop`: expected True or False"):
        vltm.direct(two_patches, SMALL, crop="no")


def keywords(text: str) -> str:
    """The command line's text with every `--flag` spelled as its keyword argument."""
    return re.sub(r"(?<![\w-])--([a-z][a-z0-9-]*)", lambda m: m.group(1).replace("-", "_"), text)


def test_info_is_the_command_lines_text(two_patches, tmp_path):
    for args, kw in [((), {}), (("--t-min", "1.3", "--rebin", "2"), {"t_min": 1.3, "rebin": 2}),
                     (("--background", "auto"), {"background": "auto"})]:
        r = cli("info", str(two_patches), *args)
        assert r.returncode == 0, r.stderr
        text = vltm.info(two_patches, **kw)
        # Options the text names (the fast paths' `--volume` hint) are keyword arguments here.
        want = keywords(r.stdout)
        assert "e.g. volume -0.7:0.7:8" in want
        assert isinstance(text, str) and text == want
        assert repr(text) == want  # shown as its lines in a REPL
    # --volume: the path a grid takes (an off-lattice grid: the nearest aligned one), as a SPEC
    # or a vltm.Volume; a point list is refused.
    spec = "-0.6:0.6:7,-0.6:0.6:7,0.5:1.0:3"
    r = cli("info", str(two_patches), "--volume", spec)
    assert r.returncode == 0, r.stderr
    want = keywords(r.stdout)
    assert want != keywords(cli("info", str(two_patches)).stdout)
    assert vltm.info(two_patches, volume=spec) == want
    assert vltm.info(two_patches, volume=vltm.Volume(spec)) == want
    with pytest.raises(vltm.ArgumentError, match="argument `volume`"):
        vltm.info(two_patches, volume=vltm.Volume(np.zeros((2, 3)) + 0.5))
    # A Capture opened from a file is described by its file; .mat overrides as on the CLI.
    assert vltm.info(vltm.open(two_patches)) == keywords(cli("info", str(two_patches)).stdout)
    r = cli("info", str(MAT), "--delta-t", "0.002", "--t-start", "0.1", "--grid-width", "0.5")
    assert r.returncode == 0, r.stderr
    # The conventions name the options that set them: keyword arguments here.
    want = keywords(r.stdout)
    assert "(set by grid_width)" in want
    assert vltm.info(MAT, delta_t=0.002, t_start=0.1, grid_width=0.5) == want
    assert vltm.info(vltm.open(MAT, delta_t=0.002, t_start=0.1, grid_width=0.5)) == want
    # --png: the summed transient, and the command line's `wrote` line.
    png = tmp_path / "t.png"
    text = vltm.info(two_patches, png=png)
    assert png.stat().st_size > 0 and text.endswith(f"wrote {png}\n")
    # The same one-line errors, keyword arguments for flags.
    with pytest.raises(vltm.ArgumentError) as e:
        vltm.info(two_patches, delta_t=0.01)
    r = cli("info", str(two_patches), "--delta-t", "0.01")
    assert r.returncode == 2 and as_python(r.stderr) == str(e.value)
    with pytest.raises(vltm.DataError) as e:
        vltm.info(tmp_path / "missing.npz")
    r = cli("info", str(tmp_path / "missing.npz"))
    assert r.returncode == 1 and as_python(r.stderr) == str(e.value)
    with pytest.raises(vltm.ArgumentError, match="argument `capture`: info describes a capture file"):
        vltm.info(vltm.Capture.from_arrays(np.ones((8, 2, 2)), np.ones((2, 3)), np.ones((2, 3)), 0.01))


def test_demo(tmp_path):
    """`vltm.demo()` is `vltm demo`: the table it prints (and writes to summary.txt), and each
    result's figure and volume."""
    out = tmp_path / "demo"
    table = vltm.demo(out)
    assert table == (out / "summary.txt").read_text()
    lines = table.splitlines()
    assert lines[0].startswith("vltm demo: panel at [-0.35, 0.0, 0.8]")
    h = next(i for i, ln in enumerate(lines) if ln.startswith("probe "))
    rows = [ln.split("  ")[0].strip() for ln in lines[h + 1:h + 11]]
    assert rows[0] == "direct (diagonal)" and rows[-1] == "in-focus indirect (Eq. 17)", rows
    npys = sorted(p.stem for p in out.glob("*.npy"))
    assert len(npys) == 10 and sorted(p.stem for p in out.glob("*.png")) == npys
    direct = np.load(out / "direct.npy")
    assert direct.shape == (21, 11, 13) and direct.dtype == np.float32 and direct.max() > 0
    # The brightest direct light is on the panel, as the table says.
    assert lines[h + 1].endswith("panel (0.04 m)"), lines[h + 1]
    with pytest.raises(vltm.ArgumentError, match="argument `out`"):
        vltm.demo(3)


@pytest.fixture
def small_budget():
    old = vltm.max_memory()
    vltm.set_max_memory("1M")
    try:
        yield 1 << 20
    finally:
        vltm.set_max_memory(old)


def refused_before_allocating(call, nbytes):
    """`call` raises one DataError line naming the budget and the largest buffer, having
    allocated (NumPy's allocations, traced) far less than the `nbytes` it would need."""
    tracemalloc.start()
    try:
        with pytest.raises(vltm.DataError) as e:
            call()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    msg = str(e.value)
    assert "\n" not in msg and "largest buffer" in msg, msg
    assert msg.endswith("> 1.0 MB memory budget (set it with vltm.set_max_memory())"), msg
    assert peak < nbytes / 4, (peak, nbytes)
    return msg


def test_python_arrays_count_against_the_budget(small_budget):
    # A float64 capture of 1.3 MB: its float32 copies, the finiteness mask and the
    # library's capture would take 2.6 MB.
    H = np.ones((160, 32, 32))
    msg = refused_before_allocating(
        lambda: vltm.Capture.from_arrays(H, np.zeros((32, 3)), np.zeros((32, 3)), 0.01),
        4 * H.size)
    assert msg.startswith("a capture from arrays of 163840 samples; largest buffer"), msg
    # Points of a volume (float64 → float32 copy and mask), a direct-light volume.
    pts = np.ones((200_000, 3))
    msg = refused_before_allocating(lambda: vltm.Volume(pts), 4 * pts.size)
    assert msg.startswith("argument `volume`: an array of 600000 values"), msg
    d = np.ones(300_000)
    refused_before_allocating(lambda: vltm.gamma_mask(d), 4 * d.size)
    # Within the budget the same calls work.
    vltm.set_max_memory("64M")
    c = vltm.Capture.from_arrays(H, np.zeros((32, 3)), np.zeros((32, 3)), 0.01)
    assert c.info()["nt"] == 160
