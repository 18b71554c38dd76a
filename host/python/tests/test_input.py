"""Bad input: wrong types, shapes, dtypes, NaN, empty arrays and unknown keywords each raise
one exception naming the argument, before any work starts."""

import numpy as np
import pytest

import vltm
from conftest import FOCUS, SMALL

BAD = [
    # (call, the argument the message must name)
    (lambda c: vltm.direct(c, SMALL, wavelength="0.3"), "wavelength"),
    (lambda c: vltm.direct(c, SMALL, wavelength=float("nan")), "wavelength"),
    (lambda c: vltm.direct(c, SMALL, sigma=np.inf), "sigma"),
    (lambda c: vltm.direct(c, SMALL, band=True), "band"),
    (lambda c: vltm.direct(c, SMALL, weights=1), "weights"),
    (lambda c: vltm.direct(c, SMALL, weights="two"), "weights"),
    (lambda c: vltm.direct(c, SMALL, gate="two-bounce"), "gate"),
    (lambda c: vltm.direct(c, SMALL, path="fast"), "path"),
    (lambda c: vltm.direct(c, SMALL, compensate_laser="yes"), "compensate_laser"),
    (lambda c: vltm.direct(c, SMALL, swap_roles=1), "swap_roles"),
    (lambda c: vltm.direct(c, SMALL, rebin=1.5), "rebin"),
    (lambda c: vltm.direct(c, SMALL, t_min=float("nan")), "t_min"),
    (lambda c: vltm.direct(c, SMALL, background=[1]), "background"),
    (lambda c: vltm.direct(c, SMALL, rows=(0, 8)), "rows"),
    (lambda c: vltm.direct(c, SMALL, as_xarray="no"), "as_xarray"),
    (lambda c: vltm.direct(c, 42), "volume"),
    (lambda c: vltm.direct(c, np.zeros((0, 3))), "volume"),
    (lambda c: vltm.direct(c, np.zeros((4, 2))), "volume"),
    (lambda c: vltm.direct(c, np.array([[0, 0, np.nan]])), "volume"),
    (lambda c: vltm.direct(c, np.array([["a", "b", "c"]])), "volume"),
    (lambda c: vltm.direct(c, np.zeros((2, 3), complex)), "volume"),
    (lambda c: vltm.direct(c, "0:1:4,0:1"), "volume"),
    (lambda c: vltm.direct(42, SMALL), "capture"),
    (lambda c: vltm.column(c, SMALL, (0, 0)), "focus"),
    (lambda c: vltm.column(c, SMALL, "0,0,1"), "focus"),
    (lambda c: vltm.column(c, SMALL, (0, 0, np.nan)), "focus"),
    (lambda c: vltm.column(c, SMALL, (0, 0, -1)), "focus"),
    (lambda c: vltm.column(c, SMALL, FOCUS, shell=(0.5, 0.2)), "shell"),
    (lambda c: vltm.column(c, SMALL, FOCUS, shell=0.5), "shell"),
    (lambda c: vltm.column(c, SMALL, FOCUS, shells=(0.5, 0.2)), "shells"),
    (lambda c: vltm.column(c, SMALL, FOCUS, shell=(0, 1), shells=(0.2, 0.5)), "shells"),
    (lambda c: vltm.column(c, SMALL, FOCUS, mask_epsilon=1.5), "mask_epsilon"),
    (lambda c: vltm.column(c, SMALL, FOCUS, leak_correct=True, leak_epsilon=-1), "leak_epsilon"),
    (lambda c: vltm.column(c, SMALL, FOCUS, gate="gaussian"), "gate"),
    (lambda c: vltm.column(c, SMALL, FOCUS, shells=(0.2, 0.5), rows=slice(0, 8)), "rows"),
    (lambda c: vltm.indirect(c, SMALL, epsilon=1.0), "epsilon"),
    (lambda c: vltm.indirect(c, SMALL, epsilon="0.1"), "epsilon"),
    (lambda c: vltm.indirect(c, SMALL, min_separation=-1), "min_separation"),
    (lambda c: vltm.indirect(c, SMALL, direct=np.zeros(5)), "direct"),
    (lambda c: vltm.indirect(c, SMALL, direct=np.full(144, np.nan)), "direct"),
    (lambda c: vltm.indirect(c, SMALL, direct=np.zeros(0)), "direct"),
    (lambda c: vltm.indirect(c, SMALL, direct=np.zeros(144)), "epsilon"),  # Γ empty
    (lambda c: vltm.indirect(c, SMALL, rows=slice(0, 8)), "direct"),
    (lambda c: vltm.relight(c, SMALL, np.zeros((2, 5))), "pattern"),
    (lambda c: vltm.relight(c, SMALL, np.array([[0, 0, 1, np.nan]])), "pattern"),
    (lambda c: vltm.relight(c, SMALL, "0,0"), "pattern"),
    (lambda c: vltm.matrix(c, "0,0,-1", SMALL), "from_"),
    (lambda c: vltm.matrix(c, SMALL, np.zeros((0, 3))), "to"),
    (lambda c: vltm.matrix(c, "gamma", SMALL), "volume"),
    (lambda c: vltm.gamma_mask([1.0, np.nan]), "direct"),
    (lambda c: vltm.Capture.from_arrays(np.full((10, 2, 2), np.nan), np.zeros((2, 3)),
                                        np.zeros((2, 3)), 0.01), "H"),
    (lambda c: vltm.Capture.from_arrays(np.zeros((10, 2, 2), complex), np.zeros((2, 3)),
                                        np.zeros((2, 3)), 0.01), "H"),
    (lambda c: vltm.Capture.from_arrays(np.zeros((10, 2, 2)), np.zeros((2, 2)),
                                        np.zeros((2, 3)), 0.01), "laser_grid_xyz"),
    (lambda c: vltm.Capture.from_arrays(np.zeros((10, 2, 2)), np.zeros((2, 3)),
                                        np.zeros((2, 3)), -0.01), "delta_t"),
    (lambda c: vltm.Capture.from_arrays(np.zeros((10, 2, 2)), np.zeros((2, 3)),
                                        np.zeros((2, 3)), 0.01, scan_type="x"), "scan_type"),
    (lambda c: c.transient(rebin=0), "rebin"),
    (lambda c: vltm.open(c.path, grid_width=1.0), "grid_width"),
]


