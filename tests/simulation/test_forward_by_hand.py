"""The forward model's tables and options against values worked out in the test: reflection coefficients, echo
tables, wavelets, amplitudes and arrival times of a layer, a box and the direct waves, attenuation, polarisation,
orientations, clutter, and the scene conversion."""

import math
import re

import numpy as np
import pytest

from gpr3d.core.poses import quat_from_yaw
from gpr3d.core.units import C0
from gpr3d.simulation.forward import (
    Box, ForwardScene, Layer, Pipe, Sphere, _echo_table, _gamma, forward_model, scene_to_forward, simulate_scene_bscan,
    wavelet_table,
)
from gpr3d.simulation.synthetic import ricker


def test_reflection_coefficients_and_echo_tables():
    assert _gamma(9.0, "pec", 4.0) == -1.0
    assert _gamma(9.0, "dielectric", 4.0) == pytest.approx((3 - 2) / (3 + 2))
    assert _gamma(4.0, "dielectric", 81.0) == pytest.approx((2 - 9) / (2 + 9))
    assert _echo_table(9.0, "pec", 1.0, 0.05) == [[0.0, -1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    # an air void of 5 cm radius in eps 9: near side G = 0.5, far side 4 r sqrt(1) / c later with -(1 - G^2) G,
    # its extra path 2 r sqrt(9 / 1) in host units
    np.testing.assert_allclose(_echo_table(9.0, "dielectric", 1.0, 0.05),
                               [[0.0, 0.5, 0.0], [0.2 / C0, -0.75 * 0.5, 0.3], [0.0, 0.0, 0.0]], rtol=1e-12)
    # a water-filled PVC pipe (wall 1 cm of eps 3): the wall's outer face, then the water at 2 wall sqrt(3) / c,
    # through (1 - G_out^2), and the water's far side
    g_out = (3 - math.sqrt(3)) / (3 + math.sqrt(3))
    thr = 1 - g_out**2
    g_in = (math.sqrt(3) - 9) / (math.sqrt(3) + 9)
    d = 2 * 0.01 * math.sqrt(3) / C0
    np.testing.assert_allclose(_echo_table(9.0, "dielectric", 81.0, 0.06, 0.01, 3.0),
                               [[0.0, g_out, 0.0], [d, thr * g_in, 0.0],
                                [d + 4 * 0.05 * 9 / C0, -thr * (1 - g_in**2) * g_in, 2 * 0.05 * math.sqrt(9 / 81)]],
                               rtol=1e-12)
    # a hollow steel pipe with a wall: its outer face, then the metal through the wall
    np.testing.assert_allclose(_echo_table(9.0, "pec", 1.0, 0.06, 0.01, 3.0),
                               [[0.0, g_out, 0.0], [d, -thr, 0.0], [0.0, 0.0, 0.0]], rtol=1e-12)


@pytest.mark.parametrize("kind", ["ricker", "ricker_d1", "ricker_half"])
def test_wavelet_tables(kind):
    f = 1e9
    t0, step, w = wavelet_table(f, kind)
    assert step == pytest.approx(1 / (400 * f), rel=1e-12, abs=0)
    t = t0 + step * np.arange(w.size)
    assert t0 >= -3 / f - 1e-15 and t[-1] <= 3 / f + 1e-15 and t0 < -3 / f + step  # |t| <= 3 / f, all of it
    assert np.abs(w).max() == pytest.approx(1.0)
    if kind == "ricker":
        np.testing.assert_allclose(w, ricker(t, f), atol=1e-12)
        assert w[np.argmin(np.abs(t))] == pytest.approx(1.0)
    elif kind == "ricker_d1":
        d = np.gradient(ricker(t, f), step)
        np.testing.assert_allclose(w, d / np.abs(d).max(), atol=2e-3)
    else:  # the half-derivative: its own half-derivative is the derivative (up to the normalisation)
        spec = np.fft.rfft(w, 4 * w.size)
        om = 2 * np.pi * np.fft.rfftfreq(4 * w.size, step)
        twice = np.fft.irfft(spec * (1j * om) ** 0.5, 4 * w.size)[: w.size]
        d = np.gradient(ricker(t, f), step)
        assert np.corrcoef(twice, d)[0, 1] > 0.999
    assert wavelet_table(f, kind, step_s=1e-12)[1] == 1e-12
    if kind == "ricker":  # the default kind
        np.testing.assert_array_equal(wavelet_table(f)[2], w)
    with pytest.raises(ValueError, match=re.escape("unknown wavelet 'sinc' (ricker, ricker_d1, ricker_half)")):
        wavelet_table(f, "sinc")


F, DT = 1e9, 0.005e-9


def _peak(tr):
    k = int(np.argmax(np.abs(tr)))
    return k * DT, float(tr[k])


@pytest.mark.parametrize("spreading, power", [("3d", 1.0), ("2d", 0.5)])
def test_a_layer_echo_by_hand(spreading, power):
    """Normal incidence on a layer 0.8 m down in eps 4 over eps 9: at sqrt(2)/f + 2 d / v, amplitude
    G / path (3D) or G / sqrt(path) (2D), times (f / 1 GHz)^(1 or 1/2), times exp(-alpha path) for a lossy host."""
    f = 0.5e9
    for sigma in (0.0, 0.01):
        scene = ForwardScene(eps_r=4.0, conductivity_s_m=sigma, layers=[Layer(0.8, 9.0)])
        tr = forward_model(scene, [[0.0, 0.0, 0.0]], frequency_hz=f, n_samples=3000, dt_s=DT, footprint="none",
                           spreading=spreading)[0]
        t, a = _peak(tr)
        v = C0 / 2
        assert t == pytest.approx(math.sqrt(2) / f + 1.6 / v, abs=DT)
        g = (2 - 3) / (2 + 3)
        alpha = sigma / 2 * math.sqrt(4e-7 * math.pi / (4 * 8.8541878128e-12))
        want = g / (1.6 if spreading == "3d" else math.sqrt(1.6)) * (f / 1e9) ** power
        assert a == pytest.approx(want * math.exp(-alpha * 1.6), rel=2e-3)
    # a given source delay moves it; time_window_s gives dt = window / n
    tr2 = forward_model(scene, [[0.0, 0.0, 0.0]], frequency_hz=f, n_samples=3000, time_window_s=3000 * DT,
                        source_delay_s=1e-9, footprint="none", spreading=spreading)[0]
    assert _peak(tr2)[0] == pytest.approx(1e-9 + 1.6 / (C0 / 2), abs=DT)


def test_direct_waves_and_a_box_by_hand():
    """The air wave at offset / c and the ground wave at offset / v with their amplitudes; a metal box 0.3 m under
    the antennas answers at 2 sqrt(0.3^2 + (offset/2)^2) / v with -1 / path."""
    off = 0.2
    scene = ForwardScene(eps_r=9.0)
    tr = forward_model(scene, [[0.0, 0.0, 0.0]], offset_m=off, frequency_hz=F, n_samples=1000, dt_s=DT,
                       air_wave=0.7, ground_wave=0.4, source_delay_s=0.0)[0]
    t = np.arange(1000) * DT
    w0, step, w = wavelet_table(F, "ricker")
    want = (0.7 * np.interp(t - off / C0, w0 + step * np.arange(w.size), w, left=0, right=0)
            + 0.4 * np.interp(t - off / (C0 / 3), w0 + step * np.arange(w.size), w, left=0, right=0))
    np.testing.assert_allclose(tr, want, atol=2e-3)
    box = ForwardScene(eps_r=9.0, boxes=[Box((-1.0, -1.0, -0.5), (1.0, 1.0, -0.3), "pec")])
    tr = forward_model(box, [[0.0, 0.0, 0.0]], offset_m=off, frequency_hz=F, n_samples=2000, dt_s=DT,
                       footprint="none", source_delay_s=0.0)[0]
    path = 2 * math.hypot(0.3, off / 2)
    t_b, a_b = _peak(tr)
    assert t_b == pytest.approx(path / (C0 / 3), abs=DT) and a_b == pytest.approx(-1.0 / path, rel=2e-3)


def test_polarisation_floors_and_orientations():
    """The dipoles lie along the antenna's y axis: a pipe along y gives its whole echo, one along x (across the
    dipoles) a metal pipe's floor (0.05, or as given) or a dielectric one's 0.3. Quaternions and headings agree."""
    def echo(pipe_axis, material, heading=0.0, floor=0.05, quat=False):
        d = np.asarray(pipe_axis, float)
        p = Pipe(tuple(-5 * d + [0, 0, -0.3]), tuple(5 * d + [0, 0, -0.3]), 0.02, material, 3.0 if material != "pec"
                 else 1.0)
        kw = {"orientations_quat_wxyz": quat_from_yaw([heading])} if quat else {"headings_rad": [heading]}
        tr = forward_model(ForwardScene(eps_r=9.0, pipes=[p]), [[0.0, 0.0, 0.0]], frequency_hz=F, n_samples=1500,
                           dt_s=DT, footprint="none", polarisation_floor=floor, **kw)[0]
        return np.abs(tr).max()

    for mat, floor in (("pec", 0.05), ("dielectric", 0.3)):
        assert echo((1, 0, 0), mat) / echo((0, 1, 0), mat) == pytest.approx(floor, rel=1e-3)
    assert echo((1, 0, 0), "pec", floor=0.2) / echo((0, 1, 0), "pec") == pytest.approx(0.2, rel=1e-3)
    # turned 90 deg, the antenna's dipoles lie along x: the pipe along x now gives its whole echo
    assert echo((1, 0, 0), "pec", heading=math.pi / 2) == pytest.approx(echo((0, 1, 0), "pec"), rel=1e-6)
    assert echo((1, 0, 0), "pec", heading=math.pi / 2, quat=True) == pytest.approx(echo((0, 1, 0), "pec"), rel=1e-6)
    # a hollow metal pipe (with a wall) answers like a dielectric one across the dipoles
    hollow = Pipe((-5, 0, -0.3), (5, 0, -0.3), 0.05, "pec", 1.0, 0.01, 3.0)
    along = Pipe((0, -5, -0.3), (0, 5, -0.3), 0.05, "pec", 1.0, 0.01, 3.0)
    a, b = (np.abs(forward_model(ForwardScene(eps_r=9.0, pipes=[p]), [[0, 0, 0]], frequency_hz=F, n_samples=1500,
                                 dt_s=DT, footprint="none")[0]).max() for p in (hollow, along))
    assert a / b == pytest.approx(0.3, rel=1e-3)


def test_clutter_noise_seeds_and_the_out_array():
    scene = ForwardScene(eps_r=6.0)
    pos = np.c_[np.linspace(0, 1, 5), np.zeros(5), np.zeros(5)]
    kw = dict(frequency_hz=F, n_samples=600, dt_s=0.02e-9, footprint="none")
    assert not forward_model(scene, pos, **kw).any()  # an empty scene is silent
    a = forward_model(scene, pos, clutter=6, **kw)
    assert np.array_equal(a, forward_model(scene, pos, clutter=6, seed=0, **kw)) and a.any()
    b = forward_model(scene, pos, clutter=6, seed=1, **kw)
    assert not np.allclose(a, b)
    # clutter amplitude scales every scatterer's echo
    np.testing.assert_allclose(forward_model(scene, pos, clutter=6, clutter_amplitude=0.1, **kw), 2 * a, rtol=1e-5,
                               atol=1e-7)
    n = forward_model(scene, pos, noise=0.1, **kw)
    assert 0.08 < n.std() < 0.12 and np.array_equal(n, forward_model(scene, pos, noise=0.1, seed=0, **kw))
    out = np.full((5, 600), 7.0, np.float32)
    res = forward_model(scene, pos, noise=0.1, out=out, **kw)
    assert res is out and np.array_equal(out, n) and out.dtype == np.float32
    assert forward_model(scene, pos, frequency_hz=F, dt_s=0.02e-9).shape == (5, 512)  # 512 samples by default


def test_forward_model_refusals_in_full():
    s = ForwardScene()
    with pytest.raises(ValueError, match=r"^air_gap_m must be a height >= 0 in metres, got -0\.1$"):
        forward_model(s, [[0, 0, 0]], dt_s=1e-11, air_gap_m=-0.1)
    with pytest.raises(ValueError, match=r"^give dt_s or time_window_s$"):
        forward_model(s, [[0, 0, 0]])
    with pytest.raises(ValueError, match=r"^footprint must be 'interface' or 'none', got 'cone'$"):
        forward_model(s, [[0, 0, 0]], dt_s=1e-11, footprint="cone")


def test_scene_to_forward_and_the_scene_bscan():
    from gpr3d.simulation.scene import Antenna, Medium, Scene, Stone, Target

    sc = Scene(medium=Medium(eps_r=7.0, conductivity_s_m=0.002),
               targets=[Target("rebar", 0.2, 0.05, 0.01),
                        Target("pipe", 0.45, 0.1, 0.03, material="water", fill="air", wall_m=0.004),
                        Target("pipe", 0.55, 0.1, 0.03, material="water", fill="air"),
                        Target("pipe", 0.4, 0.1, 0.03, y_m=0.1, axis_xyz=(1.0, 1.0, 0.0), length_m=0.4,
                               material="pvc", fill="water", wall_m=0.005),
                        Target("void", 0.5, 0.08, 0.02, material="air")],
               stones=[Stone(0.3, 0.12, 0.01, 5.0)], antenna=Antenna(frequency_hz=1.5e9, offset_m=0.05),
               n_traces=20, trace_step_m=0.02, seed=5)
    fs = scene_to_forward(sc)
    assert (fs.eps_r, fs.conductivity_s_m) == (7.0, 0.002)
    rebar, walled, bare, pipe, void, stone = fs.pipes
    assert (walled.material, walled.eps_r, walled.wall_m, walled.wall_eps_r) == ("dielectric", 1.0, 0.004, 80.0)
    assert (bare.material, bare.eps_r, bare.wall_m, bare.wall_eps_r) == ("dielectric", 1.0, 0.0, 3.0)
    np.testing.assert_allclose([rebar.p0, rebar.p1], [[0.2, -50.0, -0.06], [0.2, 50.0, -0.06]])
    assert (rebar.radius_m, rebar.material) == (0.01, "pec")
    h = 0.2 / math.sqrt(2)  # half the length along the unit axis
    np.testing.assert_allclose([pipe.p0, pipe.p1], [[0.4 - h, 0.1 - h, -0.13], [0.4 + h, 0.1 + h, -0.13]])
    assert (pipe.material, pipe.eps_r, pipe.wall_m, pipe.wall_eps_r) == ("dielectric", 80.0, 0.005, 3.0)
    assert (void.material, void.eps_r, void.wall_m, void.wall_eps_r) == ("dielectric", 1.0, 0.0, 3.0)
    np.testing.assert_allclose([stone.p0, stone.p1], [[0.3, -50.0, -0.13], [0.3, 50.0, -0.13]])
    assert (stone.radius_m, stone.material, stone.eps_r) == (0.01, "dielectric", 5.0)
    survey, info = simulate_scene_bscan(sc, n_samples=300, noise=0.01)
    x = sc.trace_midpoints_x()
    np.testing.assert_allclose(survey.positions_xyz, np.c_[x, np.zeros_like(x), np.zeros_like(x)])
    want = forward_model(fs, survey.positions_xyz, offset_m=0.05, frequency_hz=1.5e9, n_samples=300,
                         time_window_s=sc.time_window, wavelet="ricker_half", spreading="2d", air_wave=1.0,
                         ground_wave=0.5, noise=0.01, seed=sc.seed)
    np.testing.assert_array_equal(survey.data, want)
    assert survey.dt_s == pytest.approx(sc.time_window / 300, rel=1e-12, abs=0)
    assert (survey.offset_m, survey.frequency_hz, survey.eps_r) == (0.05, 1.5e9, 7.0)
    assert survey.metadata["format"] == "forward" and survey.metadata["scene"] == sc.to_dict()
    assert {k: info[k] for k in ("engine", "wavelet", "spreading", "time_window_s", "n_samples")} == {
        "engine": "forward", "wavelet": "ricker_half", "spreading": "2d", "time_window_s": sc.time_window,
        "n_samples": 300}
    assert survey.metadata["simulation"] == info and 0 <= info["wall_s"] < 60
    assert survey.metadata["antenna"] == "forward model"
    np.testing.assert_allclose(survey.orientations_quat_wxyz, np.tile([1.0, 0.0, 0.0, 0.0], (20, 1)))
    assert simulate_scene_bscan(sc)[0].n_samples == 512  # by default


def test_a_shielded_antenna_s_beam_tapers_off_axis_echoes():
    """A sphere seen 30 deg off the vertical: a Gaussian beam of 20 deg half-angle takes exp(-(30/20)^2 / 2) off
    each leg; straight below, nothing."""
    def peak(centre, beam):
        sc = ForwardScene(eps_r=4.0, spheres=[Sphere(centre, 0.01)])
        return np.abs(forward_model(sc, [[0.0, 0.0, 0.0]], frequency_hz=F, n_samples=1500, dt_s=DT, footprint="none",
                                    beam_half_angle_deg=beam)[0]).max()

    d = 0.4
    side = (d * math.tan(math.radians(30)) + 0.01 * math.sin(math.radians(30)), 0.0, -d - 0.01 * math.cos(
        math.radians(30)))
    assert peak(side, 20.0) / peak(side, None) == pytest.approx(math.exp(-(30 / 20) ** 2), rel=2e-3)
    below = (0.0, 0.0, -0.41)
    assert peak(below, 20.0) == pytest.approx(peak(below, None), rel=1e-6)
