#!/usr/bin/env python3
"""Turn a KF-GINS IMU file's axes about one body axis, as if the IMU had
been mounted turned by BETA degrees about the vehicle's vertical (that axis
being the IMU's vertical): each Δθ and Δv becomes Rot(axis, −BETA)·v, so
the mounting yaw (`mount_deg[2]`, docs/real-logs.md) grows by BETA.
Python 3 standard library only. The Husky's vertical is its body y axis:

    python3 scripts/real-logs/turn_imu.py IN.txt OUT.txt 90 y
"""

import math
import sys


def main(src, dst, beta_deg, axis):
    c, s = math.cos(-math.radians(beta_deg)), math.sin(-math.radians(beta_deg))
    # Rotation by the angle about x, y or z (right-handed).
    rot = {
        "x": lambda x, y, z: (x, c * y - s * z, s * y + c * z),
        "y": lambda x, y, z: (c * x + s * z, y, -s * x + c * z),
        "z": lambda x, y, z: (c * x - s * y, s * x + c * y, z),
    }[axis]
    with open(src) as f, open(dst, "w") as o:
        for n, line in enumerate(f, 1):
            v = line.split()
            if line.startswith("#") or not v:
                o.write(line)
                continue
            if len(v) < 7:
                sys.exit(f"{src}:{n}: expected 7 columns (sow, dθ xyz, Δv xyz), got {len(v)}")
            a = rot(*map(float, v[1:4]))
            b = rot(*map(float, v[4:7]))
            o.write(" ".join([v[0]] + [repr(x) for x in a + b] + v[7:]) + "\n")


if __name__ == "__main__":
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4])
