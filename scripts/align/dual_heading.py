#!/usr/bin/env python3
"""A moving-base receiver's heading file from a simulated truth.nav.

Usage: dual_heading.py TRUTH.nav OUT.txt MOUNT_YAW_DEG NOISE_SD_DEG [RATE_HZ]

The azimuth of the body-fixed baseline u = (cos a, sin a, 0) is
az = yaw + atan2(w_y, w_x), w = R_y(pitch) R_x(roll) u (docs/alignment.md,
"Dual-antenna heading"), plus Gaussian noise (fixed seed), at RATE_HZ (5).
"""
import math
import random
import sys

truth, out, alpha, sd = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
rate = float(sys.argv[5]) if len(sys.argv) > 5 else 5.0
random.seed(7)
a = math.radians(alpha)
with open(truth) as f, open(out, "w") as o:
    o.write("# sow heading_deg sd_deg source\n")
    for line in f:
        v = line.split()
        sow = float(v[1])
        if abs(sow * rate - round(sow * rate)) > 1e-6:
            continue
        r, p, y = (math.radians(float(x)) for x in v[8:11])
        wx = math.cos(p) * math.cos(a) + math.sin(p) * math.sin(a) * math.sin(r)
        wy = math.sin(a) * math.cos(r)
        az = math.degrees(y + math.atan2(wy, wx)) + random.gauss(0, sd)
        o.write(f"{sow:.3f} {az % 360:.5f} {sd:.3f} baseline\n")
