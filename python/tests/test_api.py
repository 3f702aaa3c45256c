"""The bindings against the CLI: same numbers, and bad input raises."""

from __future__ import annotations

import json
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import navsync
from conftest import SHARED_DRIVE


def run_cli(cli: str, *args: str) -> str:
    r = subprocess.run([cli, *args], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_version_and_columns():
    assert navsync.version().count(".") == 2
    assert navsync.NAV_COLUMNS[:5] == ("week", "sow_s", "lat_deg", "lon_deg", "h_m")


def test_simulate_fuse_evaluate_equal_the_cli(tmp_path, drives, cli):
    d = drives[0]
    # Synchronize the rig log, then fuse the synchronized files.
    s = navsync.sync(
        d / "rig.csv",
        tmp_path / "synced",
        truth=d / "imu_times_truth.txt",
        kfgins_template=d / "kf-gins.yaml",
    )
    assert s.report["mode"] == "hw"
    assert s.report["truth"]["rms_us"] < 5.0
    imu, gnss = s.imu, s.gnss
    assert list(imu.columns) == list(navsync.IMU_COLUMNS) and len(imu) > 90 * 190
    assert imu["sow_s"].is_monotonic_increasing
    assert list(gnss.columns)[:4] == ["sow_s", "lat_deg", "lon_deg", "h_m"] and len(gnss) > 80
    cfg = s.output_dir / "kf-gins.yaml"
    res = navsync.fuse(
        cfg,
        tmp_path / "py",
        imu_path=s.output_dir / "imu.txt",
        gnss_path=s.output_dir / "gnss.txt",
        smooth=True,
    )
    nav = res.nav
    assert list(nav.columns) == list(navsync.NAV_COLUMNS)
    assert len(nav) > 90 * 190 and np.isfinite(nav.to_numpy()).all()
    assert res.forward_nav is not None
    ev = navsync.evaluate(res.output_dir / "navresult.nav", d / "truth.nav")
    # The CLI on the same files.
    run_cli(cli, "sync", str(d / "rig.csv"), "--output", str(tmp_path / "csync"),
            "--kfgins-template", str(d / "kf-gins.yaml"))
    run_cli(cli, "fuse", "--config", str(tmp_path / "csync" / "kf-gins.yaml"),
            "--output", str(tmp_path / "cli"), "--smooth")
    out = run_cli(cli, "eval", "--truth", str(d / "truth.nav"),
                  "--nav", str(tmp_path / "cli" / "navresult.nav"),
                  "--json", str(tmp_path / "eval.json"))
    cli_ev = json.loads((tmp_path / "eval.json").read_text())
    # (The CLI scores forward/ beside a smoothed solution too.)
    cli_forward = cli_ev.pop("forward")
    assert ev == cli_ev
    assert navsync.evaluate(res.forward_nav, d / "truth.nav")["epochs_compared"] == (
        cli_forward["epochs_compared"]
    )
    # The printed line, to its last digit.
    line = next(l for l in out.splitlines() if l.startswith("position horizontal"))
    assert f"{ev['pos_horizontal_m']['rms']:.4f}" == line.split()[3]
    assert (tmp_path / "py" / "navresult.nav").read_bytes() == (
        tmp_path / "cli" / "navresult.nav"
    ).read_bytes()


@pytest.mark.skipif(not SHARED_DRIVE.is_dir(), reason="../shared/data not present")
def test_shared_drive_equals_the_cli(tmp_path, cli):
    cfg = SHARED_DRIVE / "kf-gins.yaml"
    res = navsync.fuse(cfg, tmp_path / "py", outages=(180, 60, 120))
    run_cli(cli, "fuse", "--config", str(cfg), "--output", str(tmp_path / "cli"),
            "--outage-period", "180", "--outage-len", "60", "--outage-first", "120")
    outages = res.summary["outages"]
    ev = navsync.evaluate(res.nav, SHARED_DRIVE / "truth.nav", outages=outages)
    run_cli(cli, "eval", "--truth", str(SHARED_DRIVE / "truth.nav"),
            "--nav", str(tmp_path / "cli" / "navresult.nav"), "--outages", outages,
            "--json", str(tmp_path / "eval.json"))
    cli_ev = json.loads((tmp_path / "eval.json").read_text())
    # Through a DataFrame and back (9 decimals, as the file): equal to print precision.
    for k in ("pos_horizontal_m", "pos_3d_m", "yaw_deg"):
        assert f"{ev[k]['rms']:.4f}" == f"{cli_ev[k]['rms']:.4f}", k
    assert f"{ev['outage_rms_max_horizontal_m']:.3f}" == f"{cli_ev['outage_rms_max_horizontal_m']:.3f}"
    # And from the file itself: identical.
    assert navsync.evaluate(res.output_dir / "navresult.nav", SHARED_DRIVE / "truth.nav",
                            outages=outages) == cli_ev


def test_process_drive_row(tmp_path, drives):
    row = navsync.process_drive(drives[1], tmp_path / "out")
    assert row["ok"], row["error"]
    assert row["sync_mode"] == "hw" and row["imu_lost"] == 0
    assert 0 < row["pos_horizontal_rms_m"] < 0.5
    assert row["verdict"] in ("good", "usable with caution", "poor")
    assert (tmp_path / "out" / "report.html").is_file()
    again = navsync.process_drive(drives[1], tmp_path / "out")
    assert again["pos_horizontal_rms_m"] == row["pos_horizontal_rms_m"]


def test_io_threads_switch_keeps_the_results(tmp_path, drives):
    # Readers and writers inline (a fleet task on one core) or threaded:
    # the same files.
    previous = navsync.set_io_threads(False)
    try:
        inline = navsync.process_drive(drives[2], tmp_path / "inline", html=False)
        assert navsync.set_io_threads(True) is False
        threaded = navsync.process_drive(drives[2], tmp_path / "threaded", html=False)
    finally:
        navsync.set_io_threads(previous)
    assert inline["ok"] and threaded["ok"]
    for f in ("synced/imu.txt", "fused/navresult.nav", "fused/forward/navresult.nav", "fused/std.txt"):
        assert (tmp_path / "inline" / f).read_bytes() == (tmp_path / "threaded" / f).read_bytes(), f


def test_gil_is_released(drives, tmp_path):
    # A Python thread keeps running while a drive is processed.
    ticks = []
    stop = threading.Event()

    def tick():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.005)

    t = threading.Thread(target=tick)
    t.start()
    t0 = time.perf_counter()
    navsync.process_drive(drives[2], tmp_path / "o", html=False)
    t1 = time.perf_counter()
    stop.set()
    t.join()
    during = [x for x in ticks if t0 < x < t1]
    assert len(during) >= 0.3 * (t1 - t0) / 0.005, (len(during), t1 - t0)


