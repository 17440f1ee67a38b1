"""Migration velocity analysis: the eps_r that focuses a random-motion survey's 3D image is the true one, where a
hyperbola read along oblique crossings comes out low."""

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.survey import Survey
from gpr3d.migration.velocity import focus_eps, image_entropy
from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model
from gpr3d.simulation.paths import random_walk


@pytest.mark.parametrize("eps", [5.0, 12.0])
def test_focus_finds_the_host_permittivity_on_oblique_crossings(eps):
    scene = ForwardScene(eps_r=eps, pipes=[Pipe((0.1, 0.3, -0.35), (1.1, 0.9, -0.35), 0.03),
                                           Pipe((0.3, 1.1, -0.25), (1.0, 0.1, -0.25), 0.02)])
    traj = random_walk(1500, area=((0.0, 1.2), (0.0, 1.2)), step_m=0.01, seed=3)
    f, ns, win = 800e6, 256, 16e-9 * np.sqrt(eps / 5.0)
    data = forward_model(scene, traj.positions_xyz, traj.orientations_quat_wxyz, offset_m=0.05, frequency_hz=f,
                         n_samples=ns, time_window_s=win, air_wave=1.0, ground_wave=0.3)
    s = Survey(data=data, dt_s=win / ns, positions_xyz=traj.positions_xyz,
               orientations_quat_wxyz=traj.orientations_quat_wxyz, offset_m=0.05, frequency_hz=f)
    grid = np.linspace(np.sqrt(3.0), np.sqrt(20.0), 9) ** 2
    r = focus_eps(s, eps_grid=grid, spacing_m=0.03, max_depth_m=0.5)
    assert not r["at_edge"]
    assert r["eps_r"] == pytest.approx(eps, rel=0.12), r
    ent = np.array(r["entropy"])
    assert ent[np.argmin(np.abs(grid - eps))] < ent[0] and ent[np.argmin(np.abs(grid - eps))] < ent[-1]


def test_entropy_is_lower_for_a_focused_image_and_inputs_are_checked():
    sharp = np.zeros((20, 20))
    sharp[10, 10] = 1.0
    blurred = np.exp(-((np.arange(20)[:, None] - 10) ** 2 + (np.arange(20)[None] - 10) ** 2) / 20.0)
    assert image_entropy(sharp) == pytest.approx(0.0) and image_entropy(blurred) > 2.0
    with pytest.raises(InvalidDataError, match="three increasing"):
        focus_eps(None, eps_grid=[4.0, 9.0])


def test_entropy_by_hand():
    assert image_entropy([1.0, -1.0, 0.0]) == pytest.approx(np.log(2))  # energy, not amplitude: two equal voxels
    assert image_entropy(np.ones((2, 2, 2))) == pytest.approx(np.log(8))
    assert image_entropy([2.0, 1.0]) == pytest.approx(-(0.8 * np.log(0.8) + 0.2 * np.log(0.2)))
    assert np.isnan(image_entropy(np.zeros(5)))


def _stub(monkeypatch, entropy_of_eps):
    """reconstruct() and image_entropy() replaced: each eps_r tried gives the entropy ``entropy_of_eps(eps)``."""
    import types

    import gpr3d.migration.reconstruct as rec
    import gpr3d.migration.velocity as vel

    tried = []

    def fake(survey, cfg, boxes=None, **parts):
        assert parts == {"with_noise_map": False, "with_targets": False}  # the envelope is all it reads
        tried.append((cfg.eps_r, cfg.spacing_m, cfg.max_depth_m, cfg.aperture_deg, boxes, cfg.depth_spacing_m,
                      cfg.coarse_to_fine))
        return types.SimpleNamespace(envelope=cfg.eps_r)

    monkeypatch.setattr(rec, "reconstruct", fake)
    monkeypatch.setattr(vel, "image_entropy", entropy_of_eps)
    return tried


