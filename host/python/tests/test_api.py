"""The Python API against the command line's .npy volumes on the path-traced captures, arrays in
(Capture.from_arrays), exceptions on bad input, and partial states split/merged/pickled."""

import pickle

import numpy as np
import pytest

import vltm
from conftest import FIXTURE, FOCUS, GRID, as_python, cli, cli_volume


def close(a: np.ndarray, b: np.ndarray, rel: float = 1e-6) -> None:
    assert a.shape == b.shape and a.dtype == b.dtype == np.float32
    assert a.max() > 0
    err = np.abs(a.astype(np.float64) - b).max() / a.max()
    assert err <= rel, f"relative difference {err:.3e} > {rel:.0e}"


def test_direct_equals_cli(two_patches, tmp_path):
    want = cli_volume(tmp_path, "direct", str(two_patches), "--volume", GRID)
    got = vltm.direct(vltm.open(two_patches), GRID)
    close(want, got)
    # y-tal's convention: the peak on patch A.
    i = np.unravel_index(np.argmax(got), got.shape)
    assert vltm.volume(GRID).points[i][2] == pytest.approx(0.65, abs=0.06)


def test_column_and_indirect_equal_cli(two_patches, tmp_path):
    f = ",".join(map(str, FOCUS))
    want = cli_volume(tmp_path, "column", str(two_patches), "--volume", GRID, "--focus", f)
    close(want, vltm.column(str(two_patches), GRID, FOCUS))
    want = cli_volume(tmp_path, "column", str(two_patches), "--volume", GRID, "--focus", f,
                      "--gate", "higher-order", "--shell", "0.2:0.9")
    close(want, vltm.column(two_patches, GRID, FOCUS, gate="higher-order", shell=(0.2, 0.9)))
    vol = "-0.6:0.6:10,-0.6:0.6:10,0.5:1.2:8"


def test_indirect_equals_cli_with_and_without_leak_correction(two_patches, tmp_path):
    vol = "-0.6:0.6:10,-0.6:0.6:10,0.5:1.2:8"
    # Both default to leak correction (the direct-return windows of Γ zeroed).
    want = cli_volume(tmp_path, "indirect", str(two_patches), "--volume", vol, "--epsilon", "0.2")
    got, rep = vltm.indirect(two_patches, vol, epsilon=0.2, report=True)
    close(want, got)
    assert 0.0 < rep["explained"] < 1.0
    plain = cli_volume(tmp_path, "indirect", str(two_patches), "--volume", vol, "--epsilon", "0.2",
                       "--no-leak-correct")
    close(plain, vltm.indirect(two_patches, vol, epsilon=0.2, leak_correct=False))
    # The correction changes the result (direct light leaks into Eq. 17 on this scene).
    assert np.abs(plain - want).max() > 0.01 * plain.max()
    # Γ given (as with rows=): the same numbers.
    d = vltm.direct(two_patches, vol)
    close(want, vltm.indirect(two_patches, vol, epsilon=0.2, direct=d))


