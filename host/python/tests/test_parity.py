"""Every probe and option of the command line against its Python counterpart: the same
volumes (float32, relative 1e-6 of the maximum; in practice bit for bit) and the same
one-line errors (flags spelled as keyword arguments)."""

import re

import numpy as np
import pytest

import vltm
from conftest import FIXTURE, FOCUS, MAT, SCENE, SMALL, as_python, cli, cli_volume

F = ",".join(map(str, FOCUS))


def close(a, b, rel=1e-6):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, (a.shape, b.shape)
    assert a.dtype == b.dtype == np.float32
    scale = np.abs(a).max()
    assert scale > 0
    err = np.abs(a.astype(np.float64) - b).max() / scale
    assert err <= rel, f"relative difference {err:.3e} > {rel:.0e}"


def cli_parts(tmp, tags, *args):
    out = tmp / "p.npy"
    r = cli(*args, "--out", str(out), "--png", str(tmp / "p.png"))
    assert r.returncode == 0, r.stderr
    return {t: np.load(tmp / (f"p.{t}.npy" if t else "p.npy")) for t in tags}


def same_error(py_call, *cli_args):
    with pytest.raises(vltm.VltmError) as e:
        py_call()
    r = cli(*cli_args)
    assert r.returncode == (2 if isinstance(e.value, vltm.ArgumentError) else 1), r.stderr
    assert as_python(r.stderr) == str(e.value)


@pytest.mark.parametrize("gate", ["none", "higher-order"])
def test_direct_diagonal_gates(two_patches, tmp_path, gate):
    want = cli_volume(tmp_path, "direct", str(two_patches), "--volume", SMALL, "--gate", gate)
    close(want, vltm.direct(two_patches, SMALL, gate=gate))


def test_swap_roles(two_patches, tmp_path):
    want = cli_volume(tmp_path, "direct", str(two_patches), "--volume", SMALL, "--swap-roles")
    got = vltm.direct(two_patches, SMALL, swap_roles=True)
    close(want, got)
    want = cli_volume(tmp_path, "column", str(two_patches), "--volume", SMALL, "--focus", F,
                      "--swap-roles")
    close(want, vltm.column(two_patches, SMALL, FOCUS, swap_roles=True))
    # A split of the swapped rows (SPAD rows) merges into the same volume.
    parts = [vltm.direct(two_patches, SMALL, swap_roles=True, rows=slice(a, b))
             for a, b in [(0, 20), (20, 64)]]
    close(got, vltm.merge(parts).finish())


def test_column_shells_mask_and_leak(two_patches, tmp_path):
    want = cli_parts(tmp_path, ["near", "middle", "far"], "column", str(two_patches),
                     "--volume", SMALL, "--focus", F, "--shells", "0.3,0.6")
    got = vltm.column(two_patches, SMALL, FOCUS, shells=(0.3, 0.6))
    assert got.shape == (3, 6, 6, 4)
    for k, t in enumerate(["near", "middle", "far"]):
        if want[t].max() > 0:
            close(want[t], got[k])
        else:
            assert not got[k].any()
    np.testing.assert_array_equal(got.sum(axis=0), vltm.column(two_patches, SMALL, FOCUS))
    want = cli_volume(tmp_path, "column", str(two_patches), "--volume", SMALL, "--focus", F,
                      "--mask-epsilon", "0.3")
    close(want, vltm.column(two_patches, SMALL, FOCUS, mask_epsilon=0.3))
    want = cli_volume(tmp_path, "column", str(two_patches), "--volume", SMALL, "--focus", F,
                      "--leak-correct", "--leak-epsilon", "0.2")
    got, rep = vltm.column(two_patches, SMALL, FOCUS, leak_correct=True, leak_epsilon=0.2,
                           report=True)
    close(want, got)
    assert 0 < rep["explained"] < 1


def test_indirect_shells_gate_gamma_direct(two_patches, tmp_path):
    vol = "-0.6:0.6:10,-0.6:0.6:10,0.5:1.2:8"
    want = cli_parts(tmp_path, ["near", "middle", "far", "gamma", "direct"], "indirect",
                     str(two_patches), "--volume", vol, "--epsilon", "0.2", "--shells",
                     "0.3,0.6")
    got, rep = vltm.indirect(two_patches, vol, epsilon=0.2, shells=(0.3, 0.6), report=True)
    assert got.shape == (3, 10, 10, 8)
    for k, t in enumerate(["near", "middle", "far"]):
        if want[t].max() > 0:
            close(want[t], got[k])
    np.testing.assert_array_equal(want["gamma"] > 0, rep["gamma"])
    close(want["direct"], rep["direct"])
    want = cli_volume(tmp_path, "indirect", str(two_patches), "--volume", vol, "--epsilon",
                      "0.2", "--gate", "higher-order", "--no-leak-correct")
    close(want, vltm.indirect(two_patches, vol, epsilon=0.2, gate="higher-order",
                              leak_correct=False))