def test_the_best_eps_is_the_parabola_vertex_in_slowness(monkeypatch):
    """Entropy (sqrt(eps) - 2.9)^2 + 1 over the default grid: the vertex in sqrt(eps_r) is exact, 2.9^2 = 8.41."""
    tried = _stub(monkeypatch, lambda eps: (np.sqrt(eps) - 2.9) ** 2 + 1.0)
    r = focus_eps("survey", boxes=[[1, 2, 3, 4]], spacing_m=0.05, max_depth_m=0.8, aperture_deg=40.0, window="depth")
    assert r["eps_r"] == pytest.approx(8.41, rel=1e-9, abs=0) and not r["at_edge"]
    np.testing.assert_allclose(r["eps_grid"], np.linspace(np.sqrt(3.0), np.sqrt(25.0), 12) ** 2)
    np.testing.assert_allclose(r["entropy"], (np.sqrt(r["eps_grid"]) - 2.9) ** 2 + 1.0)
    # every voxel migrated (the entropy reads them all), whatever reconstruct's default
    assert [t[1:] for t in tried] == [(0.05, 0.8, 40.0, [[1, 2, 3, 4]], None, False)] * 12


def test_in_migrated_time_the_depth_range_and_cell_follow_the_wave_speed(monkeypatch):
    """window="time" (the default): at eps_r 4, 9 and 36 the middle is sqrt(4 x 36) = 12, so the depth and the depth
    cell are the given ones x sqrt(12 / eps_r) (1.732, 1.155, 0.577): the two-way time to the grid's bottom is the
    same at every eps_r. The lateral cell stays."""
    tried = _stub(monkeypatch, lambda eps: (np.sqrt(eps) - 3.0) ** 2)
    focus_eps("s", eps_grid=[4.0, 9.0, 36.0], spacing_m=0.05, max_depth_m=0.8)
    k = np.sqrt(12.0 / np.array([4.0, 9.0, 36.0]))
    np.testing.assert_allclose([t[2] for t in tried], 0.8 * k, rtol=1e-12)
    np.testing.assert_allclose([t[5] for t in tried], 0.05 * k, rtol=1e-12)
    assert [t[1] for t in tried] == [0.05] * 3
    # the time to the bottom, 2 depth / v, v = c / sqrt(eps_r): one value for all three
    times = 2 * 0.8 * k * np.sqrt([4.0, 9.0, 36.0]) / 299792458.0
    np.testing.assert_allclose(times, times[0], rtol=1e-12)
    tried.clear()
    focus_eps("s", eps_grid=[4.0, 9.0, 36.0])  # no depth given: the record's (or its signal's) scales by itself
    assert [(t[2], t[5]) for t in tried] == [(None, pytest.approx(0.04 * kk, rel=1e-12)) for kk in k]
    tried.clear()
    focus_eps("s", eps_grid=[4.0, 9.0, 36.0], spacing_m=None, max_depth_m=0.5)  # the data's cell: left to them
    assert [t[5] for t in tried] == [None] * 3
    with pytest.raises(InvalidDataError, match="^window must be 'time' or 'depth', got 'migrated'$"):
        focus_eps("s", eps_grid=[4.0, 9.0, 36.0], window="migrated")


def test_a_best_eps_at_the_grid_edge_is_flagged(monkeypatch):
    _stub(monkeypatch, lambda eps: eps)  # lower is always better: the first value
    r = focus_eps("survey", eps_grid=[4.0, 9.0, 16.0])
    assert r["eps_r"] == 4.0 and r["at_edge"]
    _stub(monkeypatch, lambda eps: -eps)
    r = focus_eps("survey", eps_grid=[4.0, 9.0, 16.0])
    assert r["eps_r"] == 16.0 and r["at_edge"]


