"""Every setting of ReconstructConfig at the edges of its range: accepted just inside, refused just outside with
the whole one-line message (and the caller's name for it)."""

import re

import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.grid import Grid3D
from gpr3d.migration.reconstruct import ReconstructConfig, check_config, check_grid_fits

GOOD = [
    {"eps_r": None}, {"eps_r": 1.0}, {"eps_r": 1}, {"spacing_m": 1e-6}, {"spacing_m": None}, {"depth_spacing_m": None},
    {"max_depth_m": None}, {"pad_m": 0.0}, {"aperture_deg": None}, {"aperture_deg": 0.001}, {"aperture_deg": 89.9},
    {"threshold": 1.0}, {"threshold": 1e-6}, {"min_line_m": 0.0}, {"min_target_depth_m": None},
    {"min_target_depth_m": 0.0}, {"min_target_depth_m": 0.5}, {"taper_traces": 0.0}, {"taper_traces": 0.5},
    {"air_gap_m": 0.0}, {"obliquity": False}, {"spreading": False}, {"remove_background": False},
    {"time_zero": "first_break"}, {"time_zero": "none"}, {"normalize": "fold"}, {"normalize": "none"},
    {"method": "pseudo3d"}, {"aperture_m": None}, {"aperture_m": 1e-6}, {"aperture_m": 3},
]

BAD = [
    ({"eps_r": 0.99}, "eps_r must be >= 1.0, got 0.99"),
    ({"eps_r": float("nan")}, "eps_r must be a finite number, got nan"),
    ({"eps_r": "4"}, "eps_r must be a finite number, got '4'"),
    ({"eps_r": True}, "eps_r must be a finite number, got True"),
    ({"spacing_m": "2 cm"}, "spacing_m must be a finite number, got '2 cm'"),
    ({"spacing_m": 0.0}, "spacing_m must be positive, got 0.0"),
    ({"depth_spacing_m": 0}, "depth_spacing_m must be positive, got 0"),
    ({"max_depth_m": -1.0}, "max_depth_m must be positive, got -1.0"),
    ({"pad_m": None}, "pad_m must be a finite number, got None"),
    ({"pad_m": -0.01}, "pad_m must be >= 0.0, got -0.01"),
    ({"aperture_deg": 0.0}, "aperture_deg must be > 0.0, got 0.0"),
    ({"aperture_deg": 90.0}, "aperture_deg must be < 90.0, got 90.0"),
    ({"aperture_deg": 90.5}, "aperture_deg must be < 90.0, got 90.5"),
    ({"aperture_deg": -1.0}, "aperture_deg must be > 0.0, got -1.0"),
    ({"aperture_m": 0.0}, "aperture_m must be positive, got 0.0"),
    ({"aperture_m": -0.5}, "aperture_m must be positive, got -0.5"),
    ({"aperture_m": float("inf")}, "aperture_m must be a finite number, got inf"),
    ({"aperture_m": "1 m"}, "aperture_m must be a finite number, got '1 m'"),
    ({"method": "pseudo3d", "aperture_m": 1.0},
     "method must be 'backprojection' for an aperture radius (aperture_m; pseudo-3D's lines take the cone alone), "
     "got 'pseudo3d'"),
    ({"threshold": 0.0}, "threshold must be > 0.0, got 0.0"),
    ({"threshold": 1.01}, "threshold must be <= 1.0, got 1.01"),
    ({"min_line_m": -0.1}, "min_line_m must be >= 0.0, got -0.1"),
    ({"min_target_depth_m": -0.01}, "min_target_depth_m must be >= 0.0, got -0.01"),
    ({"taper_traces": -1.0}, "taper_traces must be >= 0.0, got -1.0"),
    ({"air_gap_m": -0.1}, "air_gap_m must be >= 0.0, got -0.1"),
    ({"air_gap_m": float("inf")}, "air_gap_m must be a finite number, got inf"),
    ({"obliquity": 1}, "obliquity must be true or false, got 1"),
    ({"spreading": "yes"}, "spreading must be true or false, got 'yes'"),
    ({"remove_background": None}, "remove_background must be true or false, got None"),
    ({"time_zero": "Peak"}, "time_zero must be 'peak', 'first_break' or 'none', got 'Peak'"),
    ({"normalize": "sqrt"}, "normalize must be 'sqrt_fold', 'fold' or 'none', got 'sqrt'"),
    ({"method": "kirchhoff"}, "method must be 'backprojection' or 'pseudo3d', got 'kirchhoff'"),
    ({"method": "pseudo3d", "workers": 2},
     "method must be 'backprojection' for site tiles (pseudo-3D migrates line by line), got 'pseudo3d'"),
    ({"method": "pseudo3d", "tile_m": 5.0},
     "method must be 'backprojection' for site tiles (pseudo-3D migrates line by line), got 'pseudo3d'"),
    ({"method": "pseudo3d", "scheduler": "tcp://h:8786"},
     "method must be 'backprojection' for site tiles (pseudo-3D migrates line by line), got 'pseudo3d'"),
    ({"method": "pseudo3d", "checkpoint": "ck"},
     "method must be 'backprojection' for site tiles (pseudo-3D migrates line by line), got 'pseudo3d'"),
]