def test_relight(two_patches, tmp_path):
    pat = "-0.25,0.15,0.7,1;0.25,0,0.9,0.5"
    want = cli_volume(tmp_path, "relight", str(two_patches), "--volume", SMALL, "--pattern", pat)
    got, A, rep = vltm.relight(two_patches, SMALL, pat, amplitudes=True, report=True)
    close(want, got)
    close(got, (np.abs(A) ** 2).astype(np.float32), rel=1e-5)
    assert rep["passes"] == 1
    arr = np.array([[-0.25, 0.15, 0.7, 1.0], [0.25, 0.0, 0.9, 0.5]])
    close(want, vltm.relight(two_patches, SMALL, arr))
    # A voxel image of the volume's shape: from a file, as the command line reads it.
    img = np.zeros((6, 6, 4), np.float32)
    img[2, 3, 1], img[4, 1, 2] = 1.0, 0.25
    np.save(tmp_path / "pat.npy", img)
    want = cli_volume(tmp_path, "relight", str(two_patches), "--volume", SMALL, "--pattern",
                      str(tmp_path / "pat.npy"))
    close(want, vltm.relight(two_patches, SMALL, img))
    close(want, vltm.relight(two_patches, SMALL, str(tmp_path / "pat.npy")))
    same_error(lambda: vltm.relight(two_patches, SMALL, "0,0,1,0"),
               "relight", str(two_patches), "--volume", SMALL, "--pattern", "0,0,1,0")


def test_row(two_patches, tmp_path):
    b = "0.25,0,0.9"
    want = cli_volume(tmp_path, "row", str(two_patches), "--volume", SMALL, "--focus", b)
    close(want, vltm.row(two_patches, SMALL, (0.25, 0.0, 0.9)))
    with pytest.raises(vltm.ArgumentError,
                       match="argument `swap_roles`: `row` is the transposed column already"):
        vltm.row(two_patches, SMALL, (0.25, 0.0, 0.9), swap_roles=True)
    r = cli("row", str(two_patches), "--volume", SMALL, "--focus", b, "--swap-roles")
    assert r.returncode == 2 and "is the transposed column already" in r.stderr


PREP = [("--t-min", "1.3", "t_min", 1.3), ("--t-max", "350b", "t_max", "350b"),
        ("--rebin", "2", "rebin", 2), ("--background", "0.000001", "background", 1e-6)]


PAT2 = "-0.25,0.15,0.7,1;0.25,0,0.9,0.5"
# The off-diagonal probes on the capture as it is (the subject is the preprocessing; the leak
# correction leaves nothing above the background on these voxels).
PREP_ARGS = {
    "direct": ((), []), "indirect": ((), []),
    "column": ((FOCUS,), ["--focus", F, "--no-leak-correct"]),
    "relight": ((PAT2,), ["--pattern", PAT2, "--no-leak-correct"]),
    "row": (((0.25, 0.0, 0.9),), ["--focus", "0.25,0,0.9", "--no-leak-correct"]),
}


@pytest.mark.parametrize("probe", sorted(PREP_ARGS))
def test_preprocessing(two_patches, tmp_path, probe):
    """Every probe applies the preprocessing as the command line does (relight and row
    included), each option changing the result."""
    flags = [x for f, v, _, _ in PREP for x in (f, v)]
    kw = {k: v for _, _, k, v in PREP}
    args, extra = PREP_ARGS[probe]
    if "--no-leak-correct" in extra:
        kw["leak_correct"] = False
    want = cli_volume(tmp_path, probe, str(two_patches), "--volume", SMALL, *extra, *flags)
    got, rep = getattr(vltm, probe)(two_patches, SMALL, *args, report=True, **kw)
    close(want, got)
    assert rep["preprocessing"].startswith("window bins")
    empty, of = re.search(r"(\d+) of (\d+) histograms left empty", rep["preprocessing"]).groups()
    assert int(empty) <= int(of) == 64 * 64 == rep["preprocessing_stats"]["histograms"]
    # Each option on its own changes the result (it is not ignored).
    lk = {"leak_correct": False} if "leak_correct" in kw else {}
    plain = getattr(vltm, probe)(two_patches, SMALL, *args, **lk)
    for _, _, k, v in PREP:
        one = getattr(vltm, probe)(two_patches, SMALL, *args, **{k: v}, **lk)
        assert not np.array_equal(one, plain), k


