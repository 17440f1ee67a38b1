"""The grid method (2D migration of each line, then pseudo-3D) against its steps written out in the test: lines in
both directions, one driven backwards, the antennas turned with the line, the planes at the lines' median
cross-coordinate, envelopes along depth, linear filling between lines and the mean of the two directions."""

import math

import numpy as np
import pytest
from scipy.signal import hilbert

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.grid import Grid3D
from gpr3d.core.poses import quat_from_yaw
from gpr3d.core.survey import Survey
from gpr3d.migration.traditional import kirchhoff_line, pseudo3d, split_lines, stolt_migrate, survey_lines

C = 299792458.0
GRID = Grid3D(0.0, 0.0, 0.01, 0.04, 0.03, 0.02, 9, 9, 10)


def _grid_survey(t0=0.3e-9, offset=0.04, seed=1):
    """Two lines along x (the second driven back west), two along y, 12 traces each, a little sideways wobble;
    headings with the travel; random data."""
    rng = np.random.default_rng(seed)
    xs = np.arange(12) * 0.03
    ys = np.arange(12) * 0.02
    parts, yaw = [], []
    for y0, back in ((0.05, False), (0.17, True)):
        x = xs[::-1] if back else xs
        parts.append(np.c_[x, y0 + rng.uniform(-0.002, 0.002, 12), np.zeros(12)])
        yaw.append(np.full(12, math.pi if back else 0.0))
    for x0 in (0.08, 0.2):
        parts.append(np.c_[x0 + rng.uniform(-0.002, 0.002, 12), ys, np.zeros(12)])
        yaw.append(np.full(12, math.pi / 2))
    pos, yaw = np.vstack(parts), np.concatenate(yaw)
    data = rng.standard_normal((len(pos), 90)).astype(np.float32)
    return Survey(data=data, dt_s=0.05e-9, t0_s=t0, offset_m=offset, positions_xyz=pos,
                  orientations_quat_wxyz=quat_from_yaw(yaw), frequency_hz=1e9)


def _kirchhoff_plane(data, pos, yaw, offset, t0, dt, eps_r, axis, coord, aperture_deg=50.0, grid=GRID):
    """One line's vertical plane: obliquity-weighted diffraction stack, aperture cone from the antennas' midpoint,
    tx and rx -/+ offset/2 along the heading."""
    v = C / math.sqrt(eps_r)
    along = grid.x if axis == "x" else grid.y
    img = np.zeros((len(along), grid.nd))
    tan = math.tan(math.radians(aperture_deg))
    for m in range(len(pos)):
        h = np.array([math.cos(yaw[m]), math.sin(yaw[m])]) * offset / 2
        a, b = pos[m, :2] - h, pos[m, :2] + h
        row = np.r_[data[m].astype(float), 0.0, 0.0]
        for i, s in enumerate(along):
            p = np.array([s, coord]) if axis == "x" else np.array([coord, s])
            first = math.ceil((np.hypot(*(p - pos[m, :2])) / tan - grid.d0) / grid.dd - 1e-12)
            for k, d in enumerate(grid.depth):
                if k < first:
                    continue
                ra, rb = math.hypot(*(p - a), d), math.hypot(*(p - b), d)
                u = min((t0 + (ra + rb) / v) / dt, data.shape[1])
                i0 = int(u)
                img[i, k] += (row[i0] + (u - i0) * (row[i0 + 1] - row[i0])) * 0.5 * (d / ra + d / rb)
    return img


def _fill(planes, n, origin, step):
    """Between the lines, linear in the cross coordinate; zero outside them."""
    coords = sorted(planes)
    stack = np.stack([planes[c] for c in coords])
    out = np.zeros((n,) + stack.shape[1:])
    for i in range(n):
        c = origin + i * step
        if coords[0] <= c <= coords[-1]:
            out[i] = np.apply_along_axis(lambda col: np.interp(c, coords, col), 0, stack)
    return out