def test_leak_correct_model_equals_cli(tmp_path):
    """``leak_correct="model"`` is the command line's ``--leak-correct model``: the surface
    model subtracted where it explains >= 99 % (the simulated two patches), the windows with
    a RuntimeWarning carrying the command line's reason where it does not (three point
    scatterers); ``"gate"`` is ``True``; another value is refused naming ``leak_correct``;
    a partial in-focus sum cannot take the model."""
    vol = "-0.6:0.6:10,-0.6:0.6:10,0.5:1.2:8"
    cap = str(FIXTURE)
    want = cli_volume(tmp_path, "indirect", cap, "--volume", vol, "--epsilon", "0.2",
                      "--leak-correct", "model")
    got, rep = vltm.indirect(cap, vol, epsilon=0.2, leak_correct="model", report=True)
    close(want, got)
    assert rep["leak_correct"] == "model" and 0.99 <= rep["explained"] < 1.0
    assert "warnings" not in rep
    gate, rg = vltm.indirect(cap, vol, epsilon=0.2, leak_correct="gate", report=True)
    assert rg["leak_correct"] == "gate"
    close(vltm.indirect(cap, vol, epsilon=0.2), gate)
    # The model keeps what the windows zero.
    assert np.abs(got - gate).max() > 0.01 * gate.max()
    focus = (-0.45, 0.0, 0.8)
    want = cli_volume(tmp_path, "column", cap, "--volume", vol, "--focus",
                      ",".join(map(str, focus)), "--leak-correct", "model")
    close(want, vltm.column(cap, vol, focus, leak_correct="model"))
    three = str(FIXTURE.parent / "three_points.npz")
    with pytest.warns(RuntimeWarning, match=r"explains 86\.6 % of the energy \(< 99 %\); "
                      r"using the time windows \(leak_correct=\"gate\"\)"):
        got, rep = vltm.indirect(three, vol, epsilon=0.2, leak_correct="model", report=True)
    assert rep["leak_correct"] == "gate"
    assert np.array_equal(got, vltm.indirect(three, vol, epsilon=0.2, leak_correct="gate"))
    with pytest.raises(vltm.ArgumentError, match="leak_correct"):
        vltm.indirect(cap, vol, leak_correct="windows")
    with pytest.raises(vltm.ArgumentError, match="rows"):
        vltm.indirect(cap, vol, leak_correct="model", direct=vltm.direct(cap, vol),
                      rows=slice(0, 8))


def test_leak_correct_auto_equals_cli(tmp_path, capsys):
    """``leak_correct="auto"`` is the command line's ``--leak-correct auto``: on the two
    patches over 10 cm voxels the energy the windows leave lies apart from them, so auto is
    the windows; over 20 cm voxels it lies next to them and auto takes the model; the
    adjacency it chose by is in the report; a partial sum cannot take it."""
    cap = str(FIXTURE)
    focus = (-0.45, 0.0, 0.8)
    for vol, used in [("-0.6:0.6:13,-0.2:0.2:3,0.5:1.2:8", "gate"),
                      ("-0.6:0.6:7,-0.2:0.2:2,0.5:1.2:5", "model")]:
        want = cli_volume(tmp_path, "indirect", cap, "--volume", vol, "--leak-correct", "auto")
        got, rep = vltm.indirect(cap, vol, leak_correct="auto", report=True)
        close(want, got)
        assert rep["leak_correct"] == used, rep
        assert (rep["adjacency"] >= 0.4) == (used == "model"), rep
        assert np.array_equal(got, vltm.indirect(cap, vol, leak_correct=used))
        want = cli_volume(tmp_path, "column", cap, "--volume", vol, "--focus",
                          ",".join(map(str, focus)), "--leak-correct", "auto")
        got, rep = vltm.column(cap, vol, focus, leak_correct="auto", report=True)
        close(want, got)
        assert "adjacency" in rep and rep["leak_correct"] in ("gate", "model"), rep
    with pytest.raises(vltm.ArgumentError, match="rows"):
        vltm.indirect(cap, vol, leak_correct="auto", direct=vltm.direct(cap, vol),
                      rows=slice(0, 8))
    with pytest.raises(vltm.ArgumentError, match="'auto'"):
        vltm.column(cap, vol, focus, leak_correct="automatic")


def test_options_and_report(two_patches, tmp_path):
    want = cli_volume(tmp_path, "direct", str(two_patches), "--volume", GRID, "--wavelength",
                      "0.3", "--weights", "one", "--path", "band")
    got, rep = vltm.direct(two_patches, GRID, wavelength=0.3, weights="one", path="band",
                           report=True)
    close(want, got)
    assert rep["rows"] == 64 and rep["path"] == "band" and rep["wavelength"] == 0.3


