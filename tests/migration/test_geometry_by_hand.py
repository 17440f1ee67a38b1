"""Physical checks of the migration's shared inputs, each against numbers worked out by hand (issue 13, item 2):
where every engine takes the same antenna positions, slowness and aperture, only an outside reference can tell a
wrong one."""

import math

import numpy as np
import pytest

from gpr3d.core.grid import Grid3D
from gpr3d.migration.operator import BackProjection, antenna_positions

C = 299792458.0


@pytest.mark.parametrize("yaw_deg, tx_xy, rx_xy", [
    (0.0, (0.8, 2.0), (1.2, 2.0)),  # heading +x: tx behind, rx ahead, 0.2 m each way
    (90.0, (1.0, 1.8), (1.0, 2.2)),  # heading +y
    (180.0, (1.2, 2.0), (0.8, 2.0)),
    (30.0, (1.0 - 0.2 * math.cos(math.radians(30)), 2.0 - 0.2 * math.sin(math.radians(30))),
     (1.0 + 0.2 * math.cos(math.radians(30)), 2.0 + 0.2 * math.sin(math.radians(30)))),
])
def test_tx_and_rx_lie_along_the_heading(yaw_deg, tx_xy, rx_xy):
    p = np.array([[1.0, 2.0, 0.05]])
    for kw in ({"headings_rad": [math.radians(yaw_deg)]},
               {"orientations_quat_wxyz": [[math.cos(math.radians(yaw_deg) / 2), 0, 0, math.sin(math.radians(yaw_deg) / 2)]]}):
        tx, rx = antenna_positions(p, offset_m=0.4, **kw)
        np.testing.assert_allclose(tx[0], [*tx_xy, 0.05], atol=1e-12)
        np.testing.assert_allclose(rx[0], [*rx_xy, 0.05], atol=1e-12)


def _spike_time(op, ix, iy, k):
    """Where the forward operator puts a unit voxel: the time (s after the first sample) of the centroid of the
    two samples it spreads the voxel over."""
    m = np.zeros(op.grid.shape, np.float32)
    m[ix, iy, k] = 1.0
    d = op.forward(m)[0].astype(float)
    idx = np.nonzero(d)[0]
    assert idx.size and idx.max() - idx.min() <= 1, idx
    return float(np.sum(idx * d[idx]) / np.sum(d[idx])) * op.dt


@pytest.mark.parametrize("engine", ["numba", "numpy"])
def test_travel_time_from_eps_r_offset_and_time_zero(engine):
    """A voxel 0.4 m below the midpoint of a 0.2 m tx-rx pair, eps_r 9 (v = c/3), time zero 2 ns: the two-way
    time is 2 ns + 2 sqrt(0.4^2 + 0.1^2) / (c/3)."""
    g = Grid3D(0.0, 0.0, 0.4, 0.1, 0.1, 0.1, 1, 1, 1)
    tx, rx = np.array([[-0.1, 0.0, 0.0]]), np.array([[0.1, 0.0, 0.0]])
    op = BackProjection(g, tx, rx, dt_s=0.01e-9, n_samples=2000, t0_s=2e-9, eps_r=9.0, engine=engine)
    want = 2e-9 + 2 * math.hypot(0.4, 0.1) / (C / 3)
    assert _spike_time(op, 0, 0, 0) == pytest.approx(want, abs=1e-13)


@pytest.mark.parametrize("engine", ["numba", "numpy"])
def test_aperture_is_a_half_angle_in_degrees_about_the_midpoint(engine):
    """Aperture 30 deg: a voxel 0.5 m deep is seen from a midpoint up to 0.5 tan 30 = 0.2887 m away, not beyond;
    the tx-rx pair lies across the line to the voxel, so it is the midpoint that counts."""
    g = Grid3D(0.0, 0.0, 0.5, 0.1, 0.1, 0.1, 1, 1, 1)
    reach = 0.5 * math.tan(math.radians(30))
    for dist, seen in ((0.97 * reach, True), (1.03 * reach, False)):
        mid = np.array([dist, 0.0, 0.0])
        tx, rx = mid - [0, 0.15, 0], mid + [0, 0.15, 0]
        op = BackProjection(g, tx[None], rx[None], dt_s=0.02e-9, n_samples=600, eps_r=4.0, aperture_deg=30.0,
                            engine=engine)
        m = np.ones(g.shape, np.float32)
        assert bool(np.any(op.forward(m))) == seen, dist


def test_sub_cell_depth_is_the_parabola_vertex():
    """Columns whose envelope is a parabola in depth: the ridge depth is its vertex, between cells, exactly; a
    column peaking on the grid's first cell stays there (no neighbour above to fit)."""
    from gpr3d.migration.targets import ridge_map

    g = Grid3D(0.0, 0.0, 0.1, 0.1, 0.1, 0.02, 3, 1, 30)
    vertex = np.array([0.437, 0.3013, 0.1])
    env = np.clip(1.0 - 40.0 * (g.depth[None, :] - vertex[:, None]) ** 2, 0, None)[:, None, :]
    val, dep = ridge_map(env.astype(np.float64), g)
    assert dep[0, 0] == pytest.approx(0.437, abs=1e-9) and dep[1, 0] == pytest.approx(0.3013, abs=1e-9)
    assert dep[2, 0] == pytest.approx(0.1, abs=1e-12)
    assert val[0, 0] == pytest.approx(1.0 - 40.0 * (0.44 - 0.437) ** 2)  # the sampled maximum, not the vertex


