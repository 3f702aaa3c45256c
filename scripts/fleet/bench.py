#!/usr/bin/env python3
"""Scale figures of the fleet function (docs/python.md):

1. N simulated drives (default 200 × 600 s, the demo rig: ADIS16465-class
   IMU at 200 Hz, 1PPS + drifting counter, 1 Hz RTK, two 30 s outages)
   through ``navsync.fleet.process`` on a Dask LocalCluster of 1 and of 2
   worker processes (1 thread each): wall time, drives per minute,
   speed-up, peak memory per worker; once with single-core tasks (each
   drive's readers and writers inline) and once with threaded tasks (the
   fleet's default: readers and writers on threads of their own, about 1.3
   cores per drive);
2. the per-drive cost of the Python layer: the same M drives through
   ``navsync batch --jobs 1`` (the CLI), ``process_drive`` in this
   process, and the 1-worker cluster.

    target/venv/bin/python scripts/fleet/bench.py [--drives 200] [--duration 600]
        [--overhead-drives 20] [--work target/fleet-bench] [--cli target/release/navsync]
        [--tasks single,threaded]

Needs the package installed (pip install ./python) and the CLI built
(cargo build --release). Writes WORK/bench.json. The drives take about
55 MB each (the IMU/GNSS files the fleet does not read are removed), and
each cluster run's outputs are removed after it is measured.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import time
from pathlib import Path

import navsync
from navsync import fleet

REPO = Path(__file__).resolve().parents[2]


def make_drive(out: str, seed: int, duration_s: float) -> str:
    navsync.simulate(out, "demo", seed=seed, duration_s=duration_s)
    # Files the drive task does not read (it syncs rig.csv itself).
    for f in ("imu.txt", "gnss.txt", "gnss_posvel.txt", "imu_err_truth.txt"):
        p = Path(out) / f
        if p.exists():
            p.unlink()
    return out


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def loadavg() -> float:
    return os.getloadavg()[0]


def run_cluster(drives, workers: int, out: Path, single_core: bool = True) -> dict:
    from distributed import Client, LocalCluster

    with LocalCluster(
        n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, Client(cluster) as client:
        client.wait_for_workers(workers)
        base = client.run(peak_rss_mb)
        load0 = loadavg()
        t0 = time.perf_counter()
        df = fleet.process(drives, client, out, html=False, single_core=single_core)
        wall = time.perf_counter() - t0
        peaks = client.run(peak_rss_mb)
    shutil.rmtree(out, ignore_errors=True)
    assert df["ok"].all(), df[~df["ok"]][["drive", "error"]]
    return {
        "workers": workers,
        "single_core_tasks": single_core,
        "drives": len(df),
        "wall_s": wall,
        "drives_per_min": 60 * len(df) / wall,
        "task_wall_mean_s": float(df["task_wall_s"].mean()),
        "task_cpu_mean_s": float(df["task_cpu_s"].mean()),
        "cpu_share": float(df["task_cpu_s"].sum() / (workers * wall)),
        "worker_peak_rss_mb": sorted(peaks.values()),
        "worker_idle_rss_mb": sorted(base.values()),
        "load_before": load0,
        "load_after": loadavg(),
        "pos_horizontal_rms_m_median": float(df["pos_horizontal_rms_m"].median()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drives", type=int, default=200)
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--overhead-drives", type=int, default=20)
    ap.add_argument("--work", type=Path, default=REPO / "target" / "fleet-bench")
    ap.add_argument("--cli", type=Path, default=REPO / "target" / "release" / "navsync")
    ap.add_argument("--skip", default="", help="comma list of: w1,w2,overhead")
    ap.add_argument(
        "--tasks",
        default="single,threaded",
        help="comma list, run in this order, of: single (each task on one core: readers and "
        "writers inline), threaded (the fleet default: readers and writers on threads of their own)",
    )
    a = ap.parse_args()
    skip = set(filter(None, a.skip.split(",")))
    a.work.mkdir(parents=True, exist_ok=True)
    data = a.work / f"drives-{int(a.duration)}s"
    data.mkdir(exist_ok=True)
    drives = [str(data / f"drive-{s:03d}") for s in range(1, a.drives + 1)]
    todo = [(d, s) for s, d in enumerate(drives, 1) if not (Path(d) / "truth.nav").is_file()]
    if todo:
        t0 = time.perf_counter()
        from distributed import Client, LocalCluster

        with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as c, Client(c) as cl:
            cl.gather([cl.submit(make_drive, d, s, a.duration, pure=False) for d, s in todo])
        print(f"simulated {len(todo)} drives of {a.duration:.0f} s in {time.perf_counter() - t0:.1f} s")
    res: dict = {
        "host": platform.node(),
        "cpus": os.cpu_count(),
        "navsync": navsync.version(),
        "drive_duration_s": a.duration,
    }
    for mode in filter(None, a.tasks.split(",")):
        single = {"single": True, "threaded": False}[mode]
        r: dict = {}
        if "w1" not in skip:
            r["one_worker"] = run_cluster(drives, 1, a.work / "out-1", single)
            print(f"{mode}, 1 worker:", json.dumps(r["one_worker"]))
        if "w2" not in skip:
            r["two_workers"] = run_cluster(drives, 2, a.work / "out-2", single)
            print(f"{mode}, 2 workers:", json.dumps(r["two_workers"]))
        if "one_worker" in r and "two_workers" in r:
            r["speedup"] = r["one_worker"]["wall_s"] / r["two_workers"]["wall_s"]
            print(f"{mode} tasks: speed-up 2 vs 1 workers: {r['speedup']:.2f}")
        res[f"{mode}_tasks"] = r
    if "overhead" not in skip:
        sub = drives[: a.overhead_drives]
        m = len(sub)
        out = a.work / "out-overhead"
        t0 = time.perf_counter()
        r = subprocess.run(
            [str(a.cli), "batch", *sub, "--jobs", "1", "--no-html", "--output", str(out / "cli")],
            capture_output=True,
            text=True,
        )
        cli_wall = time.perf_counter() - t0
        assert r.returncode == 0, r.stderr
        t0 = time.perf_counter()
        rows = [navsync.process_drive(d, out / "py" / Path(d).name, html=False) for d in sub]
        py_wall = time.perf_counter() - t0
        assert all(x["ok"] for x in rows)
        t0 = time.perf_counter()
        df = fleet.process(sub, None, out / "fleet-inproc", html=False)
        fleet_inproc = time.perf_counter() - t0
        cl1 = run_cluster(sub, 1, out / "cluster")
        cli_rows = json.loads((out / "cli" / "batch.json").read_text())
        same = all(
            c["pos_horizontal_rms_m"] == p["pos_horizontal_rms_m"] for c, p in zip(cli_rows, rows)
        )
        shutil.rmtree(out, ignore_errors=True)
        res["overhead"] = {
            "drives": m,
            "cli_batch_per_drive_s": cli_wall / m,
            "python_process_drive_per_drive_s": py_wall / m,
            "fleet_in_process_per_drive_s": fleet_inproc / m,
            "fleet_1_worker_cluster_per_drive_s": cl1["wall_s"] / m,
            "cli_equals_python": same,
            "median_drive_wall_s": statistics.median(x["wall_s"] for x in rows),
        }
        print("overhead:", json.dumps(res["overhead"]))
    (a.work / "bench.json").write_text(json.dumps(res, indent=2))
    print(f"wrote {a.work / 'bench.json'}")


if __name__ == "__main__":
    main()
