"""One profile migrated in 2D: every method focuses point diffractors where they are (the synthetic B-scan's
travel times are exact, independent of the migration code)."""

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.migration.profile import migrate_profile
from gpr3d.simulation.synthetic import point_targets_bscan

TARGETS = [(0.4, 0.25), (0.8, 0.4)]


@pytest.fixture(scope="module")
def bscan():
    s = point_targets_bscan(TARGETS, eps_r=6.0, offset_m=0.0, direct_wave=0.0, n_traces=121, trace_step_m=0.01)
    return s.replace(t0_s=2e-9)


@pytest.mark.parametrize("method, tol_x, tol_z", [("kirchhoff", 0.02, 0.02), ("backprojection", 0.02, 0.02),
                                                  ("stolt", 0.02, 0.02), ("rtm", 0.03, 0.03)])
def test_each_method_focuses_the_diffractors_where_they_are(bscan, method, tol_x, tol_z):
    prof = migrate_profile(bscan, eps_r=6.0, method=method, max_depth_m=0.6)
    env = np.abs(prof.image)
    for x, z in TARGETS:
        near = (np.abs(prof.along_m - x) < 0.1)[:, None] & (np.abs(prof.depth_m - z) < 0.1)[None, :]
        i, k = np.unravel_index(int(np.argmax(np.where(near, env, 0))), env.shape)
        assert abs(prof.along_m[i] - x) <= tol_x and abs(prof.depth_m[k] - z) <= tol_z, (method, x, z, i, k)
    # focused: the peak stands far above the image's typical level
    assert env.max() > 10 * np.median(env)


def test_trace_spacing_stands_in_for_positions_and_bad_settings_are_refused(bscan):
    bare = bscan.replace(positions_xyz=None, orientations_quat_wxyz=None)
    with pytest.raises(InvalidDataError, match="give the trace spacing"):
        migrate_profile(bare, eps_r=6.0)
    a = migrate_profile(bare, eps_r=6.0, trace_spacing_m=0.01, max_depth_m=0.6)
    b = migrate_profile(bscan, eps_r=6.0, max_depth_m=0.6)
    np.testing.assert_allclose(a.image, b.image, atol=1e-5 * np.abs(b.image).max())
    with pytest.raises(InvalidDataError, match="method must be one of"):
        migrate_profile(bscan, eps_r=6.0, method="phase-shift")
    with pytest.raises(InvalidDataError, match="eps_r must be"):
        migrate_profile(bscan, eps_r=0.5)


def test_an_air_gap_profile_focuses_with_its_gap():
    """A profile over two pipes with the antenna held 0.2 m up (the forward model's refracted rays): Kirchhoff with
    the gap finds them where they are; the default depth range leaves the air's two-way time out of the record."""
    from gpr3d.core.survey import Survey
    from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model

    x = np.arange(121) * 0.01
    pos = np.c_[x, np.zeros_like(x), np.zeros_like(x)]
    r = 0.01
    scene = ForwardScene(eps_r=6.0, pipes=[Pipe((x0, -5, -z - r), (x0, 5, -z - r), r) for x0, z in TARGETS])
    dt, ns = 0.025e-9, 480
    data = forward_model(scene, pos, offset_m=0.0, frequency_hz=1e9, n_samples=ns, dt_s=dt, air_gap_m=0.2,
                         source_delay_s=0.0, footprint="none")
    s = Survey(data=data, dt_s=dt, positions_xyz=pos, frequency_hz=1e9)
    prof = migrate_profile(s, eps_r=6.0, air_gap_m=0.2)
    record = ns * dt
    assert prof.depth_m[-1] == pytest.approx(0.5 * 0.299792458 / np.sqrt(6.0) * 1e9 * (record - 0.4 / 299792458.0)
                                              * 0.95, abs=prof.depth_m[1])
    env = np.abs(prof.image)
    for x0, z in TARGETS:
        near = (np.abs(prof.along_m - x0) < 0.1)[:, None] & (np.abs(prof.depth_m - z) < 0.1)[None, :]
        i, k = np.unravel_index(int(np.argmax(np.where(near, env, 0))), env.shape)
        assert abs(prof.along_m[i] - x0) <= 0.02 and abs(prof.depth_m[k] - z) <= 0.02, (x0, z)