def _by_hand(s, method, eps_r, aperture_deg=50.0, grid=GRID):
    yaw = (np.zeros(s.n_traces) if s.orientations_quat_wxyz is None
           else 2 * np.arctan2(s.orientations_quat_wxyz[:, 3], s.orientations_quat_wxyz[:, 0]))
    planes = {"x": {}, "y": {}}
    for k in range(4):
        idx = np.arange(12 * k, 12 * k + 12)
        axis = "x" if k < 2 else "y"
        p = s.positions_xyz[idx]
        coord = float(np.median(p[:, 1] if axis == "x" else p[:, 0]))
        if method == "kirchhoff":
            img = _kirchhoff_plane(s.data[idx], p, yaw[idx], s.offset_m, s.t0_s, s.dt_s, eps_r, axis, coord,
                                   aperture_deg, grid)
        else:
            a = p[:, 0] if axis == "x" else p[:, 1]
            order = np.argsort(a)
            step = (a[order][-1] - a[order][0]) / (len(a) - 1)  # the mean interval
            mig, dz = stolt_migrate(s.data[idx][order], step, s.dt_s, eps_r)
            z = np.arange(mig.shape[1]) * dz
            tmp = np.stack([np.interp(grid.depth, z, tr) for tr in mig])
            target = grid.x if axis == "x" else grid.y
            img = np.stack([np.interp(target, a[order], tmp[:, j], left=0, right=0) for j in range(grid.nd)], 1)
        planes[axis][coord] = np.abs(hilbert(img, axis=1))
    vx = np.transpose(_fill(planes["x"], grid.ny, grid.y0, grid.dy), (1, 0, 2))
    vy = _fill(planes["y"], grid.nx, grid.x0, grid.dx)
    return 0.5 * (vx + vy)


@pytest.mark.parametrize("method, t0", [("kirchhoff", 0.3e-9), ("stolt", 0.0)])
def test_pseudo3d_is_the_grid_method_written_out(method, t0):
    s = _grid_survey(t0=t0)
    vol, info = pseudo3d(s, GRID, eps_r=5.0, method=method)
    assert info == {"n_lines_x": 2, "n_lines_y": 2}
    assert vol.dtype == np.float32 and vol.shape == GRID.shape
    ref = _by_hand(s, method, 5.0)
    np.testing.assert_allclose(vol, ref, atol=2e-3 * ref.max())
    assert np.count_nonzero(vol) > 0.5 * vol.size


def test_stolt_takes_a_line_s_mean_interval_where_the_cart_stood_still():
    """The first line's first seven traces at one place (an operator who paused): its median interval is nil,
    its mean 0.15 m / 11; the image is the grid method's with that step, finite."""
    s = _grid_survey(t0=0.0)
    s.positions_xyz[:7, :2] = s.positions_xyz[0, :2] * [0.0, 1.0]
    s.positions_xyz[7:12, 0] = 0.03 * np.arange(1, 6)
    vol, _ = pseudo3d(s, GRID, eps_r=5.0, method="stolt")
    assert np.isfinite(vol).all()
    ref = _by_hand(s, "stolt", 5.0)
    np.testing.assert_allclose(vol, ref, atol=2e-3 * ref.max())
    s.positions_xyz[:12, :2] = [0.1, 0.05]
    with pytest.raises(InvalidDataError, match=r"^a survey line at .* has all its traces at one place: Stolt needs "
                                               r"a line that moves$"):
        pseudo3d(s, GRID, eps_r=5.0, method="stolt")


def test_one_line_by_itself_with_its_defaults():
    """kirchhoff_line's defaults: a 50 deg aperture, no air gap, the numba engine; the antennas from the headings
    and the offset it is given; a line along y images onto the y axis of the grid."""
    s = _grid_survey()
    idx = np.arange(36, 48)
    p = s.positions_xyz[idx]
    coord = float(np.median(p[:, 0]))
    img = kirchhoff_line(s.data[idx], p, s.orientations_quat_wxyz[idx], s.offset_m, dt_s=s.dt_s, t0_s=s.t0_s,
                         eps_r=5.0, grid=GRID, axis="y", coord=coord)
    ref = _kirchhoff_plane(s.data[idx], p, np.full(12, math.pi / 2), s.offset_m, s.t0_s, s.dt_s, 5.0, "y", coord)
    assert img.shape == (GRID.ny, GRID.nd)
    np.testing.assert_allclose(img, ref, atol=2e-3 * np.abs(ref).max())


