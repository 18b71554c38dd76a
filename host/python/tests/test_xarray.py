"""Labelled results: xarray.DataArray with x, y, z in metres and the parameters as
attributes; the netCDF round trip."""

import numpy as np
import pytest

import vltm
from conftest import FOCUS, GRID, SMALL

xr = pytest.importorskip("xarray")


def test_direct_as_xarray_round_trips_through_netcdf(two_patches, tmp_path):
    plain, rep = vltm.direct(two_patches, GRID, report=True)
    a = vltm.direct(two_patches, GRID, as_xarray=True)
    assert isinstance(a, xr.DataArray) and a.dims == ("x", "y", "z")
    np.testing.assert_array_equal(a.values, plain)
    pts = vltm.volume(GRID).points
    np.testing.assert_array_equal(a.x.values, pts[:, 0, 0, 0])
    np.testing.assert_array_equal(a.z.values, pts[0, 0, :, 2])
    assert a.x.attrs["units"] == "m" and a.x.values[0] == pytest.approx(-0.75)
    assert a.attrs["wavelength"] == rep["wavelength"] and a.attrs["sigma"] == rep["sigma"]
    assert a.attrs["gate"] == "gaussian" and a.attrs["path"] == rep["path"]
    # The voxel at the direct light's peak, by coordinates.
    i = np.unravel_index(np.argmax(plain), plain.shape)
    assert float(a.sel(x=a.x[i[0]], y=a.y[i[1]], z=a.z[i[2]])) == plain[i]
    f = tmp_path / "direct.nc"
    a.to_netcdf(f)
    b = xr.load_dataarray(f)
    xr.testing.assert_identical(a, b)


def test_column_indirect_shells_and_points(two_patches, tmp_path):
    c = vltm.column(two_patches, SMALL, FOCUS, shells=(0.3, 0.6), as_xarray=True)
    assert c.dims == ("shell", "x", "y", "z")
    assert list(c.shell.values) == ["near", "middle", "far"]
    np.testing.assert_array_equal(c.attrs["focus"], FOCUS)
    i = vltm.indirect(two_patches, SMALL, epsilon=0.2, as_xarray=True)
    assert i.attrs["epsilon"] == pytest.approx(0.2) and i.attrs["leak_correct"] == 1
    for n, a in (("c", c), ("i", i)):
        a.to_netcdf(tmp_path / f"{n}.nc")
        xr.testing.assert_identical(a, xr.load_dataarray(tmp_path / f"{n}.nc"))
    # A point list: dimension `voxel`, coordinates x, y, z along it.
    pts = vltm.volume(SMALL).points.reshape(-1, 3)[:7]
    p = vltm.direct(two_patches, pts, as_xarray=True)
    assert p.dims == ("voxel",)
    np.testing.assert_array_equal(p.y.values, pts[:, 1])


def test_partial_finish_matrix_and_transient(two_patches, tmp_path):
    parts = [vltm.direct(two_patches, SMALL, rows=slice(a, b)) for a, b in [(0, 30), (30, 64)]]
    a = vltm.merge(parts).finish(as_xarray=True)
    xr.testing.assert_equal(a, vltm.direct(two_patches, SMALL, as_xarray=True))
    # A state read from a file (as `--partial` writes it) knows its voxels too.
    vltm.merge(parts).write(tmp_path / "d.part")
    b = vltm.Partial.read(tmp_path / "d.part").finish(as_xarray=True)
    assert b.dims == ("x", "y", "z")
    xr.testing.assert_equal(a, b)  # values and coordinates (attributes aside)
    m = vltm.matrix(two_patches, "-0.3:0.3:2,-0.3:0.3:2,0.6:0.8:2", SMALL)
    x = m.to_xarray()
    assert x.dims == ("from", "to") and x.shape == (8, 144)
    np.testing.assert_array_equal(x.to_x.values, m.to_xyz[:, 0])
    x.to_netcdf(tmp_path / "m.nc")
    xr.testing.assert_identical(x, xr.load_dataarray(tmp_path / "m.nc"))
    t = vltm.open(two_patches).transient(rebin=2, as_xarray=True)
    assert t.dims == ("t",) and t.t.attrs["units"] == "m"
    t.to_netcdf(tmp_path / "t.nc")
    xr.testing.assert_identical(t, xr.load_dataarray(tmp_path / "t.nc"))
