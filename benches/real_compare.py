#!/usr/bin/env python3
"""vltm against y-tal's filtered backprojection (`tal.reconstruct.fbp`) on a real Stanford
confocal capture (MAT v5, `fixtures/real/`): same preprocessing, volume, λ, σ, weights.

Optional: needs `pip install y-tal scipy` (never needed to build or test vltm). y-tal cannot
read the Stanford layout (`rect_data` + `width`), so this script builds its capture by hand
with the conventions vltm applies by default (4 ps bins, t = 0 at the wall, legs excluded,
grid over [-width, width]^2, the first index along x, the second down y from +width to
-width), after the authors' preprocessing (the first 600 bins dropped, `--rebin` K = 4 bins
summed). The dropped bins are zero-padded back so that y-tal's t_start is 0 (as
benches/ytal_compare.py does); y-tal samples a summed bin at its start, vltm at its centre
((K-1)/2 source bins later). Then `vltm direct` with `--t-min 600b --rebin K --weights one`,
and both wall times, their ratio and the Pearson
correlation of the max-normalised intensities.

    python3 benches/real_compare.py fixtures/real/data_resolution_chart_40cm.mat \\
        --volume=-0.2:0.2:64,-0.2:0.2:64,0.35:0.45:11 [--wl 0.04] [--cpus 2] [--repeat 3] \\
        [--rebin 4] [--reference] [--save PREFIX]

`--reference` also evaluates the gated phasor of the paper (Eq. 11, Gaussian gate of std σ,
carrier 2π/λ, no weights) in float64 on the same preprocessed histograms, once at the exact
path time of every wall point (vltm's convention) and once as y-tal's `bp` does it: the filtered
histogram taken at the start of the bin the path falls in (`idx.astype(np.int32)`, a summed
bin timed at its start). Both are printed as Pearson against vltm and against y-tal: which
sampling convention each program follows, independently of either's code.

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


def run_ytal(path, wl, vol, cpus, k, trim=600):
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


def load_prep(path, trim, k):
    """The authors' preprocessing as vltm's `--t-min {trim}b --rebin {k}`: histograms
    (N1·N2, T) in float64, the wall points (N1·N2, 3) and the source bin width (m)."""
    import scipy.io
    m = scipy.io.loadmat(path)
    h = np.asarray(m['rect_data'], np.float64)[:, :, trim:]
    w = float(np.asarray(m['width']).item())
    n1, n2, nt = h.shape
    nt = nt // k * k
    h = h[:, :, :nt].reshape(n1 * n2, nt // k, k).sum(-1)
    g = np.zeros((n1, n2, 3))
    g[..., 0], g[..., 1] = np.linspace(-w, w, n1)[:, None], np.linspace(w, -w, n2)[None, :]
    return h, g.reshape(-1, 3), 4e-12 * C


def gated_phasors(h, dt, wl, sigma, up):
    """Z(t) = sum_n h_n g(t - t_n) exp(i 2pi (t - t_n) / wl), g(u) = exp(-u^2 / 2 sigma^2), of
    every histogram at t - t_0 = q dt / up (q = 0 .. up N - 1), float64 in frequency (the gate's
    spectrum is exact; the histograms are zero-padded by 12 sigma), stored as complex64."""
    nh, nt = h.shape
    n = 1 << int(np.ceil(np.log2(nt + 12 * sigma / dt)))
    k = np.fft.fftfreq(n, 1.0 / n)
    # The gate's Fourier transform over the bins (sum_n g(n dt) e^{...} ~ sigma sqrt(2 pi) / dt).
    gate = np.exp(-0.5 * sigma ** 2 * (2 * np.pi * k / (n * dt) - 2 * np.pi / wl) ** 2) \
        * sigma * np.sqrt(2 * np.pi) / dt
    keep = gate > 1e-12 * gate.max()
    cols = np.where(k >= 0, k, k + n * up).astype(np.int64)[keep]
    z = np.empty((nh, n * up), np.complex64)
    for i in range(0, nh, 256):
        spec = np.zeros((min(256, nh - i), n * up), np.complex128)
        spec[:, cols] = np.fft.fft(h[i:i + 256], n, axis=1)[:, keep] * gate[keep]
        z[i:i + 256] = np.fft.ifft(spec, axis=1) * up
    return z


def reference(path, wl, vol, k, trim=600):
    """The float64 reference images (|sum over wall points of Z at 2|x_s - v||^2, confocal, no
    weights): 'exact' at the exact path time with a summed bin at the mean of its times (vltm),
    'y-tal' at the start of the bin the path falls in with a summed bin at its start."""
    h, wall, delta = load_prep(path, trim, k)
    dt = k * delta
    up = int(np.ceil(dt / 3e-4))  # a fine grid of 0.3 mm, interpolated linearly
    z = gated_phasors(h, dt, wl, wl, up)
    rows = np.arange(len(wall))[None, :]
    pts = vol.reshape(-1, 3).astype(np.float64)
    out = {}
    for name, t0, floor in (('exact', (trim + (k - 1) / 2) * delta, False),
                            ('y-tal', trim * delta, True)):
        acc = np.empty(len(pts), np.complex128)
        for i in range(0, len(pts), 256):
            tau = 2 * np.linalg.norm(wall[None] - pts[i:i + 256, None], axis=-1)
            x = (tau - t0) / dt
            q = (np.floor(x) if floor else x) * up
            q0 = np.floor(q).astype(np.int64)
            f = q - q0
            ok = (q0 >= 0) & (q0 + 1 < z.shape[1])
            q0 = np.clip(q0, 0, z.shape[1] - 2)
            acc[i:i + 256] = ((z[rows, q0] * (1 - f) + z[rows, q0 + 1] * f) * ok).sum(1)
        out[name] = np.abs(acc.reshape(vol.shape[:3])) ** 2
    return out


def pearson(a, b):
    """Pearson correlation of two max-normalised intensity volumes."""
    return np.corrcoef(a.ravel() / a.max(), b.ravel() / b.max())[0, 1]


def run_vltm(exe, path, wl, spec, threads, repeat, k):
    """Median wall time of `repeat` runs of the whole command (reading the `.mat` included),
    the evaluation path it reports and its peak resident memory (KB, over the runs)."""
    import resource
    out = os.path.join(tempfile.mkdtemp(), 'direct.npy')
    cmd = [exe, '--threads', str(threads), 'direct', path, f'--volume={spec}', '--t-min', '600b',
           '--rebin', str(k), '--wavelength', str(wl), '--sigma', str(wl), '--weights', 'one',
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
    ap.add_argument('--rebin', type=int, default=4, help='bins summed (the authors: 4)')
    ap.add_argument('--reference', action='store_true',
                    help='also the float64 reference at exact and at y-tal-sampled path times')
    ap.add_argument('--save', metavar='PREFIX',
                    help='also write both intensity volumes, PREFIX-vltm.npy and PREFIX-ytal.npy')
    ap.add_argument('--vltm', default=os.path.join(os.path.dirname(__file__), '..', 'target', 'release', 'vltm'))
    a = ap.parse_args()
    if not os.path.exists(a.vltm):
        sys.exit(f'{a.vltm} not found: cargo build --release -p vltm-cli')
    if a.rebin < 1 or 600 % a.rebin:
        sys.exit('--rebin must divide the 600 dropped bins')
    vol = grid(a.volume)
    load0 = os.getloadavg()
    mine, t_v, path_used, rss = run_vltm(a.vltm, a.capture, a.wl, a.volume, a.cpus, a.repeat,
                                           a.rebin)
    try:
        theirs, t_y = run_ytal(a.capture, a.wl, vol, a.cpus, a.rebin)
    except ImportError as e:
        print(f'vltm: {t_v:.2f} s (y-tal not available: {e})')
        return
    load1 = os.getloadavg()
    theirs = theirs.reshape(mine.shape)
    if a.save:
        np.save(f'{a.save}-vltm.npy', mine)
        np.save(f'{a.save}-ytal.npy', theirs)
    r = pearson(mine, theirs)
    pm, pt = np.unravel_index(np.argmax(mine), mine.shape), np.unravel_index(np.argmax(theirs), mine.shape)
    print(f'{os.path.basename(a.capture)}: volume {a.volume} {vol.shape[:3]}, {a.cpus} cpus, '
          f'wl = sigma = {a.wl} m, rebin {a.rebin}, nice {os.nice(0)}, load average {load0[0]:.1f} before, '
          f'{load1[0]:.1f} after')
    print(f'  y-tal fbp DIRECT_LIGHT  {t_y:8.2f} s')
    print(f'  vltm direct ({path_used})  {t_v:8.2f} s   ({t_y / t_v:.1f}x; median of {a.repeat}, '
          f'max RSS {rss / 1024:.0f} MB)')
    print(f'  Pearson of normalised intensities {r:.5f}; peak voxel vltm {pm}, y-tal {pt}')
    if a.reference:
        for name, ref in reference(a.capture, a.wl, vol, a.rebin).items():
            pr = np.unravel_index(np.argmax(ref), mine.shape)
            print(f'  f64 reference, {name} sampling: Pearson {pearson(ref, mine):.5f} against '
                  f'vltm, {pearson(ref, theirs):.5f} against y-tal; peak voxel {pr}')

if __name__ == '__main__':
    main()