def test_pseudo3d_refusals_in_full():
    s = _grid_survey()
    with pytest.raises(InvalidDataError, match=r"^method must be 'kirchhoff' or 'stolt', got 'phase'$"):
        pseudo3d(s, GRID, eps_r=5.0, method="phase")
    with pytest.raises(InvalidDataError, match=r"^an air gap needs method 'kirchhoff' \(refraction at the surface\), "
                                               r"not 'stolt'$"):
        pseudo3d(s, GRID, eps_r=5.0, method="stolt", air_gap_m=0.1)
    short = s.replace(data=s.data[:9], positions_xyz=s.positions_xyz[:9], orientations_quat_wxyz=None)
    with pytest.raises(InvalidDataError, match=r"^no straight lines of 10 traces or more found in the survey$"):
        pseudo3d(short, GRID, eps_r=5.0)


def test_survey_lines_from_positions_and_grid_files_of_ten():
    s = _grid_survey()
    assert [ln.tolist() for ln in survey_lines(s)] == [list(range(12 * k, 12 * k + 12)) for k in range(4)]
    g = s.replace(metadata={"grid": {"first_trace": [0, 10, 19, 20, 30]}})  # files of 10, 9, 1, 10 and 18 traces
    assert [(int(ln[0]), len(ln)) for ln in survey_lines(g)] == [(0, 10), (20, 10), (30, 18)]


def test_split_lines_edges():
    """The defaults (lines of 10 traces or more, a jump of 3 median steps, a turn of 0.3 rad) at their edges, on
    steps that are exact in binary; a stop does not lose the heading that a later turn is measured from."""
    east = np.c_[np.arange(10) * 0.25, np.zeros(10)]
    assert [len(ln) for ln in split_lines(east)] == [10]
    assert split_lines(east[:9]) == []
    gap3 = np.r_[east, east[-1] + [[0.75, 0.0]] + east]  # a jump of exactly 3 median steps: same line
    assert [len(ln) for ln in split_lines(gap3)] == [20]
    gap35 = np.r_[east, east[-1] + [[0.875, 0.0]] + east]  # 3.5 steps: a new line
    assert [len(ln) for ln in split_lines(gap35)] == [10, 10]
    for turn, parts in ((0.28, [20]), (0.32, [10, 10])):
        d = np.array([math.cos(turn), math.sin(turn)]) * 0.25
        bent = np.r_[east, east[-1] + d + np.arange(10)[:, None] * d]
        assert [len(ln) for ln in split_lines(bent)] == parts, turn
    # stops: repeated places do not pull the median step (and the gap) to zero, nor hide a later turn
    stops = np.r_[east[:5], np.repeat(east[5:6], 12, axis=0), east[6:]]  # more stopped steps than moving ones
    assert [len(ln) for ln in split_lines(stops)] == [21]
    north = east[-1] + np.c_[np.zeros(10), 0.25 + np.arange(10) * 0.25]
    assert [len(ln) for ln in split_lines(np.r_[stops, north])] == [21, 10]
    # stopped at the corner, then north: the heading from before the stop still tells the turn
    corner = np.r_[east, np.repeat(east[-1:], 3, axis=0), north]
    assert [len(ln) for ln in split_lines(corner)] == [13, 10]


def test_stolt_leaves_a_flat_reflector_in_place_and_drops_the_mean():
    """At kx = 0 the Stolt map is the identity (omega = v kz / 2, Jacobian 1) except at zero frequency, whose
    Jacobian is 0: identical traces (no padding, which would make the line a boxcar in x) come back unchanged on
    depth = v dt / 2 per sample, less their mean; all zeros stay zeros."""
    rng = np.random.default_rng(4)
    tr = rng.standard_normal(64) + 0.7
    data = np.tile(tr, (16, 1)).astype(np.float32)
    img, dz = stolt_migrate(data, 0.02, 0.1e-9, 9.0, pad=1)
    assert img.dtype == np.float32
    assert dz == pytest.approx(0.5 * C / 3.0 * 0.1e-9, rel=1e-12, abs=0)
    np.testing.assert_allclose(img, np.tile(tr - tr.mean(), (16, 1)), atol=1e-5)
    np.testing.assert_array_equal(stolt_migrate(np.zeros((8, 32), np.float32), 0.02, 0.1e-9, 9.0)[0], 0.0)
    noise = rng.standard_normal((16, 64)).astype(np.float32)
    np.testing.assert_array_equal(stolt_migrate(noise, 0.02, 0.1e-9, 9.0)[0],
                                  stolt_migrate(noise, 0.02, 0.1e-9, 9.0, pad=2)[0])  # the default pad