@pytest.mark.parametrize("kw, words", [
    ({"air_gap_m": -0.1}, "air gap must be a height >= 0 in metres, got -0.1"),
    ({"air_gap_m": float("nan")}, "air gap must be a height >= 0 in metres, got nan"),
    ({"air_gap_m": 0.2, "method": "stolt"}, "an air gap needs method kirchhoff or backprojection, not 'stolt'"),
    ({"air_gap_m": 0.2, "method": "rtm"}, "not 'rtm'"),
    ({"max_depth_m": -1.0}, "max depth must be positive, got -1.0"),
    ({"spacing_m": 0.0}, "spacings must be positive"),
    ({"trace_spacing_m": 0.0}, "trace spacing must be a positive number of metres, got 0.0"),
])
def test_bad_profile_settings_are_named(bscan, kw, words):
    with pytest.raises(InvalidDataError, match=words.replace("(", r"\(").replace(")", r"\)")):
        migrate_profile(bscan, eps_r=6.0, **kw)


def test_rtm_needs_the_frequency_and_one_place_is_no_profile(bscan):
    with pytest.raises(InvalidDataError, match="reverse-time migration needs the antenna's centre frequency"):
        migrate_profile(bscan.replace(frequency_hz=None), eps_r=6.0, method="rtm")
    still = bscan.replace(positions_xyz=np.zeros((bscan.n_traces, 3)))
    with pytest.raises(InvalidDataError, match="the profile's traces all lie at one place"):
        migrate_profile(still, eps_r=6.0)


# --- the profile's geometry and sums, by hand -----------------------------------------------------------------------

C = 299792458.0


def _wandering_profile(n_samples=96, dt=0.1e-9, t0=0.6e-9, offset=0.06, seed=3, stops=True):
    """A short profile as a cart records it: uneven steps, the wheel stopped twice (repeated places) at the start
    and in the middle, the ground rising and falling (z, which the distance along the profile ignores) and a
    sideways drift; random data."""
    from gpr3d.core.survey import Survey

    rng = np.random.default_rng(seed)
    steps = rng.uniform(0.01, 0.03, 22)
    if stops:
        steps[[0, 9]] = 0.0
    xy = np.cumsum(np.c_[steps * 0.8, steps * 0.6], axis=0)
    xy = np.vstack([[0.0, 0.0], xy]) + [1.5, -2.0]
    z = 0.04 * np.sin(np.arange(len(xy)))
    pos = np.c_[xy, z]
    data = rng.standard_normal((len(pos), n_samples)).astype(np.float32)
    return Survey(data=data, dt_s=dt, t0_s=t0, offset_m=offset, positions_xyz=pos, frequency_hz=1e9), steps


def _stack_by_hand(data, s, dt, t0, offset, eps_r, along, depths, kirchhoff, aperture_deg=50.0):
    """The 2D diffraction stack written out: every cell gathers each trace at t0 + (|tx - p| + |p - rx|) / v,
    linearly interpolated (zero past the last sample); Kirchhoff weighs by the mean cosine of the two legs and
    keeps the cells at or below the aperture's cone from the antennas' midpoint."""
    v = C / np.sqrt(eps_r)
    n, ns = data.shape
    img = np.zeros((len(along), len(depths)))
    for j in range(n):
        row = np.r_[data[j].astype(float), 0.0, 0.0]
        for i, a in enumerate(along):
            for k, d in enumerate(depths):
                ra = np.hypot(a - (s[j] - offset / 2), d)
                rb = np.hypot(a - (s[j] + offset / 2), d)
                u = min(max((t0 + (ra + rb) / v) / dt, 0.0), ns)
                i0 = int(np.floor(u))
                val = row[i0] + (u - i0) * (row[i0 + 1] - row[i0])
                if kirchhoff:
                    first = np.ceil((abs(a - s[j]) / np.tan(np.radians(aperture_deg))) / depths[1] - 1e-12)
                    if k < first:
                        continue
                    val *= 0.5 * (d / max(ra, 1e-12) + d / max(rb, 1e-12))
                img[i, k] += val
    return img


@pytest.mark.parametrize("method", ["kirchhoff", "backprojection"])
def test_a_wandering_profile_is_stacked_as_written_out_by_hand(method):
    """Distance along the profile from the horizontal steps only (z is the ground's relief, a stopped wheel adds
    nothing), the grid from the median of the real steps, the depth range from the record after time zero, the
    tx-rx offset along the profile, the documented 50 deg aperture and obliquity for Kirchhoff only: each against a
    diffraction stack written out in the test."""
    s_, steps = _wandering_profile()
    prof = migrate_profile(s_, eps_r=4.0, method=method)
    s = np.r_[0.0, np.cumsum(steps)]
    v = C / 2.0
    step = np.median(steps[steps > 0])
    dd = 0.5 * v * s_.dt_s
    depth = 0.5 * v * (s_.n_samples * s_.dt_s - s_.t0_s) * 0.95
    np.testing.assert_allclose(prof.along_m, np.arange(int(np.floor(s[-1] / step)) + 1) * step, rtol=1e-12)
    np.testing.assert_allclose(prof.depth_m, np.arange(int(np.floor(depth / dd)) + 1) * dd, rtol=1e-12)
    assert (prof.method, prof.eps_r, prof.image.dtype) == (method, 4.0, np.float32)
    assert 0.0 <= prof.wall_s < 60.0
    ref = _stack_by_hand(s_.data, s, s_.dt_s, s_.t0_s, s_.offset_m, 4.0, prof.along_m, prof.depth_m,
                         kirchhoff=method == "kirchhoff")
    np.testing.assert_allclose(prof.image, ref, atol=2e-4 * np.abs(ref).max())


