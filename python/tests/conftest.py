"""Shared fixtures: simulated drives (made once per session) and the CLI."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

import navsync

REPO = Path(__file__).resolve().parents[2]
SHARED_DRIVE = REPO.parent / "shared" / "data" / "sim-drive-adis16465"


def cli_path() -> "str | None":
    """The `navsync` binary: $NAVSYNC_BIN, else the repository's release build."""
    p = os.environ.get("NAVSYNC_BIN") or str(REPO / "target" / "release" / "navsync")
    return p if os.path.isfile(p) and os.access(p, os.X_OK) else shutil.which("navsync")


@pytest.fixture(scope="session")
def cli() -> str:
    p = cli_path()
    if p is None:
        pytest.skip("navsync CLI not built (cargo build --release, or set NAVSYNC_BIN)")
    return p


@pytest.fixture(scope="session")
def drives(tmp_path_factory) -> "list[Path]":
    """Four short simulated drives (90 s, demo rig: hardware sync, drifting counter)."""
    root = tmp_path_factory.mktemp("drives")
    out = []
    for seed in range(1, 5):
        d = root / f"drive-{seed}"
        navsync.simulate(d, "demo", seed=seed, duration_s=90)
        out.append(d)
    return out
