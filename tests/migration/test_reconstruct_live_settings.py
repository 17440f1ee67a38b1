"""The settings that let a batch reconstruct repeat live mode: a given time zero, a moving-window background and
voxels on the spacing's lattice, each checked against what it must equal."""

import numpy as np
import pytest
from scipy.ndimage import uniform_filter1d

from gpr3d import Survey
from gpr3d.core.errors import InvalidDataError
from gpr3d.core.grid import Grid3D
from gpr3d.core.poses import quat_from_yaw
from gpr3d.migration.reconstruct import (
    ReconstructConfig,
    check_config,
    normalise_by_fold,
    reconstruct,
    record_depth_m,
)
from gpr3d.processing.timezero import shift_traces
from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model

EPS = 6.0


@pytest.fixture(scope="module")
def survey():
    pos, yaw = [], []
    for k in range(5):
        x = np.linspace(0.0, 1.0, 60)
        pos.append(np.c_[x if k % 2 == 0 else x[::-1], np.full(60, 0.013 + 0.1 * k), np.zeros(60)])
        yaw.append(np.full(60, 0.0 if k % 2 == 0 else np.pi))
    pos, q = np.concatenate(pos), quat_from_yaw(np.concatenate(yaw))
    scene = ForwardScene(eps_r=EPS, pipes=[Pipe((0.5, -0.5, -0.22), (0.5, 1.5, -0.22), 0.02)])
    data = forward_model(scene, pos, q, offset_m=0.05, frequency_hz=800e6, n_samples=128, time_window_s=12e-9,
                         air_wave=1.0, ground_wave=0.5)
    return Survey(data=data, dt_s=12e-9 / 128, offset_m=0.05, frequency_hz=800e6, eps_r=EPS, positions_xyz=pos,
                  orientations_quat_wxyz=q)


BASE = dict(eps_r=EPS, spacing_m=0.03, aperture_deg=45.0)


def test_a_given_time_zero_cuts_there(survey):
    est = reconstruct(survey, ReconstructConfig(**BASE))
    t0 = survey.time_zero(method="peak", search_s=min(survey.time_window_s / 4, 10e-9)).history[-1]["result"]["t0_s"]
    given = reconstruct(survey, ReconstructConfig(**BASE, time_zero_s=t0))
    np.testing.assert_array_equal(given.image, est.image)
    # the same as cutting by hand and telling reconstruct there is no time zero to find
    by_hand = survey.replace(data=shift_traces(survey.data, (t0 + 2 * survey.dt_s) / survey.dt_s))
    a = reconstruct(by_hand, ReconstructConfig(**BASE, time_zero="none"))
    b = reconstruct(survey, ReconstructConfig(**BASE, time_zero_s=t0 + 2 * survey.dt_s))
    np.testing.assert_array_equal(a.image, b.image)
    assert not np.allclose(a.image, est.image)


def test_a_moving_background_window_is_the_centred_moving_mean(survey):
    w = 16
    x = survey.data.astype(np.float64)
    cleaned = (x - uniform_filter1d(x, size=w, axis=0, mode="nearest")).astype(np.float32)
    a = reconstruct(survey.replace(data=cleaned), ReconstructConfig(**BASE, time_zero="none",
                                                                  remove_background=False))
    b = reconstruct(survey, ReconstructConfig(**BASE, time_zero="none", background_window=w))
    np.testing.assert_allclose(b.image, a.image, rtol=0, atol=1e-6 * np.abs(a.image).max())
    whole = reconstruct(survey, ReconstructConfig(**BASE, time_zero="none"))
    assert np.abs(whole.image - b.image).max() > 1e-3 * np.abs(a.image).max()