def test_given_spacings_and_an_aperture_are_used():
    s_, steps = _wandering_profile()
    s = np.r_[0.0, np.cumsum(steps)]
    prof = migrate_profile(s_, eps_r=9.0, spacing_m=0.05, depth_spacing_m=0.02, max_depth_m=0.3, aperture_deg=30.0)
    np.testing.assert_allclose(prof.along_m, np.arange(int(np.floor(s[-1] / 0.05)) + 1) * 0.05, rtol=1e-12)
    np.testing.assert_allclose(prof.depth_m, np.arange(16) * 0.02, rtol=1e-12)
    ref = _stack_by_hand(s_.data, s, s_.dt_s, s_.t0_s, s_.offset_m, 9.0, prof.along_m, prof.depth_m,
                         kirchhoff=True, aperture_deg=30.0)
    np.testing.assert_allclose(prof.image, ref, atol=2e-4 * np.abs(ref).max())


def test_stolt_resamples_uneven_traces_onto_the_grid_after_time_zero():
    """Stolt's input, written out: time zero moved to the first sample (a whole number of samples here), each grid
    column interpolated between the two traces around it along the profile; below the f-k image's last depth the
    profile is zero."""
    from gpr3d.migration.traditional import stolt_migrate

    s_, steps = _wandering_profile()
    s = np.r_[0.0, np.cumsum(steps)]
    deep = 2.0  # deeper than the record reaches: the f-k image ends above it
    prof = migrate_profile(s_, eps_r=4.0, method="stolt", max_depth_m=deep)
    assert prof.image.dtype == np.float32 and prof.method == "stolt"
    shifted = s_.data[:, 6:]  # t0 = 0.6 ns = 6 samples
    regular = np.stack([np.interp(prof.along_m, s, shifted[:, k]) for k in range(shifted.shape[1])], axis=1)
    mig, dz = stolt_migrate(regular, prof.along_m[1], s_.dt_s, 4.0)
    z = np.arange(mig.shape[1]) * dz
    inside = prof.depth_m <= z[-1]
    assert inside.sum() < len(prof.depth_m) - 5
    ref = np.stack([np.interp(prof.depth_m[inside], z, tr) for tr in mig])
    np.testing.assert_allclose(prof.image[:, inside], ref, atol=1e-4 * np.abs(ref).max())
    assert np.all(prof.image[:, ~inside] == 0.0)


def test_the_profile_settings_edges():
    """eps_r 1 (air) and 1.5 are permittivities; a zero depth or depth spacing is not; a profile that only moves at
    its last trace, or is shorter than a metre, still migrates."""
    s_, _ = _wandering_profile()
    for eps in (1.0, 1.5):
        assert migrate_profile(s_, eps_r=eps, max_depth_m=0.2).eps_r == eps
    with pytest.raises(InvalidDataError, match=r"^max depth must be positive, got 0\.0$"):
        migrate_profile(s_, eps_r=4.0, max_depth_m=0.0)
    with pytest.raises(InvalidDataError, match=r"^spacings must be positive, got 0\.05 along and 0\.0 in depth$"):
        migrate_profile(s_, eps_r=4.0, spacing_m=0.05, depth_spacing_m=0.0)
    with pytest.raises(InvalidDataError, match=r"^the image of \d{7} x 33 cells is too large: use larger spacings$"):
        migrate_profile(s_, eps_r=4.0, spacing_m=1e-7, max_depth_m=2.0, depth_spacing_m=0.0625)
    last = s_.replace(positions_xyz=np.r_[np.zeros((s_.n_traces - 1, 3)), [[0.3, 0.0, 0.0]]])
    prof = migrate_profile(last, eps_r=4.0, max_depth_m=0.2)
    np.testing.assert_allclose(prof.along_m, [0.0, 0.3])


