#!/usr/bin/env python3
"""Side by side: vltm against y-tal on an exhaustive 16x16 x 16x16 x 800-bin capture.

Reproduces the benchmark of the speed-up issue: one capture, the same volumes, both tools in one
run, wall times, ratios and the agreement of the two intensity volumes.

    python3 benches/side_by_side.py                     # vltm only (y-tal not importable)
    /tmp/ytalenv/bin/python benches/side_by_side.py     # both: a venv with `pip install y-tal numpy`
        [--vltm target/release/vltm] [--capture C.npz] [--cpus 2] [--repeat 3] [--skip-ytal]
        [--probes direct16,direct32,column] [--out-dir target/side_by_side]

Capture: `--capture` (a vltm `.npz` with a regular planar SPAD grid), or by default
`benches/scenes/exh16.json` rendered once with `vltm simulate --uncompressed` into
`<out-dir>/exh16.npz` (reused when present): 16x16 lasers x 16x16 SPADs on the same grid
(pitch 0.125 m), 800 bins of 6 mm from t0 = 0, patches A, B (facing each other, with the
A <-> B inter-reflection) and C.

Probes (lambda = sigma = 0.5 m, no lens weights: vltm `--weights one`, y-tal
`compensate_invsq=False`; y-tal's wl_sigma is the gate's standard deviation, so vltm
`--sigma` = wl_sigma):

* direct16 - DIRECT_LIGHT over V16 = 16x16x24 voxels whose x, y are exactly the SPAD grid
  (voxel pitch = SPAD pitch p) and z = `--z` (default 0.5..1.25 m, 24 slices).
  y-tal: its FFT fast path (`try_optimize_convolutions=True`, "camera convolutions",
  `divide_frequencies`). y-tal 0.20 takes that path for DIRECT_LIGHT only one Z slice per call
  (with several slices it reshapes the whole volume into one slice and raises), so the script
  does what y-tal offers for repeated calls: `pf_dev.precompute_fft` once, then one
  `solve(..., skip_H_fft=True)` per slice; the time is the sum of both.
* direct32 - DIRECT_LIGHT over V32 = 32x32x24 voxels over the same x, y range at pitch p/2:
  32 samples from x0 to x1 + p/2 (16 SPADs span 15 pitches = 30 half pitches, i.e. 31 samples;
  the 32nd extends the range by half a pitch so that the issue's 32x32 is met at exactly p/2).
  y-tal: brute force (`divide_volume`; the pitch differs from the SPAD pitch, so no FFT).
* column - one LTM column T(x_a, .) over V16, x_a = `--focus` (default: the centre of patch A
  of the scene, the lit patch that reflects onto B). vltm: `vltm column` (4-vertex gate, Eq. 14).
  y-tal has no 4-vertex gate: its PROJECTOR_CAMERA transient with projector focus x_a, sampled
  per voxel x_b at bin k = rint(|x_a - x_b| / delta_t), is Eq. 14 (the way
  fixtures/ytal/tools/run_reference.py made ref_ltmcol_focusA.npy). y-tal takes its
  camera-convolution FFT path for all 24 slices in one call (the projector side is a single
  point, element-wise).

Timing: vltm is run `--repeat` times per probe (median) as a subprocess with `--threads CPUS`;
the time is the wall time of the process (reading the capture included); vltm's own reported
compute time ("... rows in X s") is shown too. y-tal runs in this process under
`tal.resources(cpu_processes=CPUS)`; only the solve (incl. its FFT of H) is timed, the load of
the capture into an NLOSCaptureData is reported separately. y-tal 0.20 quirks handled here
(y-tal 0.20): `nt` is passed explicitly; a capture with t_start != 0 is moved to
t_start = 0 by prepending zero bins (pf_dev raises otherwise with compensate_invsq=False).

Agreement: Pearson correlation of the two intensity volumes |A|^2, each normalised to its
maximum, and whether the peak voxel is the same (or a tie within 1e-4). The table is printed
and written to `<out-dir>/table.md`; the volumes are saved there as `vltm_<probe>.npy` /
`ytal_<probe>.npy`.
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

import numpy as np  # noqa: E402

PROBES = ('direct16', 'direct32', 'column')
TARGET = {'direct16': 20, 'direct32': 20, 'column': 50}
WL = 0.5
SIGMA = 0.5


def load_capture(path):
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def axis_spec(lo, hi, n):
    return f'{lo:.10g}:{hi:.10g}:{n}'


def axis(lo, hi, n):
    return np.linspace(lo, hi, n)


def volumes(cap, zspec):
    """V16 (voxel pitch = SPAD pitch) and V32 (pitch p/2, extended by p/2), as vltm SPECs and
    y-tal X_Y_Z_3 arrays."""
    s = np.asarray(cap['sensor_grid_xyz'], np.float64)
    if s.ndim != 3 or s.shape[0] < 2 or s.shape[1] < 2:
        sys.exit('side_by_side: the capture needs a regular 2-D SPAD grid (sensor_grid_xyz X_Y_3)')
    nsx, nsy = s.shape[:2]
    x0, x1 = float(s[0, 0, 0]), float(s[-1, 0, 0])
    y0, y1 = float(s[0, 0, 1]), float(s[0, -1, 1])
    px, py = (x1 - x0) / (nsx - 1), (y1 - y0) / (nsy - 1)
    zlo, zhi, nz = zspec.split(':')
    zlo, zhi, nz = float(zlo), float(zhi), int(nz)
    out = {}
    for name, (ax, ay) in {
        'V16': ((x0, x1, nsx), (y0, y1, nsy)),
        'V32': ((x0, x1 + px / 2, 2 * nsx), (y0, y1 + py / 2, 2 * nsy)),
    }.items():
        spec = ','.join([axis_spec(*ax), axis_spec(*ay), axis_spec(zlo, zhi, nz)])
        xs, ys, zs = axis(*ax), axis(*ay), axis(zlo, zhi, nz)
        v = np.zeros((len(xs), len(ys), len(zs), 3), np.float32)
        v[..., 0] = xs[:, None, None]
        v[..., 1] = ys[None, :, None]
        v[..., 2] = zs[None, None, :]
        out[name] = (spec, v)
    return out, (px, py)


# ------------------------------------------------------------------------------------------ vltm

def run_vltm(exe, cpus, args, out, repeat):
    cmd = [exe, '--threads', str(cpus)] + args + ['--out', out]
    walls, computes = [], []
    for _ in range(repeat):
        t = time.perf_counter()
        p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wall = time.perf_counter() - t
        if p.returncode != 0:
            sys.exit(f'side_by_side: {" ".join(cmd)} failed ({p.returncode}): {p.stderr.strip()}')
        walls.append(wall)
        m = re.search(r'rows in ([0-9.]+) s', p.stdout)
        if m:
            computes.append(float(m.group(1)))
    return {'cmd': cmd, 'wall': statistics.median(walls), 'walls': walls,
            'compute': statistics.median(computes) if computes else None,
            'stdout': p.stdout.strip().splitlines()[0] if p.stdout.strip() else '',
            'volume': np.load(out).astype(np.float64)}


# ----------------------------------------------------------------------------------------- y-tal

def ytal_data(cap):
    """The capture as a tal NLOSCaptureData (H time-first, T_Lx_Ly_Sx_Sy)."""
    from tal.enums import GridFormat, HFormat
    from tal.io.capture_data import NLOSCaptureData
    H = cap['H']
    if H.ndim != 5:
        sys.exit('side_by_side: y-tal comparison needs an exhaustive capture H (Lx, Ly, Sx, Sy, Nt)')
    d = NLOSCaptureData()
    d.H = np.ascontiguousarray(np.moveaxis(H, -1, 0))
    d.H_format = HFormat.T_Lx_Ly_Sx_Sy
    d.laser_grid_xyz = np.asarray(cap['laser_grid_xyz'], np.float32)
    d.sensor_grid_xyz = np.asarray(cap['sensor_grid_xyz'], np.float32)
    d.laser_grid_format = d.sensor_grid_format = GridFormat.X_Y_3
    d.laser_xyz = np.asarray(cap['laser_xyz'], np.float32)
    d.sensor_xyz = np.asarray(cap['sensor_xyz'], np.float32)
    d.delta_t = float(cap['delta_t'])
    d.t_start = float(cap['t_start'])
    d.t_accounts_first_and_last_bounces = bool(cap['t_accounts_first_and_last_bounces'])
    if d.t_accounts_first_and_last_bounces:
        sys.exit('side_by_side: y-tal 0.20 pf_dev raises for t_accounts_first_and_last_bounces=True '
                 '(y-tal 0.20); use a wall-to-wall capture')
    # y-tal 0.20: pf_dev raises for t_start != 0 with compensate_invsq=False -> prepend zero bins
    n0 = int(round(d.t_start / d.delta_t))
    if n0 != 0:
        assert abs(n0 * d.delta_t - d.t_start) < 1e-6 and n0 > 0, 't_start must be a bin multiple >= 0'
        d.H = np.concatenate([np.zeros((n0,) + d.H.shape[1:], d.H.dtype), d.H], axis=0)
        d.t_start = 0.0
    return d


class YTal:
    def __init__(self, cap, cpus, downscale):
        import tal
        self.tal = tal
        tal.set_log_level(tal.LogLevel.WARNING)
        t = time.perf_counter()
        self.data = ytal_data(cap)
        self.load_s = time.perf_counter() - t
        self.cpus, self.downscale = cpus, downscale
        self.nt = self.data.H.shape[0]
        self.version = tal.__version__

    def _format(self, vol):
        from tal.enums import VolumeFormat
        return VolumeFormat.X_Y_3 if vol.ndim == 3 else VolumeFormat.X_Y_Z_3

    def path(self, vol, optimize, focus=None):
        """Which pf_dev path solve() takes: y-tal's own decision (convert_to_N_3)."""
        from tal.reconstruct.util import convert_to_N_3
        *_, opt_p, opt_c = convert_to_N_3(self.data, vol, self._format(vol), projector_focus=focus,
                                          try_optimize_convolutions=optimize)
        if opt_c or opt_p:
            return 'FFT (camera convolutions, divide_frequencies)' if opt_c else \
                'FFT (projector convolutions, divide_frequencies)'
        return 'brute force (divide_volume)'

    def solve(self, data, vol, cs, optimize, focus=None, **kw):
        with self.tal.resources(cpu_processes=self.cpus, downscale=self.downscale):
            return self.tal.reconstruct.pf_dev.solve(
                data, wl_mean=WL, wl_sigma=SIGMA, border='zero', volume_xyz=vol,
                volume_format=self._format(vol), camera_system=cs, projector_focus=focus,
                progress=False, compensate_invsq=False, nt=self.nt,   # y-tal 0.20: nt=None raises
                try_optimize_convolutions=optimize, **kw)

    def direct_fft(self, vol):
        """DIRECT_LIGHT on the FFT path, one Z slice per call on a precomputed FFT of H."""
        import copy
        from tal.enums import CameraSystem
        path = self.path(vol[:, :, 0], True)
        t = time.perf_counter()
        pre = copy.copy(self.data)
        pre.H = self.tal.reconstruct.pf_dev.precompute_fft(self.data, SIGMA)
        t_fft = time.perf_counter() - t
        out = np.zeros(vol.shape[:3], np.complex64)
        for k in range(vol.shape[2]):
            out[:, :, k] = self.solve(pre, vol[:, :, k], CameraSystem.DIRECT_LIGHT, True,
                                      skip_H_fft=True)
        total = time.perf_counter() - t
        del pre
        note = (f'{path}; precompute_fft {t_fft:.1f} s + {vol.shape[2]} slice calls '
                f'{total - t_fft:.1f} s')
        return np.abs(out) ** 2, total, note

    def direct_brute(self, vol):
        from tal.enums import CameraSystem
        path = self.path(vol, False)
        t = time.perf_counter()
        res = self.solve(self.data, vol, CameraSystem.DIRECT_LIGHT, False)
        return np.abs(res) ** 2, time.perf_counter() - t, path

    def column(self, vol, xa):
        from tal.enums import CameraSystem
        xa = np.asarray(xa, np.float32)
        path = self.path(vol, True, focus=xa)
        t = time.perf_counter()
        tr = self.solve(self.data, vol, CameraSystem.PROJECTOR_CAMERA, True, focus=xa)  # (nt, X, Y, Z)
        k = np.rint(np.linalg.norm(vol - xa, axis=-1) / self.data.delta_t).astype(np.int64)
        if k.max() >= tr.shape[0]:
            sys.exit('side_by_side: |x_a - x_b| beyond the PROJECTOR_CAMERA transient')
        col = np.take_along_axis(tr, k[None], axis=0)[0]
        dt = time.perf_counter() - t
        del tr
        return np.abs(col) ** 2, dt, path + '; transient sampled at t = |x_a - x_b|'


