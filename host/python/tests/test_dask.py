"""vltm.dask on a LocalCluster with 2 worker processes: the same volumes as one process, and
every option of the in-process functions passed through unchanged."""

import inspect

import numpy as np
import pytest

import vltm
from conftest import FIXTURE, FOCUS, GRID, SMALL

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def client():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as c:
        yield c


def close(a, b, rel=1e-6):
    assert a.shape == b.shape and a.max() > 0
    assert np.abs(a.astype(np.float64) - b).max() <= rel * a.max()


def test_dask_is_an_attribute_after_import_vltm():
    import importlib
    import sys

    sys.modules.pop("vltm.dask", None)
    m = importlib.reload(vltm)
    assert "vltm.dask" not in sys.modules  # lazy: Dask stays optional
    assert m.dask.direct is sys.modules["vltm.dask"].direct


def test_dask_direct_and_column(two_patches, client):
    assert len(client.scheduler_info()["workers"]) == 2
    close(vltm.direct(two_patches, GRID), vltm.dask.direct(two_patches, GRID, client=client,
                                                           rows_per_task=10, split_every=2))
    close(vltm.column(two_patches, GRID, FOCUS),
          vltm.dask.column(str(two_patches), GRID, FOCUS, client=client))
    # A Capture opened from a file works as well (its path goes to the workers).
    np.testing.assert_array_equal(vltm.direct(two_patches, GRID),
                                  vltm.dask.direct(vltm.open(two_patches), GRID, client=client))


def test_dask_direct_on_a_paired_scan(client):
    """A paired scan (one laser and one SPAD spot per row) split over the workers by rows."""
    from conftest import REPO

    paired = REPO / "fixtures" / "tal" / "paired.hdf5"
    vol = "-0.4:0.4:9,-0.4:0.4:9,0.4:1.0:7"
    close(vltm.direct(paired, vol, wavelength=0.15),
          vltm.dask.direct(paired, vol, client=client, wavelength=0.15, rows_per_task=40))


def test_dask_indirect(two_patches, client):
    vol = "-0.6:0.6:10,-0.6:0.6:10,0.5:1.2:8"
    # Leak-corrected (the default): each task corrects its own rows.
    close(vltm.indirect(two_patches, vol, epsilon=0.2),
          vltm.dask.indirect(two_patches, vol, client=client, epsilon=0.2, rows_per_task=16))
    close(vltm.indirect(two_patches, vol, epsilon=0.2, leak_correct=False),
          vltm.dask.indirect(two_patches, vol, client=client, epsilon=0.2, rows_per_task=16,
                             leak_correct=False))
    # The surface model is fitted to the whole capture: one task, the in-process result.
    npz = str(FIXTURE)
    close(vltm.indirect(npz, vol, epsilon=0.2, leak_correct="model"),
          vltm.dask.indirect(npz, vol, client=client, epsilon=0.2, rows_per_task=16,
                             leak_correct="model"))
    # auto decides on the whole capture: one task too.
    close(vltm.indirect(npz, vol, epsilon=0.2, leak_correct="auto"),
          vltm.dask.indirect(npz, vol, client=client, epsilon=0.2, rows_per_task=16,
                             leak_correct="auto"))


def test_dask_matrix(two_patches, client):
    frm, to = "-0.3:0.3:2,-0.3:0.3:2,0.6:0.8:2", "-0.6:0.6:10,-0.6:0.6:10,0.5:1.2:8"
    one = vltm.matrix(two_patches, frm, to)
    got = vltm.dask.matrix(two_patches, frm, to, client=client, rows_per_task=16)
    assert isinstance(got, vltm.MatrixResult) and got.amplitudes.shape == (8, 800)
    close(one.intensities, got.intensities)
    assert np.array_equal(one.to_xyz, got.to_xyz)
    # Γ × Γ: round 1 the direct light over the cluster, round 2 the matrix.
    g1 = vltm.matrix(two_patches, "gamma", "gamma", volume=to, epsilon=0.3)
    g2 = vltm.dask.matrix(two_patches, "gamma", "gamma", volume=to, epsilon=0.3, client=client)
    assert np.array_equal(g1.from_xyz, g2.from_xyz)
    close(g1.intensities, g2.intensities)


def test_row_ranges():
    assert vltm.dask.row_ranges(10, 4) == [(0, 4), (4, 8), (8, 10)]
    assert vltm.dask.row_ranges(3, 8) == [(0, 3)]


