#!/usr/bin/env python3
"""Makes the paired y-tal fixture of `tests/ytal.rs` (`paired_direct_matches_ytal_fbp`):
a paired, non-confocal capture written by y-tal's own writer and y-tal's filtered
backprojection of it.

Optional: needs `pip install y-tal==0.20.0` (never needed to build or test vltm: the outputs
are committed). Writes, from the repository root:

* `fixtures/tal/paired.hdf5`: `H_format` `T_Si`, `N_3` laser and sensor grids of 144 points
  each (12 × 12 laser spots over ±0.5 m, each SPAD spot 6 cm right and 3 cm up of its laser
  spot), on a bumpy relay surface (z = 0.03·sin(6x)·cos(5y), normals from its gradient),
  300 bins of 1 cm from t_start = 0, wall-to-wall times. y-tal reads it back with
  `is_laser_paired_to_sensor()` true and `is_confocal()` false.
* `fixtures/tal/paired_fbp.npy`: `tal.reconstruct.fbp.solve(DIRECT_LIGHT)` with the `pf`
  filter (`wl_mean = wl_sigma = 0.15` m, `border='zero'`) over the volume
  `-0.4:0.4:17,-0.4:0.4:17,0.4:1.0:13` (complex64, X × Y × Z).

The histograms are three point scatterers' direct returns (laser spot → point → SPAD spot),
`a / (d1² · d2²)` in the bin of the path length, computed here with numpy.

    python3 benches/ytal_paired.py        # run from the repository root
"""
import numpy as np

import tal
from tal.enums import CameraSystem, GridFormat, HFormat, VolumeFormat
from tal.io.capture_data import NLOSCaptureData

WL = 0.15
VOLUME = "-0.4:0.4:17,-0.4:0.4:17,0.4:1.0:13"
POINTS = [((-0.15, 0.05, 0.6), 1.0), ((0.2, -0.1, 0.8), 0.8), ((0.0, 0.25, 0.5), 0.6)]
NT, DT = 300, 0.01


def surface(x, y):
    z = 0.03 * np.sin(6 * x) * np.cos(5 * y)
    dzdx = 0.18 * np.cos(6 * x) * np.cos(5 * y)
    dzdy = -0.15 * np.sin(6 * x) * np.sin(5 * y)
    n = np.stack([-dzdx, -dzdy, np.ones_like(x)], axis=-1)
    return z, n / np.linalg.norm(n, axis=-1, keepdims=True)


def grid(spec):
    axes = [np.linspace(float(a), float(b), int(n)) for a, b, n in (s.split(':') for s in spec.split(','))]
    v = np.zeros((len(axes[0]), len(axes[1]), len(axes[2]), 3), np.float32)
    v[..., 0] = axes[0][:, None, None]
    v[..., 1] = axes[1][None, :, None]
    v[..., 2] = axes[2][None, None, :]
    return v


def main():
    u = np.linspace(-0.5, 0.5, 12)
    lx, ly = np.meshgrid(u, u, indexing='ij')
    lx, ly = lx.ravel(), ly.ravel()
    sx, sy = lx + 0.06, ly + 0.03
    lz, ln = surface(lx, ly)
    sz, sn = surface(sx, sy)
    lasers = np.stack([lx, ly, lz], -1).astype(np.float32)
    sensors = np.stack([sx, sy, sz], -1).astype(np.float32)
    k = len(lasers)
    H = np.zeros((NT, k), np.float32)
    for p, a in POINTS:
        p = np.array(p)
        d1 = np.linalg.norm(lasers - p, axis=-1)
        d2 = np.linalg.norm(sensors - p, axis=-1)
        b = np.floor((d1 + d2) / DT).astype(int)
        ok = b < NT
        H[b[ok], np.arange(k)[ok]] += (a / (d1 ** 2 * d2 ** 2))[ok]

    d = NLOSCaptureData()
    d.H = H
    d.H_format = HFormat.T_Si
    d.laser_grid_xyz = lasers
    d.sensor_grid_xyz = sensors
    d.laser_grid_normals = ln.astype(np.float32)
    d.sensor_grid_normals = sn.astype(np.float32)
    d.laser_grid_format = GridFormat.N_3
    d.sensor_grid_format = GridFormat.N_3
    d.laser_xyz = np.array([0.0, -0.8, 1.0], np.float32)
    d.sensor_xyz = np.array([0.0, 0.8, 1.0], np.float32)
    d.volume_format = VolumeFormat.UNKNOWN
    d.delta_t = np.float32(DT)
    d.t_start = np.float32(0.0)
    d.t_accounts_first_and_last_bounces = False
    d.scene_info = {'original_format': 'benches/ytal_paired.py'}
    tal.io.write_capture('fixtures/tal/paired.hdf5', d)

    data = tal.io.read_capture('fixtures/tal/paired.hdf5')
    assert data.is_laser_paired_to_sensor() and not data.is_confocal()
    tal.set_log_level(tal.LogLevel.WARNING)
    vol = grid(VOLUME)
    res = tal.reconstruct.fbp.solve(
        data, wl_mean=WL, wl_sigma=WL, border='zero', volume_xyz=vol,
        volume_format=VolumeFormat.X_Y_Z_3, camera_system=CameraSystem.DIRECT_LIGHT,
        progress=False)
    res = np.asarray(res, np.complex64)
    np.save('fixtures/tal/paired_fbp.npy', res)
    i = np.abs(res) ** 2
    print('fbp', res.shape, 'peak voxel', np.unravel_index(np.argmax(i), i.shape))


if __name__ == '__main__':
    main()
