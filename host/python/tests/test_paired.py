"""Paired scans (one laser spot and one SPAD spot per histogram, apart): `vltm.open` on y-tal's
paired `T_Si` file and `vltm.direct` on it against `vltm direct`, bit for bit; the same capture
built with `Capture.from_arrays` (the `.npz` reader's per-histogram names) against the file;
the scan kind `info()` reports; the one-line refusals (column, bad arrays) as the command line
words them."""

import h5py
import numpy as np
import pytest

import vltm
from conftest import REPO, as_python, cli

PAIRED = REPO / "fixtures" / "tal" / "paired.hdf5"
VOL = "-0.4:0.4:9,-0.4:0.4:9,0.4:1.0:7"
OPTS = dict(wavelength=0.15, sigma=0.15, weights="one")
FLAGS = ["--wavelength", "0.15", "--sigma", "0.15", "--weights", "one"]


def fields():
    """The file's fields as a numpy user holds them (time last, points per histogram)."""
    with h5py.File(PAIRED, "r") as f:
        return dict(
            H=np.ascontiguousarray(f["H"][()].T),
            laser_xyz=f["laser_grid_xyz"][()],
            sensor_xyz=f["sensor_grid_xyz"][()],
            delta_t=float(f["delta_t"][()]),
            t_start=float(f["t_start"][()]),
            laser_origin=f["laser_xyz"][()].tolist(),
            sensor_origin=f["sensor_xyz"][()].tolist(),
            laser_normals=f["laser_grid_normals"][()],
            sensor_normals=f["sensor_grid_normals"][()],
        )


def run_cli(tmp, *args):
    out = tmp / "cli.npy"
    r = cli(*args, "--out", str(out))
    assert r.returncode == 0, r.stderr
    return np.load(out)


@pytest.mark.parametrize("path", ["auto", "band", "lookup"])
def test_direct_matches_the_command_line(tmp_path, path):
    want = run_cli(tmp_path, "direct", str(PAIRED), "--volume", VOL, *FLAGS, "--path", path)
    got = vltm.direct(vltm.open(PAIRED), VOL, path=path, **OPTS)
    assert got.dtype == want.dtype == np.float32 and got.shape == want.shape
    assert np.abs(want).max() > 0
    np.testing.assert_array_equal(got, want)


def test_info_names_the_scan():
    i = vltm.open(PAIRED).info()
    assert (i["scan"], i["confocal"], i["paired"], i["spads_per_row"]) == ("paired", False, True, 1)
    assert (i["lasers"], i["spads"]) == (144, 144)
    r = cli("info", str(PAIRED))
    assert r.returncode == 0 and "scan         paired (" in r.stdout
    two = vltm.open(REPO / "fixtures" / "two_patches.npz").info()
    assert (two["scan"], two["confocal"], two["paired"]) == ("non-confocal", False, False)
    f = fields()
    conf = vltm.Capture.from_arrays(f["H"], laser_xyz=f["laser_xyz"], sensor_xyz=f["laser_xyz"],
                                    delta_t=f["delta_t"]).info()
    assert (conf["scan"], conf["confocal"], conf["paired"]) == ("confocal", True, True)


def test_from_arrays_round_trip_equals_the_file(tmp_path):
    f = fields()
    c = vltm.Capture.from_arrays(**f)
    fi, ai = vltm.open(PAIRED).info(), c.info()
    for k in ("path", "file_bytes"):
        fi.pop(k, None)
        ai.pop(k, None)
    assert ai == fi
    np.testing.assert_array_equal(c.laser_points, vltm.open(PAIRED).laser_points)
    np.testing.assert_array_equal(c.spad_points, vltm.open(PAIRED).spad_points)
    want = run_cli(tmp_path, "direct", str(PAIRED), "--volume", VOL, *FLAGS)
    np.testing.assert_array_equal(vltm.direct(c, VOL, **OPTS), want)
    # The file's normals came through: the cos-weighted volumes agree too.
    cos = run_cli(tmp_path, "direct", str(PAIRED), "--volume", VOL, "--wavelength", "0.15",
                  "--sigma", "0.15", "--weights", "cos")
    np.testing.assert_array_equal(vltm.direct(c, VOL, wavelength=0.15, sigma=0.15,
                                              weights="cos"), cos)
    # Saved as vltm's .npz and read back by the command line: the same volume again.
    npz = tmp_path / "paired.npz"
    c.save(npz)
    np.testing.assert_array_equal(run_cli(tmp_path, "direct", str(npz), "--volume", VOL, *FLAGS),
                                  want)
    # Teeth: the SPAD spots moved by 1 cm give another volume.
    moved = dict(f, sensor_xyz=f["sensor_xyz"] + np.float32(0.01))
    assert not np.array_equal(vltm.direct(vltm.Capture.from_arrays(**moved), VOL, **OPTS), want)


def test_column_refuses_a_paired_scan_as_the_command_line():
    with pytest.raises(vltm.ArgumentError) as e:
        vltm.column(PAIRED, VOL, (0.0, 0.25, 0.5))
    r = cli("column", str(PAIRED), "--focus", "0,0.25,0.5", "--volume", VOL, "--out", "x.npy")
    assert r.returncode == 2 and as_python(r.stderr) == str(e.value)
    assert "\n" not in str(e.value) and "argument `column`" in str(e.value)