def test_from_arrays_equals_file():
    z = np.load(FIXTURE)
    H = np.moveaxis(z["H"], -1, 0)  # y-tal: time first, (nt, Lx, Ly, Sx, Sy)
    c = vltm.Capture.from_arrays(H, z["laser_grid_xyz"], z["sensor_grid_xyz"],
                                 float(z["delta_t"]), float(z["t_start"]),
                                 laser_xyz=z["laser_xyz"], sensor_xyz=z["sensor_xyz"])
    info = c.info()
    assert (info["lasers"], info["spads"], info["nt"]) == (64, 64, 175)
    vol = "-0.5:0.5:8,-0.5:0.5:8,0.5:1.1:6"
    close(vltm.direct(FIXTURE, vol, path="band"), vltm.direct(c, vol, path="band"))
    # Points in, points out: an (..., 3) array gives the array's leading shape.
    pts = vltm.volume(vol).points[2:4, 3:6]
    got = vltm.direct(c, pts, path="band")
    assert got.shape == (2, 3, 6)
    # The time axis is cropped to each volume's reach, so a sub-volume runs on a shorter axis:
    # equal within the crop's bound (≲ 4e-6 of the signal, tests/proptest_fast.rs).
    close(vltm.direct(c, vol, path="band")[2:4, 3:6], got, rel=5e-6)


def test_amplitudes(two_patches, tmp_path):
    I, A = vltm.direct(two_patches, GRID, amplitudes=True)
    assert A.dtype == np.complex128 and A.shape == I.shape
    close(I, (np.abs(A) ** 2).astype(np.float32))
    # Two-bounce (factorised) columns, on the planar and the band path, and higher-order ones.
    f = ",".join(map(str, FOCUS))
    for path in ("auto", "band"):
        want = cli_volume(tmp_path, "column", str(two_patches), "--volume", GRID, "--focus", f,
                          "--path", path)
        I, A = vltm.column(two_patches, GRID, FOCUS, path=path, amplitudes=True)
        assert A.dtype == np.complex128 and A.shape == I.shape == want.shape
        close(want, I)
        close(I, (np.abs(A) ** 2).astype(np.float32), rel=1e-5)
    I, A = vltm.column(two_patches, GRID, FOCUS, gate="higher-order", shell=(0.2, 0.9),
                       amplitudes=True)
    close(I, (np.abs(A) ** 2).astype(np.float32))
    d = np.linalg.norm(vltm.volume(GRID).points - np.asarray(FOCUS, dtype=np.float32), axis=-1)
    assert np.all(A[(d < 0.2) | (d >= 0.9)] == 0)
    with pytest.raises(vltm.ArgumentError, match="amplitudes"):
        vltm.column(two_patches, GRID, FOCUS, gate="none", amplitudes=True)


def test_errors_are_exceptions_with_the_cli_messages(two_patches, tmp_path):
    with pytest.raises(ValueError) as e:
        vltm.direct(two_patches, "0:1:4,0:1")
    r = cli("direct", str(two_patches), "--volume", "0:1:4,0:1")
    assert r.returncode == 2 and as_python(r.stderr) == str(e.value)
    assert isinstance(e.value, vltm.ArgumentError) and isinstance(e.value, vltm.VltmError)
    with pytest.raises(OSError) as e:
        vltm.open(tmp_path / "missing.npz")
    assert isinstance(e.value, vltm.DataError) and "missing.npz" in str(e.value)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a capture")
    with pytest.raises(vltm.DataError):
        vltm.open(bad)
    with pytest.raises(vltm.ArgumentError, match="focus"):
        vltm.column(two_patches, GRID, (0.0, 0.0, -1.0))
    with pytest.raises(vltm.ArgumentError, match="rows"):
        vltm.direct(two_patches, GRID, rows=slice(10, 70))
    with pytest.raises(vltm.ArgumentError, match="path"):
        vltm.direct(two_patches, GRID, path="fast")
    with pytest.raises(vltm.ArgumentError, match="needs Γ"):
        vltm.indirect(two_patches, GRID, rows=slice(0, 8))
    with pytest.raises(vltm.ArgumentError, match="H"):
        vltm.Capture.from_arrays(np.zeros((10, 3, 3)), np.zeros((2, 3)), np.zeros((2, 3)), 0.01)


@pytest.mark.parametrize("kind", ["direct", "column", "higher-order", "indirect",
                                  "indirect-plain", "matrix"])