# --- bad input -------------------------------------------------------------


def test_missing_files_raise(tmp_path):
    with pytest.raises(FileNotFoundError, match="config"):
        navsync.fuse(tmp_path / "nope.yaml", tmp_path)
    with pytest.raises(FileNotFoundError):
        navsync.sync(tmp_path / "rig.csv", tmp_path / "o")
    with pytest.raises(FileNotFoundError):
        navsync.read_nav(tmp_path / "x.nav")
    row = navsync.process_drive(tmp_path / "nothing", tmp_path / "o")
    assert not row["ok"] and "not a folder" in row["error"]


def test_library_errors_carry_file_and_line(tmp_path):
    bad = tmp_path / "bad.nav"
    bad.write_text("0 1 2 3 4 5 6 7 8 9 10\n0 1 2 3 4 5 6 7 8 9 10\n0 1 2 x 4 5 6 7 8 9 10\n")
    with pytest.raises(navsync.NavsyncError, match=r"bad\.nav:3: 'x' is not a number"):
        navsync.read_nav(bad)
    short = tmp_path / "short.nav"
    short.write_text("0 1 2\n")
    with pytest.raises(navsync.NavsyncError, match=r"short\.nav:1: expected 11 columns"):
        navsync.read_nav(short)
    cfg = tmp_path / "kf.yaml"
    cfg.write_text("imupath: nothing.txt\n")
    with pytest.raises(navsync.NavsyncError, match="kf.yaml"):
        navsync.fuse(cfg, tmp_path / "o")
    rig = tmp_path / "rig.csv"
    rig.write_text("garbage\n")
    with pytest.raises(navsync.NavsyncError, match="rig.csv"):
        navsync.sync(rig, tmp_path / "s")


