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
    close(vltm.indirect(two_patches, vol, epsilon=0.2),
          vltm.dask.indirect(two_patches, vol, client=client, epsilon=0.2, rows_per_task=16))


def test_row_ranges():
    assert vltm.dask.row_ranges(10, 4) == [(0, 4), (4, 8), (8, 10)]
    assert vltm.dask.row_ranges(3, 8) == [(0, 3)]