def test_a_line_driven_back_on_itself_splits():
    """A reversal: the dot product of the two headings rounds to just below -1 here; it is still a turn of pi."""
    a = 0.026948982994331447
    step = np.array([math.cos(a), math.sin(a)]) * 0.25
    d = step / np.hypot(*step)
    assert d @ (-step / np.hypot(*-step)) < -1.0
    out = np.arange(12)[:, None] * step
    back = out[-1] - (1 + np.arange(12))[:, None] * step
    assert [len(ln) for ln in split_lines(np.r_[out, back])] == [12, 12]


# --- reconstruct(method="pseudo3d"): the grid method composed from its parts ----------------------------------------

from gpr3d.migration.masking import box_mask  # noqa: E402
from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct  # noqa: E402
from gpr3d.migration.targets import extract_targets  # noqa: E402


def _composed(s, cfg, boxes=None):
    """What reconstruct(method="pseudo3d") must give, from the parts: the grid over the positions, the pseudo-3D
    envelope of the data inside the boxes (noise map: outside them), targets from the envelope with the band of
    half a wavelength."""
    v = C / math.sqrt(cfg.eps_r)
    depth = cfg.max_depth_m or 0.5 * v * (s.n_samples * s.dt_s - s.t0_s - 2 * cfg.air_gap_m / C) * 0.95
    grid = Grid3D.covering(s.positions_xyz, depth_m=depth, spacing_m=cfg.spacing_m,
                           depth_spacing_m=cfg.depth_spacing_m, pad_m=cfg.pad_m)
    ap = cfg.aperture_deg if cfg.aperture_deg is not None else 89.0
    noise = None
    data = s.data
    if boxes is not None:
        mask = box_mask(s.n_traces, s.n_samples, s.dt_s, boxes, taper_traces=cfg.taper_traces)
        noise, _ = pseudo3d(s.replace(data=s.data * (1 - mask)), grid, eps_r=cfg.eps_r, aperture_deg=ap)
        data = s.data * mask
    env, _ = pseudo3d(s.replace(data=data), grid, eps_r=cfg.eps_r, aperture_deg=ap)
    band = max(2 * 2.0 * max(grid.dx, grid.dy), 0.5 * v / s.frequency_hz)
    targets = extract_targets(env, grid, threshold=cfg.threshold, min_line_m=cfg.min_line_m, band_m=band,
                              min_depth_m=cfg.min_target_depth_m)
    return grid, env, noise, targets


@pytest.mark.parametrize("kw, boxes", [
    ({"aperture_deg": 40.0, "max_depth_m": 0.15, "min_target_depth_m": 0.05}, None),
    ({"aperture_deg": None, "threshold": 0.5, "min_line_m": 0.1}, [[0, 1e-9, 20, 3e-9], [30, 0.5e-9, 47, 2e-9]]),
])
def test_reconstruct_pseudo3d_is_composed_of_its_parts(kw, boxes):
    s = _grid_survey(t0=0.0)
    cfg = ReconstructConfig(method="pseudo3d", eps_r=5.0, spacing_m=0.03, time_zero="none", remove_background=False,
                            **kw)
    rec = reconstruct(s, cfg, boxes=boxes)
    grid, env, noise, targets = _composed(s, cfg, boxes)
    assert rec.grid == grid and rec.fold is None and rec.eps_r == 5.0 and rec.n_traces == 48
    np.testing.assert_allclose(rec.envelope, env, rtol=1e-6, atol=1e-6 * env.max())
    np.testing.assert_array_equal(rec.image, rec.envelope)
    if boxes is None:
        assert rec.noise_map is None
    else:
        np.testing.assert_allclose(rec.noise_map, noise, rtol=1e-6, atol=1e-6 * noise.max())
    assert [(t.kind, t.n_voxels) for t in rec.targets] == [(t.kind, t.n_voxels) for t in targets]
    assert rec.config["method"] == "pseudo3d" and rec.config["aperture_deg"] == kw["aperture_deg"]
    assert set(rec.timings_s) == {"prepare", "migrate"} and 0 <= rec.timings_s["migrate"] < 60