def test_a_trailing_background_window_ends_at_each_trace(survey):
    w = 16
    x = survey.data.astype(np.float64)
    bg = uniform_filter1d(x, size=w, axis=0, mode="nearest", origin=(w - 1) // 2)
    # (scipy's trailing window, checked against one by hand in tests/processing/test_filters.py)
    a = reconstruct(survey.replace(data=(x - bg).astype(np.float32)),
                    ReconstructConfig(**BASE, time_zero="none", remove_background=False))
    b = reconstruct(survey, ReconstructConfig(**BASE, time_zero="none", background_window=w, background_trailing=True))
    np.testing.assert_allclose(b.image, a.image, rtol=0, atol=1e-6 * np.abs(a.image).max())
    centred = reconstruct(survey, ReconstructConfig(**BASE, time_zero="none", background_window=w))
    assert np.abs(centred.image - b.image).max() > 1e-3 * np.abs(a.image).max()
    # without a window there is nothing to trail: the whole survey's mean, as without the flag
    whole = reconstruct(survey, ReconstructConfig(**BASE, time_zero="none"))
    np.testing.assert_array_equal(
        reconstruct(survey, ReconstructConfig(**BASE, time_zero="none", background_trailing=True)).image, whole.image)


def test_lattice_grids_sit_on_multiples_of_the_spacing(survey):
    g = reconstruct(survey, ReconstructConfig(**BASE, lattice=True)).grid
    # positions x 0..1, y 0.013..0.413; pad 0.1: corner (-0.1, -0.087) rounded down to (-0.12, -0.09)
    assert (g.x0, g.y0) == pytest.approx((-0.12, -0.09))
    assert g.x[-1] == pytest.approx(1.11) and g.y[-1] == pytest.approx(0.54)  # 1.1 and 0.513 rounded up
    plain = reconstruct(survey, ReconstructConfig(**BASE)).grid
    assert (plain.x0, plain.y0) == pytest.approx((-0.1, -0.087))


def test_covering_on_a_lattice_by_hand():
    g = Grid3D.covering([[0.05, -0.01, 0], [0.31, 0.2, 0]], depth_m=0.5, spacing_m=0.1, pad_m=0.0, lattice=True)
    assert (g.x0, g.y0, g.nx, g.ny) == pytest.approx((0.0, -0.1, 5, 4))
    assert (g.d0, g.nd) == (0.1, 5)


@pytest.mark.parametrize("field, value, message", [
    ("background_window", 1, "background_window must be a whole number of traces >= 2"),
    ("background_window", 2.5, "background_window must be"),
    ("background_window", True, "background_window must be"),
    ("time_zero_s", -1e-9, "time_zero_s must be >= 0"),
    ("lattice", "yes", "lattice must be true or false"),
    ("background_trailing", 1, "background_trailing must be true or false"),
])
def test_wrong_live_settings_are_named(field, value, message):
    with pytest.raises(InvalidDataError, match=message):
        check_config(ReconstructConfig(**{field: value}))


def test_a_time_zero_beyond_the_record_is_refused(survey):
    with pytest.raises(InvalidDataError, match="time_zero_s 1.2e-08 s lies beyond the record"):
        reconstruct(survey, ReconstructConfig(**BASE, time_zero_s=12e-9))


def test_normalise_by_fold_holds_the_fold_at_five_percent_of_its_largest():
    img = np.array([4.0, 4.0, 4.0])
    fold = np.array([16.0, 0.0, 100.0])
    out, noise = normalise_by_fold(img, fold, "sqrt_fold", img * 2)
    np.testing.assert_allclose(out, [1.0, 4 / np.sqrt(5.0), 0.4])
    np.testing.assert_allclose(noise, 2 * out)
    out, none = normalise_by_fold(img, fold, "fold", fold_max=400.0)
    np.testing.assert_allclose(out, [0.2, 0.2, 0.04])
    assert none is None


def test_the_record_reaches_95_percent_of_its_two_way_time_less_the_air_gap():
    assert record_depth_m(1e8, 20e-9) == pytest.approx(0.95)  # 0.5 * 1e8 m/s * 20 ns * 0.95
    # an antenna 0.3 m up spends 2 ns of the record in air
    assert record_depth_m(1e8, 20e-9, 0.3) == pytest.approx(0.5 * 1e8 * (20e-9 - 0.6 / 299792458.0) * 0.95)


def test_the_default_depth_is_the_record_s_reach(survey):
    g = reconstruct(survey, ReconstructConfig(**BASE)).grid
    est = survey.time_zero(method="peak", search_s=min(survey.time_window_s / 4, 10e-9))
    reach = record_depth_m(299792458.0 / np.sqrt(EPS), est.n_samples * est.dt_s)
    assert g.depth[-1] <= reach < g.depth[-1] + g.dd
