"""The fleet on a Dask LocalCluster: one row per drive, even when a worker
is killed in the middle of the run."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

import navsync
from navsync import fleet

distributed = pytest.importorskip("distributed")


@pytest.fixture()
def client():
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    )
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def test_fleet_rows_equal_single_drive_runs(tmp_path, drives, client):
    paths = drives + [tmp_path / "missing"]
    df = fleet.process(paths, client, tmp_path / "fleet", html=False)
    assert list(df["drive"]) == [p.name for p in paths]
    assert df["ok"].tolist() == [True] * len(drives) + [False]
    assert "not a folder" in df["error"].iloc[-1]
    for col in ("pos_horizontal_rms_m", "sync_mode", "time_offset_ms", "verdict", "wall_s"):
        assert col in df.columns
    # A drive alone, in this process: the same numbers.
    alone = navsync.process_drive(drives[0], tmp_path / "alone", html=False)
    assert df["pos_horizontal_rms_m"].iloc[0] == alone["pos_horizontal_rms_m"]
    assert df["time_offset_ms"].iloc[0] == alone["time_offset_ms"]
    # Both workers took part.
    assert df["pid"].iloc[:-1].nunique() == 2
    assert not list((tmp_path / "fleet").glob(".*.tmp-*"))


def test_fleet_survives_a_killed_worker(tmp_path, drives, client):
    # Twelve drives: the four fixtures three times over, each its own folder.
    paths = []
    for k in range(3):
        for d in drives:
            link = tmp_path / "in" / f"{d.name}-copy{k}"
            link.parent.mkdir(exist_ok=True)
            os.symlink(d, link)
            paths.append(link)
    out = tmp_path / "fleet"
    killed = []

    def killer():
        # Once the first drive is written, kill a worker busy with another.
        deadline = time.time() + 60
        while time.time() < deadline and not any(out.glob("*/drive.json")):
            time.sleep(0.02)
        pids = client.run(os.getpid)
        victim = sorted(pids.values())[0]
        os.kill(victim, signal.SIGKILL)
        killed.append(victim)

    t = threading.Thread(target=killer)
    t.start()
    df = fleet.process(paths, client, out, html=False, retries=3)
    t.join()
    assert killed
    assert len(df) == len(paths)
    assert sorted(df["drive"]) == sorted(p.name for p in paths)
    assert df["drive"].is_unique
    assert df["ok"].all(), df[~df["ok"]][["drive", "error"]]
    # Each drive's folder once, complete, no leftovers of the killed attempt.
    folders = sorted(p.name for p in out.iterdir())
    assert folders == sorted(p.name for p in paths)
    for p in out.iterdir():
        assert (p / "fused" / "navresult.nav").is_file() and (p / "drive.json").is_file()
    # Copies of one drive agree, whichever worker (or attempt) ran them.
    by_src = df.assign(src=df["drive"].str.replace(r"-copy\d$", "", regex=True))
    assert (by_src.groupby("src")["pos_horizontal_rms_m"].nunique() == 1).all()
