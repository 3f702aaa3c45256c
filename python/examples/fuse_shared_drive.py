"""Fuses the shared simulated drive (ADIS16465-class IMU, 1 Hz RTK) with
GNSS outages of 60 s every 180 s, forward and smoothed, scores both against
the drive's truth and plots the trajectory and the horizontal error.

    python python/examples/fuse_shared_drive.py [--data DIR] [--output fuse_shared_drive.png]

The drive is found at ../shared/data/sim-drive-adis16465 from the
repository root unless --data says otherwise.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import navsync  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
DEFAULT_DATA = REPO.parent / "shared" / "data" / "sim-drive-adis16465"
R_EARTH_M = 6378137.0


def local_ne(df, lat0, lon0):
    """North/east (m) from a reference point (small-area approximation)."""
    n = np.radians(df["lat_deg"] - lat0) * R_EARTH_M
    e = np.radians(df["lon_deg"] - lon0) * R_EARTH_M * np.cos(np.radians(lat0))
    return n.to_numpy(), e.to_numpy()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--output", type=Path, default=Path("fuse_shared_drive.png"))
    a = ap.parse_args()
    cfg = a.data / "kf-gins.yaml"
    truth = navsync.read_nav(a.data / "truth.nav")
    with tempfile.TemporaryDirectory(prefix="navsync-example-") as tmp:
        res = navsync.fuse(cfg, Path(tmp) / "fused", smooth=True, outages=(180, 60, 120))
        outages = res.summary["outages"]
        smoothed, forward = res.nav, res.forward_nav
        ev_s = navsync.evaluate(smoothed, truth, outages=outages)
        ev_f = navsync.evaluate(forward, truth, outages=outages)
    print(f"{'':24}{'forward':>10}{'smoothed':>10}")
    for k, label in [("pos_horizontal_m", "horizontal RMS (m)"), ("pos_3d_m", "3D RMS (m)")]:
        print(f"{label:24}{ev_f[k]['rms']:>10.4f}{ev_s[k]['rms']:>10.4f}")
    print(
        f"{'outage drift RMS (m)':24}{ev_f['outage_rms_max_horizontal_m']:>10.3f}"
        f"{ev_s['outage_rms_max_horizontal_m']:>10.3f}"
    )

    lat0, lon0 = truth["lat_deg"].iloc[0], truth["lon_deg"].iloc[0]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 5.5))
    for df, name, style in [(truth, "truth", "k-"), (forward, "forward", "C1-"), (smoothed, "smoothed", "C0--")]:
        n, e = local_ne(df, lat0, lon0)
        ax1.plot(e, n, style, lw=1, label=name)
    ax1.set(xlabel="east (m)", ylabel="north (m)", title="trajectory (60 s GNSS outages every 180 s)")
    ax1.set_aspect("equal", adjustable="datalim")
    ax1.legend()
    t_sow = truth["sow_s"].to_numpy()
    for df, name, color in [(forward, "forward", "C1"), (smoothed, "smoothed", "C0")]:
        n, e = local_ne(df, lat0, lon0)
        tn = np.interp(df["sow_s"], t_sow, local_ne(truth, lat0, lon0)[0])
        te = np.interp(df["sow_s"], t_sow, local_ne(truth, lat0, lon0)[1])
        ax2.semilogy(df["sow_s"] - t_sow[0], np.hypot(n - tn, e - te) + 1e-4, color=color, lw=0.8, label=name)
    for part in filter(None, outages.split(",")):
        s, length = (float(x) for x in part.split(":"))
        ax2.axvspan(s - t_sow[0], s - t_sow[0] + length, color="0.85")
    ax2.set(xlabel="time (s)", ylabel="horizontal error (m)", title="horizontal error (grey: outages)")
    ax2.legend()
    fig.tight_layout()
    fig.savefig(a.output, dpi=110)
    print(f"wrote {a.output}")


if __name__ == "__main__":
    main()
