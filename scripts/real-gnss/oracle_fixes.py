#!/usr/bin/env python3
"""Oracle GNSS files for the real-GNSS test bed (docs/real-gnss.md).

Reads a `navsync simulate --from-nav --gnss-real` folder, computes each
fix's true horizontal error (fix minus the simulated antenna: truth.nav's
position plus the lever arm rotated by its attitude), and writes two files
that only an oracle could write:

  gnss_posvel_drop.txt:    every fix whose horizontal error exceeds
                           THRESHOLD_M left out;
  gnss_posvel_inflate.txt: every fix kept, its north and east σ raised to
                           its true north and east error where that is
                           larger (the best a weighting that knew each
                           error's size could do).

and kf-gins-drop.yaml / kf-gins-inflate.yaml pointing at them.
Usage: oracle_fixes.py SIM_FOLDER [THRESHOLD_M=0.3]. Python 3, no packages.
"""
import bisect
import math
import os
import re
import sys

EQUATORIAL_RADIUS_M = 6378137.0  # WGS-84 a; a spherical approximation is
# ample for errors of metres.


def dcm_body_to_ned(roll_deg, pitch_deg, yaw_deg):
    r, p, y = (math.radians(v) for v in (roll_deg, pitch_deg, yaw_deg))
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p),
                              math.sin(p), math.cos(y), math.sin(y))
    return [[cp * cy, -cr * sy + sr * sp * cy, sr * sy + cr * sp * cy],
            [cp * sy, cr * cy + sr * sp * sy, -sr * cy + cr * sp * sy],
            [-sp, sr * cp, cr * cp]]


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    folder = sys.argv[1]
    threshold_m = float(sys.argv[2]) if len(sys.argv) == 3 else 0.3
    config = open(os.path.join(folder, "kf-gins.yaml")).read()
    lever = re.search(r"^antlever:\s*\[([^\]]*)\]", config, re.M)
    lever_m = [float(v) for v in lever.group(1).split(",")] if lever else [0.0] * 3
    gnss_name = re.search(r'^gnsspath:\s*"\./([^"]+)"', config, re.M).group(1)

    truth_sow, truth = [], []
    for line in open(os.path.join(folder, "truth.nav")):
        f = line.split()
        if len(f) >= 11:
            truth_sow.append(float(f[1]))
            truth.append([float(v) for v in f[2:11]])

    kept, inflated, dropped = [], [], 0
    for line in open(os.path.join(folder, gnss_name)):
        f = line.split()
        if line.startswith("#") or len(f) < 13:
            kept.append(line)
            inflated.append(line)
            continue
        sow = float(f[0])
        i = min(bisect.bisect_left(truth_sow, sow), len(truth_sow) - 1)
        if i > 0 and abs(truth_sow[i - 1] - sow) < abs(truth_sow[i] - sow):
            i -= 1
        lat, lon, _h, _vn, _ve, _vd, roll, pitch, yaw = truth[i]
        c = dcm_body_to_ned(roll, pitch, yaw)
        lever_n = sum(c[0][k] * lever_m[k] for k in range(3))
        lever_e = sum(c[1][k] * lever_m[k] for k in range(3))
        err_n = math.radians(float(f[1]) - lat) * EQUATORIAL_RADIUS_M - lever_n
        err_e = (math.radians(float(f[2]) - lon) * EQUATORIAL_RADIUS_M
                 * math.cos(math.radians(lat)) - lever_e)
        # KF-GINS C++ order: sow lat lon h vn ve vd sd_n sd_e sd_d sd_vn …
        f[7] = "%.4f" % max(float(f[7]), abs(err_n))
        f[8] = "%.4f" % max(float(f[8]), abs(err_e))
        inflated.append(" ".join(f) + "\n")
        if math.hypot(err_n, err_e) > threshold_m:
            dropped += 1
        else:
            kept.append(line)

    for kind, lines in (("drop", kept), ("inflate", inflated)):
        name = "gnss_posvel_%s.txt" % kind
        open(os.path.join(folder, name), "w").writelines(lines)
        open(os.path.join(folder, "kf-gins-%s.yaml" % kind), "w").write(
            config.replace('"./%s"' % gnss_name, '"./%s"' % name))
    print("%s: %d fixes over %.2f m dropped" % (folder, dropped, threshold_m))


if __name__ == "__main__":
    main()
