"""navsync: GNSS/INS integrated navigation with first-class time synchronization.

The functions here call the navsync Rust library (the same code as the
``navsync`` command line tool) with the GIL released, and return pandas
DataFrames with unit-suffixed columns and plain dicts of figures.

>>> import navsync
>>> navsync.simulate("drive", duration_s=120, seed=1)          # doctest: +SKIP
>>> res = navsync.fuse("drive/kf-gins.yaml", "out")             # doctest: +SKIP
>>> res.nav.head(); res.summary["stats"]["gnss_fixes_used"]     # doctest: +SKIP
>>> navsync.evaluate("out/navresult.nav", "drive/truth.nav")    # doctest: +SKIP

Errors of the library are raised as :class:`NavsyncError` with the file and
line (or setting) at fault; bad arguments as :class:`ValueError`.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Optional, Tuple, Union

import numpy as np
import pandas as pd

from . import _native
from ._native import NavsyncError

__all__ = [
    "NAV_COLUMNS",
    "FuseResult",
    "GNSS_COLUMNS",
    "IMU_COLUMNS",
    "Navigator",
    "NavsyncError",
    "STREAM_COLUMNS",
    "SyncResult",
    "evaluate",
    "fuse",
    "nav_frame",
    "process_drive",
    "read_nav",
    "set_io_threads",
    "simulate",
    "sync",
    "version",
]

PathLike = Union[str, "os.PathLike[str]"]

#: Columns of an 11-column navigation file (KF-GINS ``navresult.nav``).
NAV_COLUMNS = (
    "week",
    "sow_s",
    "lat_deg",
    "lon_deg",
    "h_m",
    "vn_mps",
    "ve_mps",
    "vd_mps",
    "roll_deg",
    "pitch_deg",
    "yaw_deg",
)


def version() -> str:
    """The navsync library version this package was built from."""
    return _native.version()


def set_io_threads(enabled: bool) -> bool:
    """Whether file readers and writers of later runs in this process get
    their own threads (``True``, the default: a drive then uses about 1.3
    cores) or run inline on the calling thread (``False``: one drive, one
    core, for a scheduler that pins a core per task). Results are the same
    either way. Returns the previous setting. The environment
    variable ``NAVSYNC_IO_THREADS=0`` sets ``False`` for a whole process."""
    previous = _native.io_threads()
    _native.set_io_threads(bool(enabled))
    return previous


def _path(p: PathLike, what: str, must_exist: bool = True) -> str:
    if not isinstance(p, (str, os.PathLike)):
        raise TypeError(f"{what}: expected a path, got {type(p).__name__}")
    s = os.fspath(p)
    if must_exist and not os.path.exists(s):
        raise FileNotFoundError(f"{what}: {s} does not exist")
    return s


def read_nav(path: PathLike) -> pd.DataFrame:
    """Reads an 11-column navigation file into a DataFrame (:data:`NAV_COLUMNS`)."""
    raw, cols = _native.read_nav_bytes(_path(path, "navigation file"))
    arr = np.frombuffer(raw, dtype="<f8").reshape(-1, cols)
    return nav_frame(arr)


def nav_frame(array: np.ndarray) -> pd.DataFrame:
    """An (N, 11) array of navigation states as a DataFrame (:data:`NAV_COLUMNS`).

    Raises ValueError for another shape or non-finite values.
    """
    a = np.asarray(array, dtype=float)
    if a.ndim != 2 or a.shape[1] != len(NAV_COLUMNS):
        raise ValueError(
            f"navigation array: expected shape (N, {len(NAV_COLUMNS)}) "
            f"({', '.join(NAV_COLUMNS)}), got {a.shape}"
        )
    if not np.isfinite(a).all():
        row = int(np.argwhere(~np.isfinite(a))[0][0])
        raise ValueError(f"navigation array: non-finite value in row {row}")
    df = pd.DataFrame(a, columns=list(NAV_COLUMNS))
    df["week"] = df["week"].astype(np.int64)
    return df


def _write_nav(array: np.ndarray, path: Path) -> None:
    df = nav_frame(array)
    np.savetxt(
        path,
        df.to_numpy(),
        fmt=["%d", "%.9f", "%.12f", "%.12f", "%.6f"] + ["%.9f"] * 6,
    )


def simulate(
    output_dir: PathLike,
    scenario: str = "demo",
    *,
    seed: Optional[int] = None,
    duration_s: Optional[float] = None,
    imu_grade: Optional[str] = None,
    overrides: Tuple[str, ...] = (),
) -> Dict[str, Any]:
    """Simulates a drive with exact truth into ``output_dir`` (``navsync simulate``).

    ``scenario``: a built-in (``test-track``, ``urban``, ``figure8``,
    ``static``, ``demo``, ``hybrid``) or a TOML file; ``overrides``:
    ``KEY=VALUE`` settings as ``--set``. Writes ``rig.csv``, ``kf-gins.yaml``,
    ``imu.txt``, ``gnss.txt``, ``truth.nav``, ``scenario.json``; returns the
    simulator's report.
    """
    return json.loads(
        _native.simulate(
            _path(output_dir, "output_dir", must_exist=False),
            scenario,
            seed,
            duration_s,
            imu_grade,
            list(overrides),
        )
    )


#: Columns of a KF-GINS IMU file: increments over each interval, body FRD.
IMU_COLUMNS = (
    "sow_s",
    "dtheta_x_rad",
    "dtheta_y_rad",
    "dtheta_z_rad",
    "dvel_x_mps",
    "dvel_y_mps",
    "dvel_z_mps",
)

#: Columns of a 7-column KF-GINS GNSS file (then, in 13-column files,
#: velocities and their σ in the KF-GINS C++ order).
GNSS_COLUMNS = ("sow_s", "lat_deg", "lon_deg", "h_m", "sd_n_m", "sd_e_m", "sd_d_m")
GNSS_COLUMNS_13 = (
    "sow_s", "lat_deg", "lon_deg", "h_m", "vn_mps", "ve_mps", "vd_mps",
    "sd_n_m", "sd_e_m", "sd_d_m", "sd_vn_mps", "sd_ve_mps", "sd_vd_mps",
)  # fmt: skip


def _read_columns(path: Path, names: Tuple[str, ...]) -> pd.DataFrame:
    df = pd.read_csv(path, sep=r"\s+", header=None, comment="#")
    if df.shape[1] != len(names):
        raise NavsyncError(f"{path}: expected {len(names)} columns, found {df.shape[1]}")
    df.columns = list(names)
    return df


@dataclass
class SyncResult:
    """What :func:`sync` produced."""

    #: ``sync_report.json`` as a dict.
    report: Dict[str, Any]
    #: The output folder (``imu.txt``, ``gnss.txt``, ``imu_times.txt``, …).
    output_dir: Path

    @property
    def imu(self) -> pd.DataFrame:
        """The synchronized IMU increments (:data:`IMU_COLUMNS`), GPS time."""
        return _read_columns(self.output_dir / "imu.txt", IMU_COLUMNS)

    @property
    def gnss(self) -> pd.DataFrame:
        """The GNSS fixes at their time of validity (:data:`GNSS_COLUMNS`)."""
        p = self.output_dir / "gnss.txt"
        with open(p) as f:
            first = next((ln for ln in f if ln.strip() and not ln.startswith("#")), "")
        names = GNSS_COLUMNS_13 if len(first.split()) == 13 else GNSS_COLUMNS
        return _read_columns(p, names)


def sync(
    rig: PathLike,
    output_dir: PathLike,
    *,
    mode: str = "auto",
    causal: bool = False,
    truth: Optional[PathLike] = None,
    kfgins_template: Optional[PathLike] = None,
) -> SyncResult:
    """Puts a raw rig log on GPS time (``navsync sync``).

    ``mode``: ``auto``, ``hw`` (1PPS + counter), ``hybrid`` or ``sw``;
    ``truth``: the simulator's ``imu_times_truth.txt`` to score the stamps;
    ``kfgins_template``: a KF-GINS configuration rewritten for the synced files.
    """
    out = _path(output_dir, "output_dir", must_exist=False)
    text = _native.sync(
        _path(rig, "rig log"),
        out,
        mode,
        causal,
        None if truth is None else _path(truth, "truth"),
        None if kfgins_template is None else _path(kfgins_template, "kfgins_template"),
    )
    return SyncResult(report=json.loads(text), output_dir=Path(out))


@dataclass
class FuseResult:
    """What :func:`fuse` produced."""

    #: ``summary.json`` as a dict (statistics, final biases, time offset, …).
    summary: Dict[str, Any]
    #: The output folder (``navresult.nav``, ``std.txt``, ``imu_err.txt``, …).
    output_dir: Path

    @property
    def nav(self) -> pd.DataFrame:
        """The solution (smoothed, when smoothing ran) as a DataFrame."""
        return read_nav(self.output_dir / "navresult.nav")

    @property
    def forward_nav(self) -> Optional[pd.DataFrame]:
        """The forward filter's solution of a smoothed run, else None."""
        p = self.output_dir / "forward" / "navresult.nav"
        return read_nav(p) if p.is_file() else None