@pytest.mark.parametrize("call,name", BAD, ids=[f"{i}-{n}" for i, (_, n) in enumerate(BAD)])
def test_bad_input_names_the_argument(two_patches, call, name):
    c = vltm.open(two_patches)
    with pytest.raises(vltm.ArgumentError) as e:
        call(c)
    assert str(e.value).startswith(f"argument `{name}`"), str(e.value)
    assert "\n" not in str(e.value) and "--" not in str(e.value), str(e.value)


@pytest.mark.parametrize("fn,args", [(vltm.direct, (SMALL,)), (vltm.column, (SMALL, FOCUS)),
                                     (vltm.indirect, (SMALL,)), (vltm.row, (SMALL, FOCUS)),
                                     (vltm.relight, (SMALL, "0,0,1"))])
def test_unknown_keyword_names_itself(two_patches, fn, args):
    with pytest.raises(TypeError, match="wavelenght"):
        fn(two_patches, *args, wavelenght=0.3)


def test_gil_is_released_during_a_probe(two_patches):
    """A Python thread keeps running while a probe computes in another thread."""
    import threading
    import time

    ticks = []
    done = threading.Event()

    def tick():
        while not done.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.001)

    t = threading.Thread(target=tick)
    t.start()
    try:
        t0 = time.perf_counter()
        vltm.direct(two_patches, "-0.75:0.75:24,-0.75:0.75:24,0.4:1.35:24", gate="none")
        t1 = time.perf_counter()
    finally:
        done.set()
        t.join()
    during = [x for x in ticks if t0 < x < t1]
    assert t1 - t0 > 0.05 and len(during) >= 5, (t1 - t0, len(during))
