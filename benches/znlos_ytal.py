"""Cross-check of vltm's Z-NLOS test files against y-tal's own reader (not run in CI).

tests/znlos.rs writes Z-NLOS HDF5 files to y-tal's description (tal/io/format.py) from
captures rendered by vltm's simulator, and checks that vltm reads each back as the original.
This script checks the other half: that y-tal reads the same files as the same capture, i.e.
that the files really are what y-tal's converter expects (axis orders, grid transposes,
scalars, legs flag).

    VLTM_ZNLOS_KEEP=/tmp/znlos cargo test --release --test znlos direct_on_znlos
    python benches/znlos_ytal.py /tmp/znlos      # needs y-tal (pip install y-tal)

For every `<kind>_<order>.hdf5` beside `<kind>.npz`: y-tal's reading (`read_hdf5`, then
`convert_dict` to its HDF5_TAL fields, as `read_capture` does) must give H, the grids, delta_t, t_start and the device
positions of the original, and t_accounts_first_and_last_bounces = True. vltm's npz holds H
as (lx, ly, sx, sy, t) or confocal (lx, ly, t); tal's H is time first.
"""

import glob
import os
import sys
from types import SimpleNamespace

import numpy as np
from tal.enums import FileFormat, HFormat
from tal.io.capture_data import read_hdf5
from tal.io.format import convert_dict, detect_dict_format


def main(d):
    failures = 0
    files = sorted(glob.glob(os.path.join(d, "*_*.hdf5")))
    if not files:
        sys.exit(f"no Z-NLOS files in {d} (run the test with VLTM_ZNLOS_KEEP={d})")
    for f in files:
        kind = os.path.basename(f).split("_")[0]
        o = np.load(os.path.join(d, f"{kind}.npz"))
        # y-tal 0.20.0's read_capture fails on every Z-NLOS file after converting it
        # (NLOSCaptureData.__init__ yaml-loads the converter's scene_info, a dict: TypeError),
        # so call the two steps it runs before that: read_hdf5 and convert_dict.
        raw = read_hdf5(f)
        assert detect_dict_format(raw) == FileFormat.HDF5_ZNLOS
        c = SimpleNamespace(**convert_dict(raw, FileFormat.HDF5_TAL))
        c.is_confocal = lambda: c.H_format == HFormat.T_Sx_Sy and np.allclose(
            c.sensor_grid_xyz, c.laser_grid_xyz)
        H0 = np.moveaxis(o["H"], -1, 0)  # time first, as tal
        checks = {
            "H_format": str(c.H_format),
            "H shape": (c.H.shape, H0.shape),
            "max |H - H0| / max |H0|": float(np.abs(c.H - H0).max() / np.abs(H0).max()),
            "laser grid": bool(np.allclose(c.laser_grid_xyz, o["laser_grid_xyz"])),
            "sensor grid": bool(np.allclose(c.sensor_grid_xyz, o["sensor_grid_xyz"])),
            "delta_t": (float(c.delta_t), float(o["delta_t"])),
            "t_start": (float(c.t_start), float(o["t_start"])),
            "laser_xyz": bool(np.allclose(c.laser_xyz, o["laser_xyz"])),
            "sensor_xyz": bool(np.allclose(c.sensor_xyz, o["sensor_xyz"])),
            "legs": bool(c.t_accounts_first_and_last_bounces),
            "is_confocal": bool(c.is_confocal()),
        }
        ok = (
            c.H.shape == H0.shape
            and checks["max |H - H0| / max |H0|"] < 1e-6
            and checks["laser grid"]
            and checks["sensor grid"]
            and np.isclose(*checks["delta_t"])
            and np.isclose(*checks["t_start"])
            and checks["laser_xyz"]
            and checks["sensor_xyz"]
            and checks["legs"]
            and checks["is_confocal"] == bool(o["confocal"])
        )
        failures += not ok
        print(f"{'OK ' if ok else 'BAD'} {os.path.basename(f)}: {checks}")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "/tmp/znlos")