def test_boxes_follow_the_samples_that_time_zero_cuts(monkeypatch):
    """A symmetric direct wave peaking at sample 40 (4 ns): reconstruct cuts the 4 ns before it, so a box given in
    the recording's times (10 to 14 ns) reaches the mask as 6 to 10 ns. With a lopsided wave time zero falls
    between samples, and the boxes move by that estimate, not by the whole samples cut."""
    from gpr3d import Survey
    from gpr3d.migration import reconstruct as R

    n, ns, dt = 30, 200, 0.1e-9
    pos = np.c_[np.linspace(0, 0.6, n), np.linspace(0, 0.4, n) ** 2, np.zeros(n)]  # a curve: a 3D survey
    seen = {}
    real = R.box_mask

    def spy(n_traces, n_samples, dt_s, boxes, **kw):
        seen["boxes"], seen["n_samples"] = [list(b) for b in boxes], n_samples
        return real(n_traces, n_samples, dt_s, boxes, **kw)

    monkeypatch.setattr(R, "box_mask", spy)
    for wave, t0 in (((0.5, 1.0, 0.5), 4e-9), ((0.0, 1.0, -0.5), None)):
        data = np.zeros((n, ns), np.float32)
        data[:, 39:42] = wave
        s = Survey(data=data, dt_s=dt, positions_xyz=pos, frequency_hz=1e9)
        if t0 is None:  # what time zero itself estimates for this wave
            t0 = s.time_zero(method="peak", search_s=10e-9).history[-1]["result"]["t0_s"]
            assert abs(t0 / dt - round(t0 / dt)) > 0.05  # between samples
        R.reconstruct(s, R.ReconstructConfig(eps_r=4.0, spacing_m=0.05, max_depth_m=0.3), boxes=[[5, 10e-9, 20, 14e-9]])
        assert seen["boxes"][0] == pytest.approx([5, 10e-9 - t0, 20, 14e-9 - t0], abs=1e-15)


def _fermat_leg(h, d, rho, eps_r, n=200001):
    """The least one-way time from h above the ground to d below it, rho apart, over a dense set of crossing
    points (brute force: no Newton, no critical angle)."""
    s = np.linspace(0.0, rho, n)  # horizontal distance run in the air
    return float(np.min(np.hypot(h, s) / C + np.hypot(d, rho - s) * math.sqrt(eps_r) / C))


@pytest.mark.parametrize("engine", ["numba", "numpy"])
def test_antennas_above_the_ground_refract_at_the_surface(engine):
    """Antennas held 0.1 m above flat ground (eps_r 9): straight down to a voxel 0.3 m deep the two-way time is
    2 (0.1 / c + 0.3 * 3 / c) = 6.67 ns, not the 8 ns of 0.4 m of ground; off to the side each leg takes the least
    time over where it crosses the surface (brute force here). The same antenna z = 0.1 with no air gap means
    ground up to the antenna: 8 ns."""
    g = Grid3D(0.0, 0.0, 0.3, 0.1, 0.1, 0.1, 1, 1, 1)
    kw = dict(dt_s=0.005e-9, n_samples=4000, eps_r=9.0, engine=engine)
    on = np.array([[0.0, 0.0, 0.0]])
    op = BackProjection(g, on, on, air_gap_m=0.1, **kw)
    assert _spike_time(op, 0, 0, 0) == pytest.approx(2 * (0.1 / C + 0.9 / C), abs=2e-14)
    op = BackProjection(g, on + [0, 0, 0.1], on + [0, 0, 0.1], **kw)
    assert _spike_time(op, 0, 0, 0) == pytest.approx(2 * 0.4 * 3 / C, abs=2e-14)
    # tx 0.35 m and rx 0.15 m from the voxel's column, held 0.1 and (per trace) 0.25 m up
    tx, rx = np.array([[0.35, 0.0, 0.0]] * 2), np.array([[0.0, 0.15, 0.0]] * 2)
    g2 = Grid3D(0.0, 0.0, 0.3, 0.1, 0.1, 0.1, 1, 1, 1)
    for gap in (0.1, 0.25):
        op = BackProjection(g2, tx[:1], rx[:1], air_gap_m=[gap], **kw)
        want = _fermat_leg(gap, 0.3, 0.35, 9.0) + _fermat_leg(gap, 0.3, 0.15, 9.0)
        assert _spike_time(op, 0, 0, 0) == pytest.approx(want, abs=5e-14), gap
        # a straight ray through the air gap at ground speed (the old way) is 0.4 ns and more off
        assert abs(want - (math.hypot(0.35, 0.3 + gap) + math.hypot(0.15, 0.3 + gap)) * 3 / C) > 3e-10