# One non-default value per option of every in-process function; vltm.dask must take each
# under the same name and give the same result.
D = np.ones(144, np.float32)  # stands for a direct-light volume over SMALL
OPTIONS = {
    "direct": ((SMALL,), {
        "gate": "none", "wavelength": 0.3, "sigma": 0.2, "weights": "one", "band": 4.0,
        "compensate_laser": True, "crop": False, "path": "band", "swap_roles": True, "t_min": 1.3,
        "t_max": "350b", "rebin": 2, "background": 1e-6, "amplitudes": True,
        "report": True, "as_xarray": True}),
    "column": ((SMALL, FOCUS), {
        "gate": "higher-order", "shell": (0.2, 0.9), "shells": (0.3, 0.6),
        "mask_epsilon": 0.3, "leak_correct": True, "leak_epsilon": 0.2, "wavelength": 0.3,
        "sigma": 0.2, "weights": "one", "band": 4.0, "compensate_laser": True, "crop": False,
        "path": "band", "swap_roles": True, "t_min": 1.3, "t_max": "350b", "rebin": 2,
        "background": 1e-6, "amplitudes": True, "report": True, "as_xarray": True}),
    "indirect": ((SMALL,), {
        "epsilon": 0.3, "min_separation": 0.2, "shell": (0.2, 0.9), "shells": (0.3, 0.6),
        "gate": "higher-order", "direct": None, "leak_correct": False, "wavelength": 0.3,
        "sigma": 0.2, "weights": "one", "band": 4.0, "compensate_laser": True, "crop": False,
        "path": "band", "swap_roles": True, "t_min": 1.3, "t_max": "350b", "rebin": 2,
        "background": 1e-6, "report": True, "as_xarray": True}),
    "relight": ((SMALL, "-0.25,0.15,0.7,1;0.25,0,0.9,0.5"), {
        "leak_correct": False, "leak_epsilon": 0.2, "wavelength": 0.3, "sigma": 0.2, "weights": "one", "band": 4.0,
        "compensate_laser": True, "crop": False, "path": "band", "swap_roles": True, "t_min": 1.3,
        "t_max": "350b", "rebin": 2, "background": 1e-6, "amplitudes": True,
        "report": True, "as_xarray": True}),
    "row": ((SMALL, (0.25, 0.0, 0.9)), {
        "leak_correct": False, "leak_epsilon": 0.2, "wavelength": 0.3, "sigma": 0.2, "weights": "one", "band": 4.0,
        "compensate_laser": True, "crop": False, "path": "band", "swap_roles": True, "t_min": 1.3, "t_max": "350b",
        "rebin": 2, "background": 1e-6, "report": True, "as_xarray": True}),
    "matrix": (("-0.3:0.3:2,-0.3:0.3:2,0.6:0.8:2", "gamma"), {
        "volume": SMALL, "epsilon": 0.3, "direct": None, "wavelength": 0.3, "sigma": 0.2,
        "weights": "one", "band": 4.0, "compensate_laser": True, "crop": False}),
}
CASES = [(fn, opt) for fn, (_, kw) in OPTIONS.items() for opt in kw]


def test_every_option_is_in_the_table():
    for fn, (_, kw) in OPTIONS.items():
        sig = inspect.signature(getattr(vltm, fn))
        names = {p.name for p in sig.parameters.values() if p.kind == p.KEYWORD_ONLY}
        assert names - {"rows"} == set(kw), fn


def _same(a, b):
    if isinstance(a, tuple):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            _same(x, y)
    elif isinstance(a, dict):
        for k in ("wavelength", "sigma", "rows", "passes"):
            assert a.get(k) == b.get(k), k
        # The removed energy's f64 sums add up in another order over the tasks.
        if a.get("explained") is None:
            assert b.get("explained") is None
        else:
            assert a["explained"] == pytest.approx(b.get("explained"), rel=1e-9)
    elif hasattr(a, "dims"):  # xarray
        assert a.dims == b.dims
        for k in ("wavelength", "sigma", "gate", "probe"):
            assert a.attrs.get(k) == b.attrs.get(k), k
        for c in a.coords:
            np.testing.assert_array_equal(a[c].values, b[c].values)
        np.testing.assert_array_equal(a.values, b.values)
    elif np.iscomplexobj(a):
        # Complex128 amplitudes: f64 accumulators added in another order over the tasks.
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * np.abs(a).max())
    else:
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("fn,opt", CASES, ids=[f"{f}-{o}" for f, o in CASES])
def test_dask_passes_every_option(two_patches, client, fn, opt):
    args, table = OPTIONS[fn]
    value = table[opt]
    kw = {opt: value}
    if opt == "direct":  # Γ from a given direct-light volume
        kw["direct"] = vltm.direct(two_patches, SMALL)
    try:
        want = getattr(vltm, fn)(two_patches, *args, **kw)
    except vltm.ArgumentError as e:  # refused in process (row's swap_roles): the same error
        with pytest.raises(vltm.ArgumentError) as d:
            getattr(vltm.dask, fn)(two_patches, *args, client=client, **kw)
        assert str(d.value) == str(e)
        return
    got = getattr(vltm.dask, fn)(two_patches, *args, client=client, **kw)
    if fn == "matrix":
        np.testing.assert_array_equal(want.intensities, got.intensities)
        return
    _same(want, got)


def test_dask_refuses_unknown_options_on_the_client(two_patches, client):
    with pytest.raises(vltm.ArgumentError, match="argument `wavelenght`"):
        vltm.dask.direct(two_patches, SMALL, client=client, wavelenght=0.3)
    with pytest.raises(vltm.ArgumentError, match="argument `rows`"):
        vltm.dask.direct(two_patches, SMALL, client=client, rows=slice(0, 8))
    with pytest.raises(vltm.ArgumentError, match="argument `capture`"):
        vltm.dask.direct(vltm.Capture.from_arrays(np.ones((8, 2, 2)), np.ones((2, 3)),
                                                  np.ones((2, 3)), 0.01), SMALL, client=client)
