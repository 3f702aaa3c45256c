#!/usr/bin/env python3
"""Convert comma2k19 Example_1 (CSV export in ../shared/data/comma2k19-example1)
into KF-GINS files for `navsync fuse`, plus a truth file and a speed file.

A small, single-purpose conversion path (general converters are another
issue's work). Conventions:
- every stream is stamped with boot time at arrival; GPS time of week =
  boot + 357697.8495 s (the constant offset of reference_pose.csv);
- IMU: rates to increments with the trapezoid rule over each interval
  (Tang, Zhang & Niu 2022: rate -> increment by trapezoid), FRD as recorded;
- GNSS: the fix's own time of validity (UTC ms + 18 s leap seconds -> GPS),
  lat/lon/alt (alt is ellipsoidal: it agrees with the reference to ~2 m,
  MSL would be ~32 m off here), standard deviations given on the command line;
- CAN speed -> `sow speed_mps`;
- reference_pose.csv (camera, ECEF; quaternion = C_camera^ECEF) -> 11-column
  truth (week sow lat lon h vn ve vd roll pitch yaw), used for the initial
  state and for scoring. The camera is not the IMU: small lever arm and
  rotation, ignored.
Also prints the camera's mounting angles relative to the direction of
travel (for --mount of the NHC), estimated from the reference velocity.

Usage: comma2k19_to_kfgins.py SRC_DIR OUT_DIR [--gnss-sd H V]
"""
import sys, os, math
import numpy as np

OFFSET = 357697.8495
A = 6378137.0
F = 1 / 298.257223563
E2 = F * (2 - F)


def ecef2lla(x, y, z):
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1 - E2))
    for _ in range(8):
        n = A / np.sqrt(1 - E2 * np.sin(lat) ** 2)
        h = p / np.cos(lat) - n
        lat = np.arctan2(z, p * (1 - E2 * n / (n + h)))
    return lat, lon, h


def c_ne(lat, lon):
    """C_n^e (NED -> ECEF)."""
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-sl * co, -so, -cl * co], [-sl * so, co, -cl * so], [cl, 0, -sl]])


def q2m(w, x, y, z):
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def euler(c_bn):
    roll = math.atan2(c_bn[2, 1], c_bn[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, c_bn[2, 0])))
    yaw = math.atan2(c_bn[1, 0], c_bn[0, 0])
    return roll, pitch, yaw