def test_bad_arrays_and_arguments_raise(tmp_path, drives):
    truth = drives[0] / "truth.nav"
    with pytest.raises(ValueError, match=r"shape \(N, 11\)"):
        navsync.evaluate(np.zeros((10, 7)), truth)
    with pytest.raises(ValueError, match=r"shape \(N, 11\)"):
        navsync.evaluate(np.zeros(11), truth)
    a = navsync.read_nav(truth).to_numpy()
    a[5, 3] = np.nan
    with pytest.raises(ValueError, match="non-finite value in row 5"):
        navsync.evaluate(a, truth)
    with pytest.raises(ValueError, match="lacks columns"):
        navsync.evaluate(pd.DataFrame({"x": [1.0]}), truth)
    with pytest.raises(ValueError, match="mode 'bogus'"):
        navsync.sync(drives[0] / "rig.csv", tmp_path / "s", mode="bogus")
    with pytest.raises(ValueError, match="outages"):
        navsync.fuse(drives[0] / "kf-gins.yaml", tmp_path / "o", outages=(60, 90, 0))
    with pytest.raises(ValueError, match="outages"):
        navsync.fuse(drives[0] / "kf-gins.yaml", tmp_path / "o", outages=(np.nan, 1, 0))
    with pytest.raises(ValueError, match="duration_s"):
        navsync.simulate(tmp_path / "s", duration_s=float("nan"))
    with pytest.raises(navsync.NavsyncError):
        navsync.simulate(tmp_path / "s", "no-such-scenario")
    with pytest.raises(TypeError):
        navsync.fuse(42)  # type: ignore[arg-type]
    # An array round trip scores the same as the file.
    good = navsync.read_nav(truth)
    assert navsync.evaluate(good, truth)["pos_3d_m"]["rms"] < 1e-6


def test_navigator_stream_equals_fuse(tmp_path, drives):
    """Blocks of IMU increments and fixes through the streaming Navigator give
    `fuse`'s solution on the same files, epoch for epoch."""
    d = drives[1]
    s = navsync.sync(d / "rig.csv", tmp_path / "synced", kfgins_template=d / "kf-gins.yaml")
    cfg = s.output_dir / "kf-gins.yaml"
    res = navsync.fuse(cfg, tmp_path / "batch", imu_path=s.output_dir / "imu.txt",
                       gnss_path=s.output_dir / "gnss.txt")
    imu, gnss = s.imu, s.gnss
    nav = navsync.Navigator(cfg)
    assert nav.push_gnss(gnss[list(navsync.GNSS_COLUMNS)].to_numpy()) == len(gnss)
    parts = [nav.push_imu(imu.iloc[i:i + 1000].to_numpy()) for i in range(0, len(imu), 1000)]
    streamed = pd.concat(parts, ignore_index=True)
    summary = nav.finish()
    assert summary["fixes_weighed"] >= len(gnss) - 2
    batch = res.nav
    assert list(streamed.columns) == list(navsync.STREAM_COLUMNS)
    assert len(streamed) == len(batch)
    # The file is written to 9 decimals in degrees and 4 in metres.
    assert np.allclose(streamed["sow_s"], batch["sow_s"], atol=1e-6)
    assert np.allclose(streamed["lat_deg"], batch["lat_deg"], atol=1e-8)
    assert np.allclose(streamed["lon_deg"], batch["lon_deg"], atol=1e-8)
    assert np.allclose(streamed["h_m"], batch["h_m"], atol=1e-3)
    assert np.allclose(streamed["yaw_deg"], batch["yaw_deg"], atol=1e-6)
    with pytest.raises(navsync.NavsyncError, match="finished"):
        nav.push_imu(imu.iloc[:1].to_numpy())


def test_navigator_bad_input_raises(tmp_path, drives):
    nav = navsync.Navigator(drives[0] / "kf-gins.yaml")
    with pytest.raises(ValueError, match=r"shape \(n, 7\)"):
        nav.push_imu(np.zeros((3, 6)))
    bad = np.zeros((2, 7))
    bad[1, 3] = np.nan
    with pytest.raises(ValueError, match="row 1 column 3 is not a finite"):
        nav.push_imu(bad)
    with pytest.raises(ValueError, match="σ must be positive"):
        nav.push_gnss(np.array([[100.0, 30.0, 114.0, 20.0, 0.0, 0.1, 0.1]]))
    with pytest.raises(FileNotFoundError):
        navsync.Navigator(tmp_path / "missing.yaml")
