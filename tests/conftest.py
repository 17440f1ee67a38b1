"""Shared fixtures: the real recordings in ../shared/data/real (skipped cleanly when absent)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# no background compilation of the numba kernels under the tests (gpr3d.core.warmup): the commands they run compile
# what they call, as before; the warm-up's own tests turn it on, each with a numba cache of its own
os.environ.setdefault("GPR3D_WARMUP", "0")
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


def pipe_walk_files(d: Path, n_traces: int) -> Path:
    """``d/line.h5`` (a random walk over a pipe 0.33 m deep along x at y = 0.4, eps_r 6 in its header, no poses in
    the file) and ``d/walk.tum`` (the walk's poses, one per trace): the survey several tests run commands on."""
    from gpr3d import Survey
    from gpr3d.io.trajectory import write_tum
    from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model
    from gpr3d.simulation.paths import random_walk

    walk = random_walk(n_traces, area=((0, 0.8), (0, 0.8)), step_m=0.01, seed=4)
    scene = ForwardScene(eps_r=6.0, pipes=[Pipe((0.1, 0.4, -0.33), (0.7, 0.4, -0.33), 0.03)])
    data = forward_model(scene, walk.positions_xyz, walk.orientations_quat_wxyz, offset_m=0.08, frequency_hz=800e6,
                         n_samples=192, time_window_s=12e-9, air_wave=1.0, ground_wave=0.5)
    Survey(data=data, dt_s=12e-9 / 192, offset_m=0.08, frequency_hz=800e6, eps_r=6.0).save(d / "line.h5")
    write_tum(walk, d / "walk.tum")
    return d