# ---------------------------------------------------------------- the operator's inputs, refused or used, by hand

from gpr3d.core.errors import InvalidDataError  # noqa: E402
from gpr3d.migration.operator import effective_slowness  # noqa: E402


def test_layered_slowness_by_hand():
    """Layers eps 4 from 0 and 16 from 0.2 m: at 0.1 m the slowness of eps 4 (2/c); at 0.5 m the vertical time
    (0.2 * 2 + 0.3 * 4) / c over 0.5 m; at depth 0 the top layer's; a constant eps_r 9 gives 3/c everywhere."""
    s = effective_slowness(np.array([0.0, 0.1, 0.2, 0.5]), layers=[(0.0, 4.0), (0.2, 16.0)])
    np.testing.assert_allclose(s, np.array([2.0, 2.0, 2.0, (0.4 + 1.2) / 0.5]) / C, rtol=1e-12)
    np.testing.assert_allclose(effective_slowness(np.array([0.0, 1.0]), eps_r=9.0), [3 / C, 3 / C])
    three = effective_slowness(np.array([1.0]), layers=[(0.0, 1.0), (0.5, 4.0), (0.75, 9.0)])
    assert three[0] == pytest.approx((0.5 * 1 + 0.25 * 2 + 0.25 * 3) / C, rel=1e-12, abs=0)
    with pytest.raises(InvalidDataError, match="^give eps_r or layers for the migration velocity$"):
        effective_slowness(np.array([0.1]))
    for bad in ([(0.1, 4.0)], [(0.0, 4.0), (0.0, 9.0)], [(0.0, 4.0), (0.3, 9.0), (0.2, 16.0)]):
        with pytest.raises(InvalidDataError, match="^layers must start at depth 0 and deepen$"):
            effective_slowness(np.array([0.1]), layers=bad)


def test_the_operator_refuses_what_it_cannot_use():
    g = Grid3D(0.0, 0.0, 0.1, 0.1, 0.1, 0.1, 2, 2, 2)
    one = np.zeros((1, 3))
    kw = dict(dt_s=1e-10, n_samples=10, eps_r=4.0)
    with pytest.raises(InvalidDataError, match=r"^tx and rx must both be \(n_traces, 3\)$"):
        BackProjection(g, one, np.zeros((2, 3)), **kw)
    with pytest.raises(InvalidDataError, match=r"^tx and rx must both be \(n_traces, 3\)$"):
        BackProjection(g, np.zeros((1, 2)), np.zeros((1, 2)), **kw)
    with pytest.raises(InvalidDataError, match=r"^engine must be one of 'numba', 'numpy', 'torch' \(or 'torch:cuda', 'torch:cuda:N'\), got 'cuda'$"):
        BackProjection(g, one, one, engine="cuda", **kw)
    with pytest.raises(InvalidDataError, match=r"^air_gap_m must be one number or one per trace \(1\), got shape \(2,\)$"):
        BackProjection(g, one, one, air_gap_m=[0.1, 0.2], **kw)
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(InvalidDataError, match="^air_gap_m must be finite and >= 0"):
            BackProjection(g, one, one, air_gap_m=bad, **kw)
    op = BackProjection(g, one, one, **kw)
    with pytest.raises(InvalidDataError, match=r"^data must be \(1, 10\), got \(1, 9\)$"):
        op.adjoint(np.zeros((1, 9), np.float32))
    with pytest.raises(InvalidDataError, match=r"^image must be \(2, 2, 2\), got \(2, 2, 3\)$"):
        op.forward(np.zeros((2, 2, 3), np.float32))
    for window in ((0, 3, 0, 2), (1, 1, 0, 2), (-1, 1, 0, 2), (0, 2, 1, 0)):
        with pytest.raises(InvalidDataError, match="does not lie inside the 2 x 2 columns of the grid"):
            op.adjoint(np.zeros((1, 10), np.float32), window=window)


def test_reach_traces_and_shape():
    g = Grid3D(0.0, 0.0, 0.1, 0.1, 0.1, 0.1, 2, 3, 4)  # deepest voxel 0.4 m
    tx = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    op = BackProjection(g, tx, tx + [0.1, 0, 0], dt_s=1e-10, n_samples=10, eps_r=4.0, aperture_deg=45.0,
                        air_gap_m=[0.0, 0.1, 0.2])
    assert op.reach_m == pytest.approx(0.4 + 1e-6) and op.shape == (30, 24) and op.n_traces == 3
    sub = op.with_traces([2, 0])
    np.testing.assert_array_equal(sub.tx[:, 0], [2.0, 0.0])
    np.testing.assert_array_equal(sub.rx[:, 0], [2.1, 0.1])
    np.testing.assert_array_equal(sub.air_gap, [0.2, 0.0])
    assert sub.tan_ap == op.tan_ap and sub.n_traces == 2 and op.n_traces == 3
    assert BackProjection(g, tx, tx, dt_s=1e-10, n_samples=10, eps_r=4.0).reach_m == math.inf
