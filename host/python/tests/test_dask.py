"""vltm.dask on a LocalCluster with 2 worker processes: the same volumes as one process."""

import numpy as np
import pytest

import vltm
import vltm.dask
from conftest import FOCUS, GRID

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


def test_dask_direct_and_column(two_patches, client):
    assert len(client.scheduler_info()["workers"]) == 2
    close(vltm.direct(two_patches, GRID), vltm.dask.direct(two_patches, GRID, client=client,
                                                           rows_per_task=10, split_every=2))
    close(vltm.column(two_patches, GRID, FOCUS),
          vltm.dask.column(str(two_patches), GRID, FOCUS, client=client))


def test_dask_indirect(two_patches, client):
    vol = "-0.6:0.6:10,-0.6:0.6:10,0.5:1.2:8"
    # Leak-corrected (the default): each task corrects its own rows.
    close(vltm.indirect(two_patches, vol, epsilon=0.2),
          vltm.dask.indirect(two_patches, vol, client=client, epsilon=0.2, rows_per_task=16))
    close(vltm.indirect(two_patches, vol, epsilon=0.2, leak_correct=False),
          vltm.dask.indirect(two_patches, vol, client=client, epsilon=0.2, rows_per_task=16,
                             leak_correct=False))


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