@pytest.mark.parametrize("kw", GOOD, ids=[next(iter(k)) + "=" + repr(next(iter(k.values()))) for k in GOOD])
def test_settings_inside_their_ranges_pass(kw):
    check_config(ReconstructConfig(**kw))


@pytest.mark.parametrize("kw, words", BAD, ids=[w[:40] for _, w in BAD])
def test_settings_outside_their_ranges_are_named_in_full(kw, words):
    with pytest.raises(InvalidDataError, match="^" + re.escape(words) + "$"):
        check_config(ReconstructConfig(**kw))


def test_the_caller_s_names_and_the_site_settings():
    with pytest.raises(InvalidDataError, match=r"^--spacing must be positive, got -0\.02$"):
        check_config(ReconstructConfig(spacing_m=-0.02), {"spacing_m": "--spacing"})
    with pytest.raises(InvalidDataError, match=re.escape(
            "--method must be 'backprojection' for an aperture radius (--aperture-radius; pseudo-3D's lines take "
            "the cone alone), got 'pseudo3d'")):
        check_config(ReconstructConfig(method="pseudo3d", aperture_m=1.0),
                     {"method": "--method", "aperture_m": "--aperture-radius"})
    with pytest.raises(InvalidDataError, match="^tile"):  # the site settings are checked too
        check_config(ReconstructConfig(tile_m=-1.0))
    with pytest.raises(InvalidDataError, match="^workers"):
        check_config(ReconstructConfig(workers=-1))
    with pytest.raises(InvalidDataError, match="^scheduler must be an address such as tcp://host:8786, got 'h:1'$"):
        check_config(ReconstructConfig(scheduler="h:1"))


def test_a_grid_larger_than_memory_is_refused_with_its_size():
    g = Grid3D(0, 0, 0, 0.01, 0.01, 0.01, 100, 100, 100)  # 1 M voxels x 32 bytes = 30.5 MiB
    check_grid_fits(g, available_bytes=int(32e6 / 0.8) + 1)
    with pytest.raises(InvalidDataError, match=re.escape(
            "the grid of 100 x 100 x 100 voxels (1 M) would need about 0.0 GiB, more than this machine's 0.0 GiB "
            "can hold: use a larger --spacing or a smaller --max-depth")):
        check_grid_fits(g, available_bytes=int(32e6 / 0.8) - 1)
    big = Grid3D(0, 0, 0, 0.01, 0.01, 0.01, 2000, 2000, 1000)  # 4e9 voxels: 119.2 GiB
    with pytest.raises(InvalidDataError, match=re.escape("voxels (4,000 M) would need about 119.2 GiB, more than "
                                                         "this machine's 2.0 GiB can hold")):
        check_grid_fits(big, available_bytes=2**31)
    check_grid_fits(g)  # this machine's own memory holds a million voxels
