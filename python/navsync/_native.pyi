"""Native half of navsync (Rust, pyo3); use the functions of ``navsync``."""

from typing import List, Optional, Tuple

class NavsyncError(Exception):
    """An error of the navsync library, naming the file and line or setting at fault."""

def version() -> str: ...
def set_io_threads(enabled: bool) -> None: ...
def io_threads() -> bool: ...
def simulate(
    output_dir: str,
    scenario: str = "demo",
    seed: Optional[int] = None,
    duration_s: Optional[float] = None,
    imu_grade: Optional[str] = None,
    overrides: List[str] = ...,
) -> str: ...
def sync(
    rig: str,
    output_dir: str,
    mode: str = "auto",
    causal: bool = False,
    truth: Optional[str] = None,
    kfgins_template: Optional[str] = None,
) -> str: ...
def fuse(
    config: str,
    output_dir: Optional[str] = None,
    smooth: bool = False,
    estimate_time_offset: bool = False,
    zupt: bool = False,
    align: bool = False,
    outages: Optional[Tuple[float, float, float]] = None,
    imu_path: Optional[str] = None,
    gnss_path: Optional[str] = None,
    week: int = 0,
) -> str: ...
def evaluate(truth: str, nav: str, outages: str = "") -> str: ...
def process_drive_json(
    input_dir: str,
    output_dir: str,
    smooth: bool = True,
    estimate_time_offset: bool = True,
    html: bool = True,
) -> str: ...
def read_nav_bytes(path: str) -> Tuple[bytes, int]: ...

class NativeNavigator:
    def __init__(self, config: str, week: int = 0) -> None: ...
    def push_gnss(self, rows: bytes) -> int: ...
    def push_imu(self, rows: bytes) -> bytes: ...
    def finish(self) -> str: ...
