#!/usr/bin/env python3
"""vltm against y-tal's filtered backprojection (`tal.reconstruct.fbp`) on a real Stanford
confocal capture (MAT v5, `../shared/data/real/`): same preprocessing, volume, λ, σ, weights.

Optional: needs `pip install y-tal scipy` (never needed to build or test vltm). y-tal cannot
read the Stanford layout (`rect_data` + `width`), so this script builds its capture by hand
with the conventions vltm applies by default (4 ps bins, t = 0 at the wall, legs excluded,
grid over [-width, width]^2, the first index along x, the second down y from +width to
-width), after the authors' preprocessing (the first 600 bins dropped, 4 bins summed). The dropped bins are zero-padded back so that
y-tal's t_start is 0 (as benches/ytal_compare.py does); y-tal samples a summed bin at its
start, vltm at its centre (1.5 source bins later: 0.9 mm of depth). Then `vltm direct` with
`--t-min 600b --rebin 4 --weights one`, and both wall times, their ratio and the Pearson
correlation of the max-normalised intensities.

    python3 benches/real_compare.py ../shared/data/real/data_resolution_chart_40cm.mat \\
        --volume=-0.2:0.2:64,-0.2:0.2:64,0.35:0.45:11 [--wl 0.04] [--cpus 2] [--repeat 3]

Run it under `nice -n 10` on a shared machine (both programs then run at the same priority).
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

C = 299_792_458.0


def grid(spec):
    axes = []
    for a in spec.split(','):
        lo, hi, n = a.split(':')
        axes.append(np.linspace(float(lo), float(hi), int(n)))
    v = np.zeros((len(axes[0]), len(axes[1]), len(axes[2]), 3), np.float32)
    v[..., 0] = axes[0][:, None, None]
    v[..., 1] = axes[1][None, :, None]
    v[..., 2] = axes[2][None, None, :]
    return v


def run_ytal(path, wl, vol, cpus, trim=600, k=4):
    import scipy.io
    import tal
    from tal.enums import CameraSystem, GridFormat, HFormat, VolumeFormat
    from tal.io.capture_data import NLOSCaptureData
    tal.set_log_level(tal.LogLevel.WARNING)
    t = time.perf_counter()
    m = scipy.io.loadmat(path)
    h = np.asarray(m['rect_data'], np.float32)
    w = float(np.asarray(m['width']).item())
    n1, n2, nt = h.shape
    h[:, :, :trim] = 0  # the authors' z_trim, kept as zeros so that t_start = 0
    nt = nt // k * k
    h = h[:, :, :nt].reshape(n1, n2, nt // k, k).sum(-1)
    xs, ys = np.linspace(-w, w, n1), np.linspace(w, -w, n2)
    g = np.zeros((n1, n2, 3), np.float32)
    g[..., 0], g[..., 1] = xs[:, None], ys[None, :]
    d = NLOSCaptureData()
    d.H = np.ascontiguousarray(np.moveaxis(h, 2, 0))
    d.H_format = HFormat.T_Sx_Sy
    d.sensor_grid_xyz = g
    d.laser_grid_xyz = g.copy()
    d.sensor_grid_format = d.laser_grid_format = GridFormat.X_Y_3
    normals = np.zeros_like(g)
    normals[..., 2] = 1
    d.sensor_grid_normals, d.laser_grid_normals = normals, normals.copy()
    d.sensor_xyz = d.laser_xyz = np.array([-0.5, 0.0, 0.25], np.float32)
    d.delta_t = 4e-12 * C * k
    d.t_start = 0.0
    d.t_accounts_first_and_last_bounces = False
    d.scene_info = {}
    with tal.resources(cpu_processes=cpus):
        res = tal.reconstruct.fbp.solve(
            d, wl_mean=wl, wl_sigma=wl, border='zero', volume_xyz=vol,
            volume_format=VolumeFormat.X_Y_Z_3, camera_system=CameraSystem.DIRECT_LIGHT,
            compensate_invsq=False, progress=False)
    return np.abs(res) ** 2, time.perf_counter() - t


def run_vltm(exe, path, wl, spec, threads, repeat):
    """Median wall time of `repeat` runs of the whole command (reading the `.mat` included),
    the evaluation path it reports and its peak resident memory (KB, over the runs)."""
    import resource
    out = os.path.join(tempfile.mkdtemp(), 'direct.npy')
    cmd = [exe, '--threads', str(threads), 'direct', path, f'--volume={spec}', '--t-min', '600b',
           '--rebin', '4', '--wavelength', str(wl), '--sigma', str(wl), '--weights', 'one',
           '--out', out]
    times, text = [], ''
    for _ in range(repeat):
        t = time.perf_counter()
        r = subprocess.run(cmd, check=True, capture_output=True, text=True)
        times.append(time.perf_counter() - t)
        text = r.stdout + r.stderr
    m = re.search(r', path (\w+)\)', text)
    path_used = m.group(1) if m else '?'
    rss = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return np.load(out).astype(np.float64), float(np.median(times)), path_used, rss


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('capture')
    ap.add_argument('--wl', type=float, default=0.04, help='virtual wavelength = gate sigma [m]')
    ap.add_argument('--volume', default='-0.2:0.2:64,-0.2:0.2:64,0.35:0.45:11')
    ap.add_argument('--cpus', type=int, default=2)
    ap.add_argument('--repeat', type=int, default=3, help='vltm runs (the median is reported)')
    ap.add_argument('--vltm', default=os.path.join(os.path.dirname(__file__), '..', 'target', 'release', 'vltm'))
    a = ap.parse_args()
    if not os.path.exists(a.vltm):
        sys.exit(f'{a.vltm} not found: cargo build --release -p vltm')
    vol = grid(a.volume)
    load0 = os.getloadavg()
    mine, t_v, path_used, rss = run_vltm(a.vltm, a.capture, a.wl, a.volume, a.cpus, a.repeat)
    try:
        theirs, t_y = run_ytal(a.capture, a.wl, vol, a.cpus)
    except ImportError as e:
        print(f'vltm: {t_v:.2f} s (y-tal not available: {e})')
        return
    load1 = os.getloadavg()
    theirs = theirs.reshape(mine.shape)
    x, y = mine.ravel() / mine.max(), theirs.ravel() / theirs.max()
    r = np.corrcoef(x, y)[0, 1]
    pm, pt = np.unravel_index(np.argmax(x), mine.shape), np.unravel_index(np.argmax(y), mine.shape)
    print(f'{os.path.basename(a.capture)}: volume {a.volume} {vol.shape[:3]}, {a.cpus} cpus, '
          f'wl = sigma = {a.wl} m, nice {os.nice(0)}, load average {load0[0]:.1f} before, '
          f'{load1[0]:.1f} after')
    print(f'  y-tal fbp DIRECT_LIGHT  {t_y:8.2f} s')
    print(f'  vltm direct ({path_used})  {t_v:8.2f} s   ({t_y / t_v:.1f}x; median of {a.repeat}, '
          f'max RSS {rss / 1024:.0f} MB)')
    print(f'  Pearson of normalised intensities {r:.5f}; peak voxel vltm {pm}, y-tal {pt}')

if __name__ == '__main__':
    main()
