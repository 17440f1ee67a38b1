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
