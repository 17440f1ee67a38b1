"""Shared fixtures: the real recordings in ../shared/data/real (skipped cleanly when absent)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
REAL = Path(os.environ.get("GPR3D_REAL_DATA", REPO.parent / "shared" / "data" / "real"))


def real_file(rel: str) -> Path:
    """Path of a real recording, or skip the test when the shared data folder is absent."""
    p = REAL / rel
    if not p.exists():
        pytest.skip(f"real data not available: {p}")
    return p


@pytest.fixture
def real():
    return real_file


def real_files():
    """Every readable recording (data files, not sidecars) in the shared folder; [] when absent."""
    if not REAL.exists():
        return []
    exts = {".dzt", ".dt1", ".rd3"}
    return sorted(p for p in REAL.rglob("*") if p.suffix.lower() in exts)


class StepClock:
    """A stand-in for the ``time`` module in a training loop: each ``perf_counter()`` reading is half a second
    after the last, the first at 1000 s."""

    def __init__(self):
        self.t = 999.5

    def perf_counter(self):
        self.t += 0.5
        return self.t


@pytest.fixture
def step_clock():
    """:class:`StepClock`, to make fresh clocks from."""
    return StepClock