def test_preprocessing_errors(two_patches):
    same_error(lambda: vltm.direct(two_patches, SMALL, t_min="x"),
               "direct", str(two_patches), "--volume", SMALL, "--t-min", "x")
    same_error(lambda: vltm.direct(two_patches, SMALL, background=-1),
               "direct", str(two_patches), "--volume", SMALL, "--background=-1.0")
    # `auto` needs bins no return from the volume reaches: none in this window.
    same_error(lambda: vltm.direct(two_patches, SMALL, background="auto"),
               "direct", str(two_patches), "--volume", SMALL, "--background", "auto")
    same_error(lambda: vltm.direct(two_patches, SMALL, rebin=0),
               "direct", str(two_patches), "--volume", SMALL, "--rebin", "0")
    same_error(lambda: vltm.direct(two_patches, SMALL, t_min=100.0),
               "direct", str(two_patches), "--volume", SMALL, "--t-min", "100.0")
    with pytest.raises(vltm.ArgumentError, match="argument `rows`: partial states do not record"):
        vltm.direct(two_patches, SMALL, rebin=2, rows=slice(0, 8))


def test_transient_equals_info(two_patches):
    r = cli("info", str(two_patches), "--t-min", "1.3", "--rebin", "2")
    assert r.returncode == 0, r.stderr
    line = next(x for x in r.stdout.splitlines() if x.startswith("transient"))
    total, peak, at = re.search(r"([\d.e+-]+) counts; peak bin (\d+) \(path ([\d.]+) m\)", line).groups()
    c, rep = vltm.open(two_patches).transient(t_min=1.3, rebin=2, report=True)
    assert c.dtype == np.float64 and c.ndim == 1
    assert float(total) == pytest.approx(c.sum(), rel=1e-4) and int(np.argmax(c)) == int(peak)
    assert f"{rep['t'][int(peak)]:.4f}" == at
    plain = vltm.open(two_patches).transient()
    assert len(plain) == vltm.open(two_patches).info()["nt"]
    assert plain.sum() >= c.sum() > 0


def test_mat_conventions_and_refusals(two_patches):
    c = vltm.open(MAT, delta_t=0.002, t_start=0.1, grid_width=0.5)
    i = c.info()
    assert (i["delta_t"], i["t_start"]) == (0.002, 0.1)
    wide = vltm.open(MAT, delta_t=0.002, t_start=0.1, grid_width=1.0)
    assert np.abs(wide.laser_points).max() == pytest.approx(2 * np.abs(c.laser_points).max())
    r = cli("info", str(MAT), "--delta-t", "0.002", "--t-start", "0.1", "--grid-width", "0.5")
    assert r.returncode == 0 and "0.002" in r.stdout, r.stderr
    same_error(lambda: vltm.open(two_patches, delta_t=0.01),
               "info", str(two_patches), "--delta-t", "0.01")


def test_simulate(tmp_path):
    r = cli("simulate", str(SCENE), "--out", str(tmp_path / "cli.npz"))
    assert r.returncode == 0, r.stderr
    c = vltm.simulate(SCENE, tmp_path / "py.npz", ptu=tmp_path / "py.ptu")
    assert (tmp_path / "py.ptu").exists() and (tmp_path / "py.json").exists()
    a, b = np.load(tmp_path / "cli.npz"), np.load(tmp_path / "py.npz")
    np.testing.assert_array_equal(a["H"], b["H"])
    assert c.info()["nt"] == 260


def test_memory_and_threads(two_patches):
    with pytest.raises(vltm.ArgumentError, match="argument `size`: expected a size such as 12G"):
        vltm.set_max_memory("12Q")
    old = vltm.max_memory()
    try:
        assert vltm.set_max_memory("1M") == vltm.max_memory() == 1 << 20
        with pytest.raises(vltm.DataError) as e:
            vltm.direct(two_patches, "-0.6:0.6:40,-0.6:0.6:40,0.5:1.2:40")
        assert str(e.value).endswith("> 1.0 MB memory budget (set it with vltm.set_max_memory())")
        with pytest.raises(vltm.ArgumentError, match="argument `size`: expected a size from 1M"):
            vltm.set_max_memory(4096)
    finally:
        vltm.set_max_memory(old)
    with pytest.raises(vltm.ArgumentError, match=r"argument `threads`: expected 1 to"):
        vltm.set_threads(0)