def test_split_merge_equals_one_pass(two_patches, kind):
    vol = "-0.6:0.6:10,-0.6:0.6:10,0.5:1.2:8"
    if kind == "direct":
        run = lambda **kw: vltm.direct(two_patches, vol, **kw)  # noqa: E731
    elif kind == "column":
        # Parts of a column are not leak-corrected (Γ needs the whole capture).
        run = lambda **kw: vltm.column(two_patches, vol, FOCUS, leak_correct=False, **kw)  # noqa: E731
    elif kind == "higher-order":
        run = lambda **kw: vltm.column(two_patches, vol, FOCUS, gate="higher-order",  # noqa: E731
                                       leak_correct=False, **kw)
    elif kind == "matrix":
        run = lambda **kw: vltm.matrix(two_patches, FOCUS_SET, vol, **kw)  # noqa: E731
    else:
        d = vltm.direct(two_patches, vol)
        leak = kind == "indirect"
        run = lambda **kw: vltm.indirect(two_patches, vol, direct=d, leak_correct=leak, **kw)  # noqa: E731
    one = run()
    if kind == "matrix":
        parts = [run(rows=slice(a, b)) for a, b in [(40, 64), (0, 13), (13, 40)]]
        parts = [pickle.loads(pickle.dumps(p)) for p in parts]
        m = vltm.merge(parts).finish()
        assert isinstance(m, vltm.MatrixResult) and m.amplitudes.shape == (8, 800)
        close(one.intensities, m.intensities)
        scale = np.abs(one.amplitudes).max()
        assert np.abs(one.amplitudes - m.amplitudes).max() <= 1e-6 * scale
        assert np.array_equal(one.from_xyz, m.from_xyz) and np.array_equal(one.to_xyz, m.to_xyz)
        return
    parts = [run(rows=slice(a, b)) for a, b in [(40, 64), (0, 13), (13, 40)]]
    parts = [pickle.loads(pickle.dumps(p)) for p in parts]
    assert [p.rows for p in parts] == [[range(40, 64)], [range(0, 13)], [range(13, 40)]]
    merged = vltm.merge(parts)
    assert merged.complete and merged.rows == [range(0, 64)]
    close(one, merged.finish())
    # One part with every row: the same numbers as one pass.
    close(one, run(rows=slice(None, None)).finish())


FOCUS_SET = "-0.3:0.3:2,-0.3:0.3:2,0.6:0.8:2"
TO_SET = "-0.6:0.6:10,-0.6:0.6:10,0.5:1.2:8"


def test_matrix_equals_cli(two_patches, tmp_path):
    h5py = __import__("h5py")
    out = tmp_path / "m.h5"
    r = cli("matrix", str(two_patches), "--from", FOCUS_SET, "--to", TO_SET, "--out", str(out))
    assert r.returncode == 0, r.stderr
    m = vltm.matrix(vltm.open(two_patches), FOCUS_SET, TO_SET)
    assert m.amplitudes.dtype == np.complex64 and m.intensities.dtype == np.float32
    assert m.amplitudes.shape == m.intensities.shape == (8, 800)
    with h5py.File(out, "r") as f:
        close(f["intensity"][:], m.intensities)
        scale = np.abs(m.amplitudes).max()
        assert np.abs(f["re"][:] - m.amplitudes.real).max() <= 1e-6 * scale
        assert np.abs(f["im"][:] - m.amplitudes.imag).max() <= 1e-6 * scale
        assert np.array_equal(f["from_xyz"][:], m.from_xyz)
        assert np.array_equal(f["to_xyz"][:], m.to_xyz)
    assert m.report["rows"] == 64 and m.report["passes"] == 1
    # Γ × Γ, as `vltm matrix --from gamma --to gamma --volume V --no-leak-correct` (the
    # command line leak-corrects over --volume by default; the Python matrix does not yet);
    # arrays in give the same.
    out = tmp_path / "g.h5"
    r = cli("matrix", str(two_patches), "--from", "gamma", "--to", "gamma", "--volume", TO_SET,
            "--epsilon", "0.3", "--no-leak-correct", "--out", str(out))
    assert r.returncode == 0, r.stderr
    g = vltm.matrix(two_patches, "gamma", "gamma", volume=TO_SET, epsilon=0.3)
    with h5py.File(out, "r") as f:
        close(f["intensity"][:], g.intensities)
        assert np.array_equal(f["from_xyz"][:], g.from_xyz)
    close(g.intensities, vltm.matrix(two_patches, g.from_xyz, vltm.Volume(g.to_xyz)).intensities)
    # A part written by the CLI merges with a part from Python.
    part = tmp_path / "b.part"
    r = cli("matrix", str(two_patches), "--from", FOCUS_SET, "--to", TO_SET, "--rows", "20:64",
            "--partial", str(part))
    assert r.returncode == 0, r.stderr
    a = vltm.matrix(two_patches, FOCUS_SET, TO_SET, rows=slice(0, 20))
    assert a.kind == "matrix"
    close(m.intensities, vltm.merge([a, vltm.Partial.read(part)]).finish().intensities)


