"""gprMax builds every kind of scene the runner can describe (geometry only: fast)."""

import contextlib
import io

import pytest

from gpr3d.simulation.gprmax_runner import build_gprmax_scene
from gpr3d.simulation.sampler import sample_scene
from gpr3d.simulation.scene import Antenna, Medium, Scene, Stone, Target


def build_only(scene, tmp_path):
    gprMax = pytest.importorskip("gprMax")
    with contextlib.redirect_stdout(io.StringIO()):
        gprMax.run(scenes=[build_gprmax_scene(scene)], n=1, geometry_only=True, outputfile=str(tmp_path / "g.h5"),
                   hide_progress_bars=True, log_level=40, allow_underresolved=True)


def test_heterogeneous_soil_rough_surface_stones_and_hollow_pipes(tmp_path):
    s = Scene(medium=Medium(kind="soil", eps_r=8.0, conductivity_s_m=0.005,
                            peplinski={"sand": 0.5, "clay": 0.5, "bulk_density": 2.0, "sand_density": 2.66,
                                       "water": [0.05, 0.15], "fractal_dim": 1.5, "n_materials": 10}),
              antenna=Antenna(frequency_hz=800e6, offset_m=0.06), width_m=0.6, depth_m=0.35, air_m=0.08,
              n_traces=3, trace_step_m=0.05, x_start_m=0.2, rough_surface_m=0.01,
              targets=[Target("pvc_pipe", x_m=0.3, depth_m=0.1, radius_m=0.04, material="pvc", fill="water",
                              wall_m=0.006),
                       Target("tank", x_m=0.45, depth_m=0.15, radius_m=0.08)],
              stones=[Stone(x_m=0.12, depth_m=0.05, radius_m=0.015, eps_r=7.0)])
    build_only(s, tmp_path)


def test_sampled_scenes_build(tmp_path):
    for i in (1, 3, 16, 26):  # soil with stones, rough surfaces, water-filled pipes, tanks
        build_only(sample_scene(0, i), tmp_path)


def test_targets_must_cross_the_line():
    s = sample_scene(0, 2)
    s.targets[0].axis_xyz = (1.0, 0.0, 0.0)
    pytest.importorskip("gprMax")
    with pytest.raises(ValueError, match="must cross the line"):
        build_gprmax_scene(s)
