#!/usr/bin/env python3
"""Side-by-side timing of vltm and the peer library y-tal on the same capture and volume.

Optional: needs `pip install y-tal` (never needed to build or test vltm). Runs y-tal 0.20's
`tal.reconstruct.pf_dev.solve(DIRECT_LIGHT)` the way `fixtures/ytal/tools/run_reference.py`
made the committed references (laser falloff compensated, t_start moved to 0 by zero
padding, wl_sigma = wl_mean, brute-force path), then `vltm direct` with the matching options
(`--weights one --sigma WL --compensate-laser --band 6`), and prints both wall times, the ratio
and the Pearson correlation of the two intensity volumes.

    python3 benches/ytal_compare.py fixtures/ytal/two_patches/two_patches.hdf5 --wl 0.4 \\
        [--volume -0.75:0.75:16,-0.75:0.75:16,0.4:1.35:20] [--cpus 2] [--vltm target/release/vltm]
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np


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


def run_ytal(path, wl, vol, cpus):
    import tal
    from tal.enums import CameraSystem, VolumeFormat
    tal.set_log_level(tal.LogLevel.WARNING)
    t = time.perf_counter()
    data = tal.io.read_capture(path)
    tal.reconstruct.compensate_laser_cos_dsqr(data)
    n0 = int(round(float(data.t_start) / float(data.delta_t)))
    data.H = np.concatenate([np.zeros((n0,) + data.H.shape[1:], data.H.dtype), data.H], axis=0)
    data.t_start = 0.0
    with tal.resources(cpu_processes=cpus, downscale=16):
        res = tal.reconstruct.pf_dev.solve(
            data, wl_mean=wl, wl_sigma=wl, border='zero', volume_xyz=vol,
            volume_format=VolumeFormat.X_Y_Z_3, camera_system=CameraSystem.DIRECT_LIGHT,
            progress=False, compensate_invsq=False, nt=data.H.shape[0],
            try_optimize_convolutions=False)
    return np.abs(res) ** 2, time.perf_counter() - t


def run_vltm(exe, path, wl, spec, threads):
    out = os.path.join(tempfile.mkdtemp(), 'direct.npy')
    cmd = [exe, '--threads', str(threads), 'direct', path, '--volume', spec, '--wavelength', str(wl),
           '--sigma', str(wl), '--weights', 'one', '--compensate-laser', '--band', '6', '--out', out]
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return np.load(out).astype(np.float64), time.perf_counter() - t


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('capture')
    ap.add_argument('--wl', type=float, required=True, help='virtual wavelength = gate sigma [m]')
    ap.add_argument('--volume', default='-0.75:0.75:16,-0.75:0.75:16,0.4:1.35:20')
    ap.add_argument('--cpus', type=int, default=2)
    ap.add_argument('--vltm', default=os.path.join(os.path.dirname(__file__), '..', 'target', 'release', 'vltm'))
    a = ap.parse_args()
    if not os.path.exists(a.vltm):
        sys.exit(f'{a.vltm} not found: cargo build --release -p vltm-cli')
    vol = grid(a.volume)
    mine, t_v = run_vltm(a.vltm, a.capture, a.wl, a.volume, a.cpus)
    try:
        theirs, t_y = run_ytal(a.capture, a.wl, vol, a.cpus)
    except ImportError:
        print(f'vltm: {t_v:.2f} s (y-tal not installed: pip install y-tal)')
        return
    x, y = mine.ravel() / mine.max(), theirs.ravel() / theirs.max()
    r = np.corrcoef(x, y)[0, 1]
    print(f'{os.path.basename(a.capture)}: volume {vol.shape[:3]}, {a.cpus} cpus')
    print(f'  y-tal pf_dev DIRECT_LIGHT  {t_y:8.2f} s')
    print(f'  vltm direct                {t_v:8.2f} s   ({t_y / t_v:.1f}x faster)')
    print(f'  Pearson of normalised intensities {r:.5f}; same peak voxel: {np.argmax(x) == np.argmax(y)}')


if __name__ == '__main__':
    main()
