import numpy as np
import pytest
from scipy.spatial import cKDTree

from gpr3d.core.poses import yaw_from_quat
from gpr3d.simulation.paths import grid_lines, random_walk


def coverage(traj, area=2.0, radius=0.1):
    """Fraction of 5 cm cells of the area within ``radius`` of a trace."""
    c = np.arange(0.025, area, 0.05)
    cells = np.stack(np.meshgrid(c, c), -1).reshape(-1, 2)
    d, _ = cKDTree(traj.positions_xyz[:, :2]).query(cells)
    return float(np.mean(d < radius))


def test_random_walk_steps_are_even_and_the_heading_follows_the_path():
    walk = random_walk(500, seed=1)
    step = np.diff(walk.positions_xyz, axis=0)
    assert np.linalg.norm(step, axis=1) == pytest.approx(0.01, abs=1e-9)
    # the antenna's x axis (the heading) points along the step taken to each trace
    turn = np.arctan2(step[:, 1], step[:, 0]) - yaw_from_quat(walk.orientations_quat_wxyz[1:])
    assert np.abs(np.angle(np.exp(1j * turn))).max() < 1e-6
    assert np.all(np.diff(walk.timestamps_s) == pytest.approx(0.02))


def test_exploring_walk_covers_the_area_better_than_the_plain_one():
    plain = [coverage(random_walk(8000, seed=s, explore=0.0)) for s in range(4)]
    explore = [coverage(random_walk(8000, seed=s)) for s in range(4)]
    assert min(explore) >= 0.95  # the demo's survey: 80 m of path over 2 m x 2 m
    assert np.mean(explore) > np.mean(plain) + 0.05


def test_grid_lines_run_both_ways_along_x_then_y():
    tr = grid_lines(area=((0, 1), (0, 1)), line_spacing_m=0.5, step_m=0.1, directions="xy")
    assert len(tr) == 2 * 3 * 11
    first = tr.positions_xyz[:11]
    assert np.all(first[:, 1] == 0) and np.all(np.diff(first[:, 0]) > 0)
    second = tr.positions_xyz[11:22]
    assert np.all(second[:, 1] == 0.5) and np.all(np.diff(second[:, 0]) < 0)
    assert np.all(tr.positions_xyz[33:44, 0] == 0) and np.all(np.diff(tr.positions_xyz[33:44, 1]) > 0)