def test_matrix_errors(two_patches, tmp_path):
    with pytest.raises(vltm.ArgumentError) as e:
        vltm.matrix(two_patches, "0:1:4,0:1", TO_SET)
    r = cli("matrix", str(two_patches), "--from", "0:1:4,0:1", "--to", TO_SET, "--out",
            str(tmp_path / "x.h5"))
    assert r.returncode == 2 and as_python(r.stderr) == str(e.value)
    with pytest.raises(vltm.ArgumentError) as e:
        vltm.matrix(two_patches, "0,0,-1", TO_SET)
    r = cli("matrix", str(two_patches), "--from", "0,0,-1", "--to", TO_SET, "--out",
            str(tmp_path / "x.h5"))
    assert r.returncode == 2 and as_python(r.stderr) == str(e.value)
    with pytest.raises(vltm.ArgumentError, match="needs the volume of Γ"):
        vltm.matrix(two_patches, "gamma", TO_SET)
    with pytest.raises(vltm.ArgumentError, match="needs Γ"):
        vltm.matrix(two_patches, "gamma", TO_SET, volume=TO_SET, rows=slice(0, 8))
    with pytest.raises(vltm.ArgumentError, match="rows"):
        vltm.matrix(two_patches, FOCUS_SET, TO_SET, rows=slice(0, 70))
    with pytest.raises(vltm.ArgumentError, match="different probes or parameters"):
        vltm.merge([vltm.matrix(two_patches, FOCUS_SET, TO_SET, rows=slice(0, 8)),
                    vltm.matrix(two_patches, FOCUS_SET, TO_SET, rows=slice(8, 64), wavelength=0.5)])


def test_merge_errors_and_cli_interop(two_patches, tmp_path):
    vol = "-0.6:0.6:6,-0.6:0.6:6,0.5:1.2:4"
    a = vltm.direct(two_patches, vol, rows=slice(0, 32))
    with pytest.raises(vltm.ArgumentError, match="overlap"):
        vltm.merge([a, vltm.direct(two_patches, vol, rows=slice(20, 64))])
    with pytest.raises(vltm.ArgumentError, match="missing"):
        vltm.merge([a]).finish()
    with pytest.raises(vltm.ArgumentError, match="different probes or parameters"):
        vltm.merge([a, vltm.direct(two_patches, vol, rows=slice(32, 64), wavelength=0.5)])
    with pytest.raises(vltm.ArgumentError, match="different captures"):
        vltm.merge([a, vltm.direct(FIXTURE, vol, rows=slice(32, 64))])
    with pytest.raises(vltm.DataError, match="crc32"):
        b = bytearray(a.to_bytes())
        b[-1] ^= 1
        vltm.Partial.from_bytes(bytes(b))
    # A part from the command line merges with a part from Python; `vltm merge` reads both.
    part = tmp_path / "b.part"
    r = cli("direct", str(two_patches), "--volume", vol, "--rows", "32:64", "--partial", str(part))
    assert r.returncode == 0, r.stderr
    both = vltm.merge([a, vltm.Partial.read(part)]).finish()
    close(vltm.direct(two_patches, vol), both)
    a.write(tmp_path / "a.part")
    r = cli("merge", str(tmp_path / "a.part"), str(part), "--out", str(tmp_path / "m.npy"))
    assert r.returncode == 0, r.stderr
    close(both, np.load(tmp_path / "m.npy"))