def test_bad_paired_arrays_are_one_line_errors_naming_the_argument():
    f = fields()

    def fails(name, match, **edit):
        with pytest.raises(vltm.ArgumentError) as e:
            vltm.Capture.from_arrays(**dict(f, **edit))
        msg = str(e.value)
        assert msg.startswith(f"argument `{name}`: ") and "\n" not in msg, msg
        assert match in msg, msg

    fails("sensor_xyz", "one SPAD point per laser point (laser_xyz has 144), found 143 points",
          sensor_xyz=f["sensor_xyz"][:143])
    nan = f["laser_xyz"].copy()
    nan[7, 1] = np.nan
    fails("laser_xyz", "expected finite coordinates, found [", laser_xyz=nan)
    fails("laser_xyz", "at index 7", laser_xyz=nan)
    inf = f["sensor_xyz"].copy()
    inf[3, 0] = np.inf
    fails("sensor_xyz", "at index 3", sensor_xyz=inf)
    fails("sensor_xyz", "shape (K, 3)", sensor_xyz=f["sensor_xyz"][:, :2])
    fails("H", "expected shape (144, Nt): one histogram per pair", H=f["H"].T)
    h = f["H"].copy()
    h[0, 0] = np.nan
    fails("H", "NaN or infinite", H=h)
    fails("delta_t", "> 0", delta_t=0.0)
    fails("t_accounts_first_and_last_bounces", "laser_origin and sensor_origin",
          t_accounts_first_and_last_bounces=True, laser_origin=None)
    fails("laser_origin", "finite", laser_origin=(0.0, float("nan"), 0.0))
    g = {k: f[k] for k in ("H", "laser_xyz", "sensor_xyz")}
    with pytest.raises(vltm.ArgumentError, match="argument `delta_t`: missing"):
        vltm.Capture.from_arrays(**g)


def test_ytal_fields_with_scan_type_paired_equal_the_file(tmp_path):
    """y-tal's own fields (time first, grids, device positions) with `scan_type="paired"`."""
    with h5py.File(PAIRED, "r") as f:
        c = vltm.Capture.from_arrays(
            f["H"][()], f["laser_grid_xyz"][()], f["sensor_grid_xyz"][()],
            float(f["delta_t"][()]), float(f["t_start"][()]), laser_xyz=f["laser_xyz"][()],
            sensor_xyz=f["sensor_xyz"][()], scan_type="paired")
        lg, sg = f["laser_grid_xyz"][()], f["sensor_grid_xyz"][()]
        h = f["H"][()]
    assert c.info()["scan"] == "paired"
    want = run_cli(tmp_path, "direct", str(PAIRED), "--volume", VOL, *FLAGS)
    np.testing.assert_array_equal(vltm.direct(c, VOL, **OPTS), want)
    with pytest.raises(vltm.ArgumentError, match="argument `sensor_grid_xyz`: expected one SPAD"):
        vltm.Capture.from_arrays(h[:, :143], lg, sg[:143], 0.01, scan_type="paired")


def test_normals_pass_through_from_arrays(tmp_path):
    """`laser_normals`/`sensor_normals` reach the library: `info()` reports them; with
    `weights="cos"` the image equals `vltm direct --weights cos` on the same arrays written as
    a per-histogram `.npz` with the normals; tilted normals change the cos-weighted image (so
    they are not dropped) and `compensate_laser`; bad normals are one-line errors naming the
    keyword."""
    f = fields()
    k = len(f["laser_xyz"])
    tilt = np.zeros((k, 3))
    tilt[:, 0] = np.linspace(-0.4, 0.4, k)
    tilt[:, 2] = 1.0
    kw = dict(laser_xyz=f["laser_xyz"], sensor_xyz=f["sensor_xyz"], delta_t=f["delta_t"],
              t_start=f["t_start"], laser_origin=f["laser_origin"],
              sensor_origin=f["sensor_origin"])
    plain = vltm.Capture.from_arrays(f["H"], **kw)
    tilted = vltm.Capture.from_arrays(f["H"], laser_normals=tilt, sensor_normals=tilt, **kw)
    assert plain.info()["normals"] == "+z"
    assert tilted.info()["normals"] == "per point"
    assert tilted.info()["relay"] != "planar"
    opts = dict(wavelength=0.15, sigma=0.15, weights="cos")
    a = vltm.direct(plain, VOL, **opts)
    b = vltm.direct(tilted, VOL, **opts)
    assert np.abs(a - b).max() > 1e-3 * np.abs(a).max()
    npz = tmp_path / "tilted.npz"
    np.savez(npz, H=f["H"].astype(np.float32), laser_xyz=f["laser_xyz"],
             sensor_xyz=f["sensor_xyz"], delta_t=f["delta_t"], t_start=f["t_start"],
             laser_origin=np.array(f["laser_origin"]), sensor_origin=np.array(f["sensor_origin"]),
             laser_normals=tilt, sensor_normals=tilt)
    want = run_cli(tmp_path, "direct", str(npz), "--volume", VOL, "--wavelength", "0.15",
                   "--sigma", "0.15", "--weights", "cos")
    np.testing.assert_allclose(b, want, rtol=1e-5, atol=1e-6 * np.abs(want).max())
    c1 = vltm.direct(plain, VOL, wavelength=0.15, sigma=0.15, compensate_laser=True)
    c2 = vltm.direct(tilted, VOL, wavelength=0.15, sigma=0.15, compensate_laser=True)
    assert np.abs(c1 - c2).max() > 1e-3 * np.abs(c1).max()
    bad = tilt.copy()
    bad[3] = 0.0
    for name, v in (("laser_normals", bad), ("sensor_normals", tilt[:5])):
        with pytest.raises(vltm.ArgumentError) as e:
            vltm.Capture.from_arrays(f["H"], **{name: v}, **kw)
        msg = str(e.value)
        assert name in msg and "\n" not in msg, msg