def main():
    args = sys.argv[1:]
    if len(args) < 2:
        sys.exit(__doc__)
    src, out = args[0], args[1]
    sd_h, sd_v = 3.0, 5.0
    if "--gnss-sd" in args:
        i = args.index("--gnss-sd")
        sd_h, sd_v = float(args[i + 1]), float(args[i + 2])
    os.makedirs(out, exist_ok=True)
    load = lambda name: np.loadtxt(os.path.join(src, name), delimiter=",", comments="#")
    imu, gnss, can, ref = load("imu.csv"), load("gnss_ublox.csv"), load("can_speed.csv"), load("reference_pose.csv")

    # Truth from the reference (camera).
    week = int(ref[0, 1])
    lat, lon, h = ecef2lla(ref[:, 3], ref[:, 4], ref[:, 5])
    with open(os.path.join(out, "truth.nav"), "w") as f:
        mounts = []
        for k in range(len(ref)):
            cne = c_ne(lat[k], lon[k])
            vn = cne.T @ ref[k, 6:9]
            c_bn = cne.T @ q2m(*ref[k, 9:13])
            r, p, y = euler(c_bn)
            f.write(f"{week} {ref[k, 0] + OFFSET:.6f} {math.degrees(lat[k]):.11f} {math.degrees(lon[k]):.11f} {h[k]:.4f} "
                    f"{vn[0]:.5f} {vn[1]:.5f} {vn[2]:.5f} {math.degrees(r):.5f} {math.degrees(p):.5f} {math.degrees(y):.5f}\n")
            vb = c_bn.T @ vn
            if np.linalg.norm(vb) > 5:
                mounts.append((math.atan2(-vb[2], math.hypot(vb[0], vb[1])), math.atan2(vb[1], vb[0])))
    # Velocity direction in the camera frame: the vehicle's forward axis.
    # Mount angles of the camera in the vehicle (pitch, yaw): the vehicle x
    # axis seen from the camera is at elevation -pitch... reported as the
    # rotation that takes camera axes to vehicle axes (NHC --mount roll,pitch,yaw).
    mp = -float(np.median([m[0] for m in mounts])) if mounts else 0.0
    my = -float(np.median([m[1] for m in mounts])) if mounts else 0.0

    # IMU increments (trapezoid over each arrival interval).
    t = imu[:, 0] + OFFSET
    with open(os.path.join(out, "imu.txt"), "w") as f:
        for k in range(1, len(imu)):
            dt = t[k] - t[k - 1]
            dth = 0.5 * (imu[k - 1, 1:4] + imu[k, 1:4]) * dt
            dv = 0.5 * (imu[k - 1, 4:7] + imu[k, 4:7]) * dt
            f.write(f"{t[k]:.9f} " + " ".join(f"{v:.12e}" for v in (*dth, *dv)) + "\n")
    rate = (len(imu) - 1) / (t[-1] - t[0])

    # GNSS at its time of validity.
    with open(os.path.join(out, "gnss.txt"), "w") as f:
        for row in gnss:
            gps = row[4] / 1000.0 - 315964800.0 + 18.0
            sow = gps - week * 604800.0
            f.write(f"{sow:.3f} {row[1]:.9f} {row[2]:.9f} {row[5]:.3f} {sd_h} {sd_h} {sd_v}\n")

    with open(os.path.join(out, "speed.txt"), "w") as f:
        f.write("# comma2k19 CAN vehicle speed at arrival (boot + 357697.8495 s)\n# sow speed_mps\n")
        for row in can:
            f.write(f"{row[0] + OFFSET:.6f} {row[1]:.4f}\n")

    # Initial state: the reference interpolated at the first IMU epoch after it.
    t_ref = ref[:, 0] + OFFSET
    t0 = t[t > t_ref[0]][1]
    i = np.searchsorted(t_ref, t0) - 1
    a = (t0 - t_ref[i]) / (t_ref[i + 1] - t_ref[i])
    tr = np.loadtxt(os.path.join(out, "truth.nav"))
    s0 = tr[i] + a * (tr[i + 1] - tr[i])
    cfg = f"""# KF-GINS configuration for comma2k19 Example_1 (written by comma2k19_to_kfgins.py)
imupath: "{out}/imu.txt"
gnsspath: "{out}/gnss.txt"
outputpath: "{out}/out"
imudatalen: 7
imudatarate: {rate:.3f}
starttime: {t0:.9f}
endtime: -1
initpos: [ {s0[2]:.11f}, {s0[3]:.11f}, {s0[4]:.4f} ]
initvel: [ {s0[5]:.5f}, {s0[6]:.5f}, {s0[7]:.5f} ]
initatt: [ {s0[8]:.5f}, {s0[9]:.5f}, {s0[10]:.5f} ]
initgyrbias: [ 0, 0, 0 ]
initaccbias: [ 0, 0, 0 ]
initgyrscale: [ 0, 0, 0 ]
initaccscale: [ 0, 0, 0 ]
initposstd: [ 1.0, 1.0, 2.0 ]
initvelstd: [ 0.2, 0.2, 0.2 ]
initattstd: [ 1.0, 1.0, 2.0 ]
# Phone-class MEMS, gyros uncalibrated: turn-on biases of degrees per second.
initbgstd: [ 7200, 7200, 7200 ]
initbastd: [ 30000, 30000, 30000 ]
initsgstd: [ 5000, 5000, 5000 ]
initsastd: [ 5000, 5000, 5000 ]
imunoise:
  arw: [ 0.5, 0.5, 0.5 ]
  vrw: [ 0.2, 0.2, 0.2 ]
  gbstd: [ 50, 50, 50 ]
  abstd: [ 2000, 2000, 2000 ]
  gsstd: [ 3000, 3000, 3000 ]
  asstd: [ 3000, 3000, 3000 ]
  corrtime: 1.0
antlever: [ 0, 0, 0 ]
"""
    with open(os.path.join(out, "kf-gins.yaml"), "w") as f:
        f.write(cfg)
    print(f"wrote {out}: imu.txt ({len(imu) - 1} increments, {rate:.2f} Hz), gnss.txt ({len(gnss)}), "
          f"speed.txt ({len(can)}), truth.nav ({len(ref)}), kf-gins.yaml (start {t0:.3f})")
    print(f"camera mounting relative to the direction of travel: --mount 0,{math.degrees(mp):.2f},{math.degrees(my):.2f}")


if __name__ == "__main__":
    main()