@pytest.mark.parametrize("kw, words", [
    ({"method": "phase-shift"}, "method must be one of kirchhoff, backprojection, stolt, rtm, got 'phase-shift'"),
    ({"eps_r": 0.5}, "eps_r must be a relative permittivity >= 1, got 0.5"),
    ({"eps_r": float("nan")}, "eps_r must be a relative permittivity >= 1, got nan"),
    ({"air_gap_m": 0.1, "method": "backprojection", "max_depth_m": 0.2}, None),
])
def test_profile_messages_in_full(kw, words):
    s_, _ = _wandering_profile()
    args = {"eps_r": 4.0, **kw}
    if words is None:
        assert migrate_profile(s_, **args).depth_m[-1] == pytest.approx(26 * 0.5 * C / 2 * 0.1e-9, rel=1e-12, abs=0)
        return
    with pytest.raises(InvalidDataError, match="^" + words.replace("(", r"\(").replace(")", r"\)") + "$"):
        migrate_profile(s_, **args)


def test_profile_place_messages_in_full():
    s_, _ = _wandering_profile()
    with pytest.raises(InvalidDataError, match="^the profile has no trace positions: give the trace spacing$"):
        migrate_profile(s_.replace(positions_xyz=None), eps_r=4.0)
    with pytest.raises(InvalidDataError,
                       match="^the profile's traces all lie at one place: nothing to migrate along$"):
        migrate_profile(s_.replace(positions_xyz=np.ones((s_.n_traces, 3))), eps_r=4.0)
    with pytest.raises(InvalidDataError, match="^reverse-time migration needs the antenna's centre frequency$"):
        migrate_profile(s_.replace(frequency_hz=None), eps_r=4.0, method="rtm")


def test_rtm_section_is_resampled_onto_the_profile_grid():
    """The RTM section (on its own cells) read onto the profile's grid: linear in depth and along the line, and
    zero below its deepest row (just above 0.2 m here) rather than that row repeated."""
    from gpr3d.migration.rtm import rtm_bscan

    s_, steps = _wandering_profile(stops=False)  # (RTM takes strictly increasing places)
    s = np.r_[0.0, np.cumsum(steps)]
    prof = migrate_profile(s_, eps_r=4.0, method="rtm", max_depth_m=0.2, depth_spacing_m=0.004)
    res = rtm_bscan(s_.data, s, s_.dt_s, frequency_hz=1e9, depth_m=0.2, eps_r=4.0, t0_s=s_.t0_s)
    inside = prof.depth_m <= res.depth_m[-1]
    assert (~inside).sum() >= 1
    ref = np.empty((len(prof.along_m), int(inside.sum())))
    for k, d in enumerate(prof.depth_m[inside]):
        col = [np.interp(d, res.depth_m, row) for row in res.image]
        ref[:, k] = np.interp(prof.along_m, res.x_m, col)
    np.testing.assert_allclose(prof.image[:, inside], ref, atol=1e-5 * np.abs(ref).max())
    assert np.all(prof.image[:, ~inside] == 0.0) and np.abs(prof.image).max() > 0


def test_rtm_takes_the_first_trace_where_the_wheel_stopped():
    """A stopped wheel repeats a place along the profile; RTM (which needs places in order) takes the first trace
    recorded there: the same section as the profile without the repeats."""
    s_, _ = _wandering_profile(n_samples=64)
    moved = np.r_[True, np.diff(np.r_[0.0, np.cumsum(np.hypot(*np.diff(s_.positions_xyz[:, :2], axis=0).T))]) > 0]
    assert (~moved).sum() == 2
    a = migrate_profile(s_, eps_r=4.0, method="rtm", max_depth_m=0.15, spacing_m=0.02)
    b = migrate_profile(s_.replace(data=s_.data[moved], positions_xyz=s_.positions_xyz[moved]), eps_r=4.0,
                        method="rtm", max_depth_m=0.15, spacing_m=0.02)
    np.testing.assert_array_equal(a.image, b.image)


def test_stolt_on_exactly_even_steps_reads_the_first_and_last_traces():
    """Steps of exactly 0.25 m: the grid's columns fall on the traces, the first on trace 0 and the last on the
    last trace, and Stolt's input is the traces themselves."""
    from gpr3d.core.survey import Survey
    from gpr3d.migration.traditional import stolt_migrate

    rng = np.random.default_rng(5)
    n = 9
    data = rng.standard_normal((n, 64)).astype(np.float32)
    s = Survey(data=data, dt_s=0.1e-9, positions_xyz=np.c_[np.arange(n) * 0.25, np.zeros((n, 2))])
    prof = migrate_profile(s, eps_r=4.0, method="stolt", max_depth_m=0.3)
    np.testing.assert_allclose(prof.along_m, np.arange(n) * 0.25)
    mig, dz = stolt_migrate(data, 0.25, 0.1e-9, 4.0)
    ref = np.stack([np.interp(prof.depth_m, np.arange(mig.shape[1]) * dz, tr, right=0.0) for tr in mig])
    np.testing.assert_allclose(prof.image, ref, atol=1e-5 * np.abs(ref).max())