# ------------------------------------------------------------------------------------------ main

def agreement(a, b):
    """Pearson of the max-normalised volumes; 'yes' if the peak voxel is the same, 'tie' if it
    differs but each tool's peak voxel is within 1e-4 of the maximum in the other's volume."""
    x, y = a.ravel() / a.max(), b.ravel() / b.max()
    ix, iy = int(np.argmax(x)), int(np.argmax(y))
    same = 'yes' if ix == iy else 'tie' if min(x[iy], y[ix]) >= 1 - 1e-4 else 'no'
    return float(np.corrcoef(x, y)[0, 1]), same


def peak(vol, v):
    i = np.unravel_index(np.argmax(vol), vol.shape)
    return '(' + ', '.join(f'{c:+.3f}' for c in v[i]) + ')'


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog='\n'.join(__doc__.split('\n')[2:]))
    ap.add_argument('--vltm', default=os.path.join(ROOT, 'target', 'release', 'vltm'))
    ap.add_argument('--capture', help='capture .npz (default: render --scene into --out-dir)')
    ap.add_argument('--scene', default=os.path.join(HERE, 'scenes', 'exh16.json'))
    ap.add_argument('--out-dir', default=os.path.join(ROOT, 'target', 'side_by_side'))
    ap.add_argument('--cpus', type=int, default=2)
    ap.add_argument('--repeat', type=int, default=3, help='vltm runs per probe (median)')
    ap.add_argument('--skip-ytal', action='store_true')
    ap.add_argument('--ytal-downscale', type=int, default=16,
                    help='tal.resources downscale (work chunks; as run_reference.py)')
    ap.add_argument('--probes', default=','.join(PROBES))
    ap.add_argument('--z', default='0.5:1.25:24', help='z0:z1:nz of both volumes [m]')
    ap.add_argument('--focus', help='x_a "X,Y,Z" of the column (default: patch A of --scene)')
    a = ap.parse_args()

    probes = [p for p in a.probes.split(',') if p]
    for p in probes:
        if p not in PROBES:
            sys.exit(f'side_by_side: unknown probe {p!r} (one of {", ".join(PROBES)})')
    if not os.path.exists(a.vltm):
        sys.exit(f'side_by_side: {a.vltm} not found: cargo build --release -p vltm-cli (or --vltm PATH)')
    os.makedirs(a.out_dir, exist_ok=True)

    capture = a.capture
    if capture is None:
        capture = os.path.join(a.out_dir, os.path.splitext(os.path.basename(a.scene))[0] + '.npz')
        if not os.path.exists(capture):
            t = time.perf_counter()
            subprocess.run([a.vltm, '--threads', str(a.cpus), 'simulate', a.scene, '--out', capture, '--uncompressed'],
                           check=True, stdout=subprocess.DEVNULL)
            print(f'rendered {a.scene} -> {capture} in {time.perf_counter() - t:.1f} s')
    if a.focus:
        xa = [float(c) for c in a.focus.split(',')]
    else:
        scene = json.load(open(a.scene))
        xa = [o['center'] for o in scene['objects'] if o.get('name') == 'A']
        if not xa:
            sys.exit(f'side_by_side: {a.scene} has no object "A": give --focus X,Y,Z')
        xa = [float(c) for c in xa[0]]
    focus = ','.join(f'{c:.10g}' for c in xa)

    load0 = os.getloadavg()[0]
    cap = load_capture(capture)
    H = cap['H']
    vols, (px, py) = volumes(cap, a.z)
    print(f'capture {capture}: H {H.shape} {H.dtype}, delta_t {float(cap["delta_t"])} m, '
          f't_start {float(cap["t_start"])} m; SPAD pitch {px:.4f} x {py:.4f} m')
    for name, (spec, v) in vols.items():
        print(f'  {name}: {"x".join(map(str, v.shape[:3]))} voxels  --volume={spec}')
    print(f'  column focus x_a = ({focus}) m; lambda = {WL} m, sigma = {SIGMA} m, no lens weights; '
          f'{a.cpus} cpus; load average {os.getloadavg()[0]:.2f}')

    ytal = None
    if not a.skip_ytal:
        try:
            ytal = YTal(cap, a.cpus, a.ytal_downscale)
            print(f'y-tal {ytal.version}: capture loaded into NLOSCaptureData in {ytal.load_s:.2f} s '
                  f'(H {ytal.data.H.shape}, not timed below)')
        except ImportError:
            print(f'y-tal: not importable by {sys.executable} (pip install y-tal; '
                  'e.g. /tmp/ytalenv/bin/python benches/side_by_side.py)')
    del H

    common = ['--wavelength', str(WL), '--sigma', str(SIGMA), '--weights', 'one']
    jobs = {
        'direct16': ('V16', ['direct', capture, '--volume=' + vols['V16'][0]] + common),
        'direct32': ('V32', ['direct', capture, '--volume=' + vols['V32'][0]] + common),
        'column': ('V16', ['column', capture, '--focus=' + focus, '--volume=' + vols['V16'][0],
                           '--no-leak-correct'] + common),
    }
    rows = []
    for p in probes:
        vname, args = jobs[p]
        spec, v = vols[vname]
        print(f'\n{p} over {vname} ({"x".join(map(str, v.shape[:3]))}):', flush=True)
        r = run_vltm(a.vltm, a.cpus, args, os.path.join(a.out_dir, f'vltm_{p}.npy'), a.repeat)
        comp = f', compute {r["compute"]:.2f} s' if r['compute'] is not None else ''
        print(f'  vltm  {r["wall"]:8.2f} s wall (median of {", ".join(f"{w:.2f}" for w in r["walls"])}'
              f'{comp}); peak {peak(r["volume"], v)}')
        print(f'        {" ".join(r["cmd"])}', flush=True)
        row = {'probe': p, 'volume': f'{vname} {"x".join(map(str, v.shape[:3]))}', 'vltm': r['wall'],
               'vltm_compute': r['compute'], 'ytal': None, 'pearson': None, 'same_peak': None, 'note': ''}
        if ytal is not None:
            la = os.getloadavg()[0]
            if p == 'direct16':
                vol, t, note = ytal.direct_fft(v)
            elif p == 'direct32':
                vol, t, note = ytal.direct_brute(v)
            else:
                vol, t, note = ytal.column(v, xa)
            np.save(os.path.join(a.out_dir, f'ytal_{p}.npy'), vol.astype(np.float32))
            rho, same = agreement(r['volume'], vol)
            row.update(ytal=t, pearson=rho, same_peak=same, note=note)
            print(f'  y-tal {t:8.2f} s ({note}; load average {la:.2f}); peak {peak(vol, v)}')
            print(f'  ratio {t / r["wall"]:.1f}x (target {TARGET[p]}x); Pearson {rho:.6f}; '
                  f'same peak voxel: {same}', flush=True)
        rows.append(row)

    def f(x, fmt):
        return '—' if x is None else format(x, fmt)

    def cell(text):
        return text.replace('|', '\\|')   # a '|' inside a markdown table cell

    lines = ['| probe | volume | y-tal s | vltm s | ratio | target | Pearson | same peak '
             '| vltm compute s | ratio to compute | y-tal path |',
             '|---|---|---|---|---|---|---|---|---|---|---|']
    for r in rows:
        ratio = None if r['ytal'] is None else r['ytal'] / r['vltm']
        cratio = None if r['ytal'] is None or not r['vltm_compute'] else r['ytal'] / r['vltm_compute']
        lines.append(f'| {r["probe"]} | {r["volume"]} | {f(r["ytal"], ".2f")} | {r["vltm"]:.2f} | '
                     f'{"—" if ratio is None else f"{ratio:.1f}x"} | ≥{TARGET[r["probe"]]}x | '
                     f'{f(r["pearson"], ".6f")} | {f(r["same_peak"], "")} | '
                     f'{f(r["vltm_compute"], ".2f")} | {"—" if cratio is None else f"{cratio:.1f}x"} | '
                     f'{cell(r["note"]) or "—"} |')
    foot = (f'\ncapture `{os.path.relpath(capture, ROOT) if capture.startswith(ROOT) else capture}` '
            f'{"x".join(map(str, cap["H"].shape))}, λ = σ = {WL} m, {a.cpus} cpus; vltm: median wall '
            f'time of {a.repeat} runs incl. reading the capture ("ratio"), and vltm\'s own reported '
            f'compute time without it ("ratio to compute"); y-tal: solve only'
            + (f' (y-tal {ytal.version}, load {ytal.load_s:.2f} s not included)' if ytal else '')
            + f'; 1-min load average {load0:.2f} at the start, {os.getloadavg()[0]:.2f} at the end.')
    table = '\n'.join(lines) + '\n' + foot + '\n'
    print('\n' + table)
    with open(os.path.join(a.out_dir, 'table.md'), 'w') as fh:
        fh.write(table)


if __name__ == '__main__':
    main()