def fuse(
    config: PathLike,
    output_dir: Optional[PathLike] = None,
    *,
    smooth: bool = False,
    estimate_time_offset: bool = False,
    zupt: bool = False,
    align: bool = False,
    outages: Optional[Tuple[float, float, float]] = None,
    imu_path: Optional[PathLike] = None,
    gnss_path: Optional[PathLike] = None,
    week: int = 0,
) -> FuseResult:
    """Fuses IMU and GNSS as ``navsync fuse --config CONFIG`` does.

    ``config``: a KF-GINS YAML configuration (read unchanged; ``imu_path``
    and ``gnss_path`` replace its files); ``output_dir`` defaults to the
    configuration's ``outputpath``. ``outages=(period_s, len_s, first_s)``
    withholds GNSS as ``--outage-period/--outage-len/--outage-first``;
    ``smooth`` runs the forward–backward smoother (forward solution in
    ``forward/``). Writes the same files and ``summary.json`` as the CLI.
    """
    if outages is not None:
        o = tuple(float(x) for x in outages)
        if len(o) != 3 or not all(np.isfinite(o)):
            raise ValueError("outages: expected three finite numbers (period_s, len_s, first_s)")
        outages = o  # type: ignore[assignment]
    text = _native.fuse(
        _path(config, "config"),
        None if output_dir is None else _path(output_dir, "output_dir", must_exist=False),
        smooth,
        estimate_time_offset,
        zupt,
        align,
        outages,
        None if imu_path is None else _path(imu_path, "imu_path"),
        None if gnss_path is None else _path(gnss_path, "gnss_path"),
        int(week),
    )
    summary = json.loads(text)
    return FuseResult(summary=summary, output_dir=Path(summary["output_dir"]))