def test_reconstruct_pseudo3d_refuses_diagonal_lines_and_single_lines():
    s = _grid_survey()
    p = s.positions_xyz.copy()
    p[12:24, 1] = 0.17 + 0.12 * (p[12:24, 0] - p[12:24, 0].min())  # the second line runs 7 deg off x
    cfg = ReconstructConfig(method="pseudo3d", eps_r=5.0, spacing_m=0.03, time_zero="none", remove_background=False)
    with pytest.raises(InvalidDataError, match=r"^pseudo-3D needs lines along x or y; line 1 \(traces 12\.\.23\) runs "
                                               r"7 deg off both: use method 'backprojection'$"):
        reconstruct(s.replace(positions_xyz=p), cfg)
    p[12:24, 1] = 0.17 + 0.07 * (p[12:24, 0] - p[12:24, 0].min())  # 4 deg: along x still
    reconstruct(s.replace(positions_xyz=p), cfg)
    one = s.replace(data=s.data[:12], positions_xyz=s.positions_xyz[:12], orientations_quat_wxyz=None)
    with pytest.raises(InvalidDataError, match=r"^pseudo-3D needs two lines at least, the survey has 1: migrate one "
                                               r"profile with 'gpr3d migrate', or use method 'backprojection'$"):
        reconstruct(one, cfg)


def test_stolt_leaves_nothing_where_the_map_reaches_past_the_record_s_frequencies():
    """Each output (kx, kz) takes the data at omega = sign(kz) v/2 sqrt(kx^2 + kz^2); where that lies beyond the
    record's highest frequency (either sign) there is nothing to take, and the image's spectrum is zero there
    (no padding, so the image's FFT is the mapped spectrum itself, made real)."""
    rng = np.random.default_rng(6)
    data = rng.standard_normal((32, 64)).astype(np.float32)
    dx, dt, eps = 0.02, 0.1e-9, 4.0
    img, _ = stolt_migrate(data, dx, dt, eps, pad=1)
    v2 = 0.5 * C / math.sqrt(eps)
    kx = 2 * np.pi * np.fft.fftfreq(32, dx)
    w = 2 * np.pi * np.fft.fftfreq(64, dt)
    kz = w / v2
    wk = np.sign(kz)[None, :] * v2 * np.sqrt(kx[:, None] ** 2 + kz[None, :] ** 2)
    beyond = (wk > w.max()) | (wk < w.min())
    # the image is real: its spectrum at k also holds the mapped spectrum at -k, so both must lie beyond
    mirror = beyond[(-np.arange(32)) % 32][:, (-np.arange(64)) % 64]
    beyond &= mirror
    assert beyond.sum() > 50
    spec = np.abs(np.fft.fft2(img.astype(np.float64)))
    assert spec[beyond].max() < 1e-4 * spec.max()


@pytest.mark.parametrize("method", ["kirchhoff", "stolt"])
def test_pseudo3d_on_a_grid_reaching_past_the_lines_with_its_own_aperture(method):
    """A grid that starts before the lines (its first columns see no trace: zero), a 30 deg aperture, and no
    orientations (every antenna heading along +x)."""
    s = _grid_survey(t0=0.0).replace(orientations_quat_wxyz=None)
    g = Grid3D(-0.06, -0.05, 0.01, 0.04, 0.03, 0.02, 11, 10, 10)
    vol, _ = pseudo3d(s, g, eps_r=5.0, method=method, aperture_deg=30.0)
    ref = _by_hand(s, method, 5.0, aperture_deg=30.0, grid=g)
    np.testing.assert_allclose(vol, ref, atol=2e-3 * ref.max())
    if method == "stolt":
        assert not vol[0].any()  # x = -0.06 m: before every line's first trace, and outside the y lines


def test_pseudo3d_kirchhoff_with_an_air_gap_refracts():
    s = _grid_survey()
    a, _ = pseudo3d(s, GRID, eps_r=5.0, air_gap_m=0.05)
    b, _ = pseudo3d(s, GRID, eps_r=5.0)
    assert not np.allclose(a, b, rtol=0.05)
