#!/usr/bin/env python3
"""Writes the synthetic paired benchmark scene (issue 36): 64 x 64 = 4,096 pairs on a 2 x 2 m
wall, each SPAD spot 0.27 m to the right of its laser spot, 512 bins of 32 ps, patches at
0.7-1.6 m. Usage: python3 benches/paired_scene.py OUT.json [N]  (N x N pairs, default 64)."""
import json
import sys

out = sys.argv[1]
n = int(sys.argv[2]) if len(sys.argv) > 2 else 64
gap = 0.27
lasers, spads = [], []
for i in range(n):
    for j in range(n):
        x = -1.0 + (2.0 - gap) * i / (n - 1)
        y = -1.0 + 2.0 * j / (n - 1)
        lasers.append([round(x, 6), round(y, 6), 0.0])
        spads.append([round(x + gap, 6), round(y, 6), 0.0])
scene = {
    "description": f"paired benchmark: {n}x{n} pairs 0.27 m apart on a 2 x 2 m wall, 512 bins of 32 ps",
    "setup": {
        "lasers": {"points": lasers, "shape": [n, n]},
        "spads": {"points": spads, "shape": [n, n]},
        "scan": "paired",
        "nt": 512,
        "dt": 0.0095938,
        "t0": 1.0,
    },
    "bounces": "direct",
    "max_vertices": 3,
    "objects": [
        {"type": "patch", "name": "near", "center": [-0.3, 0.2, 0.7], "normal": [0, 0, -1], "size": [0.3, 0.2]},
        {"type": "patch", "name": "mid", "center": [0.3, -0.2, 1.1], "normal": [0, 0, -1], "size": 0.3},
        {"type": "patch", "name": "far", "center": [0.0, 0.4, 1.6], "normal": [0, 0, -1], "size": [0.5, 0.3]},
    ],
}
with open(out, "w") as f:
    json.dump(scene, f)