def _nav_arg(x: Any, what: str, tmp: Path) -> str:
    if isinstance(x, (str, os.PathLike)):
        return _path(x, what)
    if isinstance(x, pd.DataFrame):
        missing = [c for c in NAV_COLUMNS if c not in x.columns]
        if missing:
            raise ValueError(f"{what}: DataFrame lacks columns {missing}")
        x = x[list(NAV_COLUMNS)].to_numpy(dtype=float)
    p = tmp / f"{what}.nav"
    _write_nav(np.asarray(x), p)
    return str(p)


def evaluate(
    nav: Any,
    truth: Any,
    *,
    outages: str = "",
) -> Dict[str, Any]:
    """Scores a solution against a reference, as ``navsync eval`` does.

    ``nav`` and ``truth``: paths of 11-column navigation files, or (N, 11)
    arrays / DataFrames with :data:`NAV_COLUMNS`. ``outages``:
    ``"sow:len,…"`` windows to score the drift in. Returns the report:
    ``pos_horizontal_m``, ``pos_3d_m``, ``yaw_deg``, … each with ``rms``,
    ``max``, ``mean``; ``outage_rms_max_horizontal_m``; ``epochs_compared``.
    """
    import tempfile

    with tempfile.TemporaryDirectory(prefix="navsync-eval-") as d:
        tmp = Path(d)
        n = _nav_arg(nav, "nav", tmp)
        t = _nav_arg(truth, "truth", tmp)
        return json.loads(_native.evaluate(t, n, outages))


