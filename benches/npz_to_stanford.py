#!/usr/bin/env python3
"""Write a confocal vltm capture (`.npz` from `vltm simulate`) as a Stanford confocal `.mat`
(`rect_data` uint16 (N, N, T) + `width`), so that benches/real_compare.py can run both programs
on a rendering whose scene is known. The counts are scaled to a peak of `--peak` and rounded
(16-bit, as the published captures). The grid must be N x N points from -width to +width on
both axes, first index along x, second along y, z = 0; the second axis is flipped on writing,
since Stanford's second index runs down y (from +width to -width, as vltm reads it,
docs/real-data.md). The capture must start at t = 0
with 4 ps bins (`"dt": 0.00119916983` in the scene), else the `.mat` would mean another capture:
both are checked.

Optional: needs numpy and scipy (never needed to build or test vltm).

    sed 's/"dt": 0.0012,/"dt": 0.00119916983,/' benches/scenes/confocal64.json > conf64.json
    vltm simulate conf64.json --out conf64.npz
    python3 benches/npz_to_stanford.py conf64.npz conf64.mat
    python3 benches/real_compare.py conf64.mat --volume=-0.4:0.4:64,-0.4:0.4:64,0.40:0.55:11 --reference
"""
import argparse
import sys

import numpy as np
import scipy.io

DT = 4e-12 * 299_792_458.0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('npz')
    ap.add_argument('mat')
    ap.add_argument('--peak', type=float, default=60000.0, help='counts of the largest bin')
    a = ap.parse_args()
    z = np.load(a.npz)
    if not int(z['confocal']):
        sys.exit(f'{a.npz}: not a confocal capture')
    h = np.asarray(z['H'], np.float64)
    g = np.asarray(z['laser_grid_xyz'], np.float64)
    n1, n2 = g.shape[:2]
    w = round(float(g[-1, -1, 0]), 6)  # the f32 grid, to the micrometre
    want = np.zeros_like(g)
    want[..., 0] = np.linspace(-w, w, n1)[:, None]
    want[..., 1] = np.linspace(-w, w, n2)[None, :]
    if h.shape[:2] != (n1, n2) or n1 != n2 or np.abs(g - want).max() > 1e-6:
        sys.exit(f'{a.npz}: not an N x N grid over [-width, width]^2 with x along the first index')
    if abs(float(z['delta_t']) - DT) > 1e-9 or float(z['t_start']) != 0.0:
        sys.exit(f'{a.npz}: needs 4 ps bins ({DT:.11f} m) from t = 0')
    if h.max() <= 0:
        sys.exit(f'{a.npz}: empty capture')
    q = np.round(h[:, ::-1, :] / h.max() * a.peak).astype(np.uint16)
    scipy.io.savemat(a.mat, {'rect_data': q, 'width': np.array([[w]])}, do_compression=True)
    print(f'wrote {a.mat}: {n1}x{n2}x{h.shape[2]} uint16, width {w} m, peak {a.peak:.0f} counts')


if __name__ == '__main__':
    main()
