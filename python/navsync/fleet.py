"""A fleet of drives on a Dask cluster: one drive, one task.

Each task runs :func:`navsync.process_drive` (sync → fuse → smooth →
score → verdict and report) on one drive folder and writes that drive's
output folder, which it first builds under a temporary name and then
renames into place: a task retried after its worker died leaves no half
folder, and overwrites its own folder only. The table is assembled from
the tasks' results in the order of ``paths``, so each drive is one row,
whatever the retries.

Works unchanged on a ``LocalCluster`` and on any Dask cluster whose
workers have this package installed and see the paths (shared file system
or object storage mounted at the same place).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
import uuid
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Union

import pandas as pd

from . import process_drive, set_io_threads

__all__ = ["drive_task", "output_names", "process"]

PathLike = Union[str, "os.PathLike[str]"]


def output_names(paths: Sequence[PathLike]) -> List[str]:
    """One output folder name per drive: the drive folder's name, with its
    position appended where two drives share a name."""
    names = [Path(os.fspath(p)).name or "drive" for p in paths]
    seen: Dict[str, int] = {}
    for n in names:
        seen[n] = seen.get(n, 0) + 1
    return [n if seen[n] == 1 else f"{n}-{i}" for i, n in enumerate(names)]


def drive_task(
    input_dir: str,
    output_dir: str,
    smooth: bool = True,
    estimate_time_offset: bool = True,
    html: bool = True,
    single_core: bool = False,
) -> Dict[str, Any]:
    """One drive into ``output_dir``, atomically: built in a temporary
    sibling folder, then moved into place (replacing an earlier attempt's).
    ``single_core``: file readers and writers run inline, so the task uses
    one core (see :func:`navsync.set_io_threads`)."""
    t0 = time.perf_counter()
    cpu0 = time.process_time()
    final = Path(output_dir)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.parent / f".{final.name}.tmp-{uuid.uuid4().hex[:12]}"
    previous = set_io_threads(not single_core)
    try:
        row = process_drive(
            input_dir,
            tmp,
            smooth=smooth,
            estimate_time_offset=estimate_time_offset,
            html=html,
        )
    finally:
        set_io_threads(previous)
    if final.exists():
        shutil.rmtree(final)
    if tmp.exists():
        os.replace(tmp, final)
        # drive.json names the folder the drive was built in: name the final one.
        j = final / "drive.json"
        if j.is_file():
            row["drive"] = final.name
            row["output_dir"] = str(final)
            j.write_text(json.dumps(row, indent=2))
    # The drive's name in the table: its output folder's (unique per fleet).
    row["drive"] = final.name
    row["output_dir"] = str(final)
    row["pid"] = os.getpid()
    row["task_wall_s"] = time.perf_counter() - t0
    # CPU seconds of the worker process over the task (all its threads).
    row["task_cpu_s"] = time.process_time() - cpu0
    return row


def process(
    paths: Sequence[PathLike],
    client: Any,
    output_root: PathLike,
    *,
    smooth: bool = True,
    estimate_time_offset: bool = True,
    html: bool = True,
    retries: int = 2,
    single_core: bool = False,
) -> pd.DataFrame:
    """Processes every drive folder in ``paths`` on ``client``'s cluster.

    ``client``: a ``distributed.Client`` (``None`` runs the drives one after
    the other in this process). Each drive's files go to
    ``output_root/<drive name>``. Returns one row per drive, in the order
    of ``paths``: ``drive``, ``ok``, ``error``, accuracy against
    ``truth.nav`` (``pos_horizontal_rms_m``, ``pos_3d_rms_m``,
    ``outage_drift_rms_m``, …), sync health (``sync_mode``, ``imu_lost``,
    ``stamp_bound_max_us``, ``stamp_error_rms_us``), the estimated time
    offset (``time_offset_ms``), the report's ``verdict``, ``wall_s`` and
    ``output_dir``. A failing drive is a row with its error.

    ``single_core``: each task runs its file readers and writers inline
    and so uses one core, as a scheduler that pins a core per task counts
    it. By default (``False``) a task overlaps reading and writing with the
    filter on threads of its own (about 1.3 cores): measured on 2 cores,
    that is 28 % faster with 1 worker and still 5 % faster with 2 workers
    filling the machine (docs/python.md, "Scale figures").
    """
    root = Path(os.fspath(output_root)).resolve()
    root.mkdir(parents=True, exist_ok=True)
    inputs = [os.path.abspath(os.fspath(p)) for p in paths]
    outs = [str(root / n) for n in output_names(paths)]
    kw = dict(
        smooth=smooth,
        estimate_time_offset=estimate_time_offset,
        html=html,
        single_core=single_core,
    )
    if client is None:
        rows = [drive_task(i, o, **kw) for i, o in zip(inputs, outs)]
    else:
        # Keys name the drive and its output, so resubmitting the same
        # fleet reuses finished tasks instead of running them twice.
        keys = [
            "navsync-drive-" + hashlib.sha1(repr((i, o, sorted(kw.items()))).encode()).hexdigest()[:16]
            for i, o in zip(inputs, outs)
        ]
        futures = [
            client.submit(drive_task, i, o, key=k, retries=retries, pure=False, **kw)
            for i, o, k in zip(inputs, outs, keys)
        ]
        rows = client.gather(futures)
    # Temporary folders of attempts whose worker died.
    for p in root.glob(".*.tmp-*"):
        shutil.rmtree(p, ignore_errors=True)
    return pd.DataFrame(rows)