def process_drive(
    input_dir: PathLike,
    output_dir: PathLike,
    *,
    smooth: bool = True,
    estimate_time_offset: bool = True,
    html: bool = True,
) -> Dict[str, Any]:
    """One drive end to end, as ``navsync batch`` runs each: sync (when the
    folder has ``rig.csv``) → fuse → smooth → score (``truth.nav``) →
    verdict and ``report.html``. Returns the drive's row; a failure is its
    ``error`` (``ok`` False), not an exception. ``output_dir`` is
    overwritten, so running a drive again gives the same folder.
    """
    return json.loads(
        _native.process_drive_json(
            _path(input_dir, "input_dir", must_exist=False),
            _path(output_dir, "output_dir", must_exist=False),
            smooth,
            estimate_time_offset,
            html,
        )
    )


# The streaming Navigator (push_gnss / push_imu / finish) binds the core
# library's `navsync::navigator::Navigator` when that lands: see
# python/src/lib.rs.


#: Columns of the solutions a :class:`Navigator` returns.
STREAM_COLUMNS = NAV_COLUMNS[1:]


def _rows(array: Any, cols: int, what: str) -> bytes:
    a = np.asarray(array, dtype=np.float64)
    if a.ndim == 1 and a.size == cols:
        a = a.reshape(1, cols)
    if a.ndim != 2 or a.shape[1] != cols:
        raise ValueError(f"{what}: expected an array of shape (n, {cols}), got {a.shape}")
    return np.ascontiguousarray(a, dtype="<f8").tobytes()


class Navigator:
    """The streaming navigator, record by record (or block by block).

    Built on a KF-GINS configuration (noise model, lever arm, initial
    state). Push GNSS fixes no later than the IMU samples that pass their
    time (as a file delivers them; earlier is fine), then IMU increments;
    every IMU epoch returns its solution. The same engine as ``fuse``:
    pushing a drive's files through it gives ``fuse``'s solution.

    >>> nav = navsync.Navigator("drive/kf-gins.yaml")            # doctest: +SKIP
    >>> nav.push_gnss(gnss[["sow_s", "lat_deg", "lon_deg", "h_m",
    ...                     "sd_n_m", "sd_e_m", "sd_d_m"]])       # doctest: +SKIP
    >>> sol = nav.push_imu(imu_block)   # DataFrame, STREAM_COLUMNS  # doctest: +SKIP
    >>> nav.finish()["fixes_weighed"]                             # doctest: +SKIP
    """

    def __init__(self, config: PathLike, week: int = 0) -> None:
        self._native = _native.NativeNavigator(_path(config, "configuration"), int(week))

    def push_gnss(self, fixes: Any) -> int:
        """Fixes, shape (n, 7): sow_s, lat_deg, lon_deg, h_m, sd_n_m, sd_e_m, sd_d_m."""
        return self._native.push_gnss(_rows(fixes, 7, "GNSS fixes"))

    def push_imu(self, increments: Any) -> pd.DataFrame:
        """Increments, shape (n, 7): sow_s, dθx, dθy, dθz (rad), dvx, dvy, dvz
        (m/s), body FRD. Returns the solutions (one per epoch once running)."""
        raw = self._native.push_imu(_rows(increments, 7, "IMU increments"))
        a = np.frombuffer(raw, dtype="<f8").reshape(-1, len(STREAM_COLUMNS))
        return pd.DataFrame(a.copy(), columns=list(STREAM_COLUMNS))

    def finish(self) -> Dict[str, Any]:
        """Ends the stream: fixes weighed and withheld, the filter's statistics."""
        return json.loads(self._native.finish())