def test_a_flat_or_empty_focus(monkeypatch):
    # entropies 1, 0.5, 0.5, 2 at sqrt(eps_r) 2, 3, 4, 5: the parabola through the best three (2, 3, 4) has its
    # vertex half-way between the equal two, sqrt(eps_r) = 3.5
    _stub(monkeypatch, lambda eps: {4.0: 1.0, 9.0: 0.5, 16.0: 0.5, 25.0: 2.0}[eps])
    r = focus_eps("survey", eps_grid=[4.0, 9.0, 16.0, 25.0])
    assert r["eps_r"] == pytest.approx(12.25, rel=1e-9, abs=0) and not r["at_edge"]
    # a neighbour whose image was empty (NaN): no parabola, the best grid value stands
    _stub(monkeypatch, lambda eps: {4.0: float("nan"), 9.0: 0.5, 16.0: 1.0}[eps])
    assert focus_eps("survey", eps_grid=[4.0, 9.0, 16.0])["eps_r"] == 9.0
    _stub(monkeypatch, lambda eps: float("nan"))
    with pytest.raises(InvalidDataError, match="the migrated image is empty for every eps_r"):
        focus_eps("survey", eps_grid=[4.0, 9.0, 16.0])
    for bad in ([4.0, 4.0, 9.0], [0.5, 4.0, 9.0], [4.0, float("inf"), 9.0]):
        with pytest.raises(InvalidDataError, match="at least three increasing values >= 1"):
            focus_eps("survey", eps_grid=bad)


def test_entropy_in_float64_and_the_defaults_passed_on(monkeypatch):
    big = np.array([1e20, 1e20], np.float32)  # squares overflow float32
    assert image_entropy(big) == pytest.approx(np.log(2))
    tried = _stub(monkeypatch, lambda eps: (np.sqrt(eps) - 3.0) ** 2)
    seen = []
    import gpr3d.migration.reconstruct as rec

    inner = rec.reconstruct

    def spy(survey, cfg, boxes=None, **parts):
        seen.append(survey)
        return inner(survey, cfg, boxes=boxes, **parts)

    monkeypatch.setattr(rec, "reconstruct", spy)
    r = focus_eps("the survey", eps_grid=[[4.0], [9.0], [16.0]])  # any shape: flattened
    assert set(seen) == {"the survey"} and r["eps_grid"] == [4.0, 9.0, 16.0]
    assert [t[1:4] for t in tried] == [(0.04, None, 50.0)] * 3
    np.testing.assert_allclose([t[5] for t in tried], 0.04 * np.sqrt(8.0 / np.array([4.0, 9.0, 16.0])), rtol=1e-12)
    assert focus_eps("s", eps_grid=[1.0, 4.0, 9.0])["eps_grid"][0] == 1.0  # eps_r 1 is allowed
    assert focus_eps("s", eps_grid=[4.0, 4.5, 5.0])["eps_grid"] == [4.0, 4.5, 5.0]  # steps under one


def test_velocity_messages_exactly(monkeypatch):
    with pytest.raises(InvalidDataError, match="^eps_grid must hold at least three increasing values >= 1$"):
        focus_eps("s", eps_grid=[4.0, 9.0])
    _stub(monkeypatch, lambda eps: float("nan"))
    with pytest.raises(InvalidDataError, match="^the migrated image is empty for every eps_r: no data to focus$"):
        focus_eps("s", eps_grid=[4.0, 9.0, 16.0])
    # best at the last value: no parabola (it would need a value beyond the grid)
    _stub(monkeypatch, lambda eps: {4.0: 3.0, 9.0: 2.0, 16.0: 1.0}[eps])
    assert focus_eps("s", eps_grid=[4.0, 9.0, 16.0]) ["eps_r"] == 16.0
    # a vertex outside the best three is held to them
    _stub(monkeypatch, lambda eps: {4.0: 1.0, 9.0: 0.0, 16.0: 10.0, 25.0: 20.0}[eps])
    r = focus_eps("s", eps_grid=[4.0, 9.0, 16.0, 25.0])
    assert 4.0 <= r["eps_r"] <= 16.0


def test_the_parabola_next_to_the_last_value(monkeypatch):
    """Best at the second-to-last value: still a parabola through it and its neighbours (the vertex, not the grid
    value)."""
    _stub(monkeypatch, lambda eps: (np.sqrt(eps) - 3.8) ** 2)
    r = focus_eps("s", eps_grid=[4.0, 9.0, 16.0, 25.0])
    assert r["eps_r"] == pytest.approx(3.8**2, rel=1e-9, abs=0) and not r["at_edge"]
