"""The numba forward model against an independent numpy evaluation of the same equations."""

import math

import numpy as np
import pytest

from gpr3d.core.units import C0
from gpr3d.simulation.forward import (
    ForwardScene, Layer, Pipe, Sphere, forward_model, simulate_scene_bscan, wavelet_table,
)

F = 800e6
DT = 0.02e-9
NS = 1200


def reference_traces(xs, offset, pipe_x, pipe_z, pipe_r, sph_c, sph_r, eps):
    """numpy: PEC pipe along y and PEC sphere, 3D spreading, no footprint or loss, heading 0."""
    v = C0 / math.sqrt(eps)
    t0, step, w = wavelet_table(F, "ricker")
    w = w * (F / 1e9)
    tw = t0 + step * np.arange(w.size)
    t = np.arange(NS) * DT
    out = np.zeros((len(xs), NS))
    for i, x in enumerate(xs):
        a, b, m = np.array([x - offset / 2, 0, 0]), np.array([x + offset / 2, 0, 0]), np.array([x, 0, 0.0])
        # pipe: nearest axis point, then out to the surface
        q = np.array([pipe_x, 0.0, pipe_z])
        p = q + pipe_r * (m - q) / np.linalg.norm(m - q)
        path = np.linalg.norm(a - p) + np.linalg.norm(b - p)
        rm = path / 2
        amp = -1.0 * math.sqrt(pipe_r / (2 * rm)) / (2 * rm)
        out[i] += amp * np.interp(t - (math.sqrt(2) / F + path / v), tw, w, left=0, right=0)
        c = np.asarray(sph_c, float)
        p = c + sph_r * (m - c) / np.linalg.norm(m - c)
        path = np.linalg.norm(a - p) + np.linalg.norm(b - p)
        rm = path / 2
        amp = -1.0 * sph_r / (2 * rm * rm)
        out[i] += amp * np.interp(t - (math.sqrt(2) / F + path / v), tw, w, left=0, right=0)
    return out


def test_kernel_matches_numpy_reference():
    xs = np.linspace(0, 1.0, 21)
    scene = ForwardScene(eps_r=6.0, pipes=[Pipe((0.4, -5, -0.3), (0.4, 5, -0.3), 0.02)],
                         spheres=[Sphere((0.7, 0.0, -0.5), 0.05)])
    got = forward_model(scene, np.c_[xs, 0 * xs, 0 * xs], offset_m=0.1, frequency_hz=F, n_samples=NS, dt_s=DT,
                        footprint="none")
    ref = reference_traces(xs, 0.1, 0.4, -0.3, 0.02, (0.7, 0, -0.5), 0.05, 6.0)
    np.testing.assert_allclose(got, ref, atol=2e-3 * np.abs(ref).max())


def test_layer_time_and_heading_rotation():
    scene = ForwardScene(eps_r=4.0, layers=[Layer(0.6, 16.0)])
    v = C0 / 2
    tr = forward_model(scene, [[0, 0, 0]], offset_m=0.0, frequency_hz=F, n_samples=NS, dt_s=DT, footprint="none")[0]
    assert np.argmax(np.abs(tr)) * DT == pytest.approx(math.sqrt(2) / F + 1.2 / v, abs=DT)
    # the offset rotates with the heading: a layer does not care, a pipe along the line does
    a = forward_model(scene, [[0, 0, 0]], headings_rad=[0.0], offset_m=0.3, frequency_hz=F, n_samples=NS, dt_s=DT)
    b = forward_model(scene, [[0, 0, 0]], headings_rad=[1.0], offset_m=0.3, frequency_hz=F, n_samples=NS, dt_s=DT)
    np.testing.assert_allclose(a, b, atol=1e-6)


def test_polarisation():
    along_y = ForwardScene(eps_r=6.0, pipes=[Pipe((0, -5, -0.3), (0, 5, -0.3), 0.01)])
    along_x = ForwardScene(eps_r=6.0, pipes=[Pipe((-5, 0, -0.3), (5, 0, -0.3), 0.01)])
    kw = dict(offset_m=0.0, frequency_hz=F, n_samples=NS, dt_s=DT)
    amp_y = np.abs(forward_model(along_y, [[0, 0, 0]], **kw)).max()
    amp_x = np.abs(forward_model(along_x, [[0, 0, 0]], **kw)).max()
    assert amp_x / amp_y == pytest.approx(0.05, rel=1e-3)  # dipoles lie along antenna y
    turned = np.abs(forward_model(along_x, [[0, 0, 0]], headings_rad=[np.pi / 2], **kw)).max()
    assert turned == pytest.approx(amp_y, rel=1e-4)


def test_spreading_laws():
    def apex_amp(depth, spreading):
        sc = ForwardScene(eps_r=6.0, pipes=[Pipe((0, -9, -depth - 0.01), (0, 9, -depth - 0.01), 0.01)])
        return np.abs(forward_model(sc, [[0, 0, 0]], frequency_hz=F, n_samples=4000, dt_s=DT, footprint="none",
                                    spreading=spreading)).max()
    assert apex_amp(0.2, "2d") / apex_amp(0.4, "2d") == pytest.approx(2.0, rel=1e-3)  # 1/R
    assert apex_amp(0.2, "3d") / apex_amp(0.4, "3d") == pytest.approx(2 ** 1.5, rel=1e-3)  # R^-1.5


def test_interface_footprint_peaks_at_the_critical_angle():
    eps = 9.0
    sc = ForwardScene(eps_r=eps, spheres=[Sphere((0, 0, -1.0), 0.05)])
    crit = math.asin(1 / 3)
    xs = np.tan(np.radians([0, 10, math.degrees(crit), 40]))  # sphere seen at these angles
    on = forward_model(sc, np.c_[xs, 0 * xs, 0 * xs], frequency_hz=F, n_samples=4000, dt_s=DT)
    off = forward_model(sc, np.c_[xs, 0 * xs, 0 * xs], frequency_hz=F, n_samples=4000, dt_s=DT, footprint="none")
    pattern = np.abs(on).max(axis=1) / np.abs(off).max(axis=1)
    assert pattern[0] == pytest.approx(1.0, rel=1e-6)
    # T(theta_c) / T(0) = 2 / (2n / (n + 1)) = (n + 1) / n, twice (transmit and receive)
    assert pattern[2] == pytest.approx(((3 + 1) / 3) ** 2, rel=0.02)
    assert pattern[1] < pattern[2] and pattern[3] < pattern[2]


def test_noise_is_reproducible_per_trace():
    sc = ForwardScene(eps_r=6.0)
    kw = dict(frequency_hz=F, n_samples=256, dt_s=DT, noise=0.1, seed=3)
    a = forward_model(sc, np.zeros((4, 3)), **kw)
    b = forward_model(sc, np.zeros((4, 3)), **kw)
    np.testing.assert_array_equal(a, b)
    assert a[0].std() == pytest.approx(0.1, rel=0.2)
    assert not np.allclose(a[0], a[1])


def test_forward_engine_bscan_matches_its_labels():
    from gpr3d.processing.picking import pick_peak
    from gpr3d.simulation.labels import label_scene
    from gpr3d.simulation.sampler import sample_scene

    scene = sample_scene(0, 2)  # three rebars in concrete
    s, info = simulate_scene_bscan(scene, n_samples=1024)
    assert info["engine"] == "forward" and s.shape == (scene.n_traces, 1024)
    env = s.remove_background().envelope().data
    for lab in label_scene(scene, s.n_samples, s.dt_s):
        t, _ = pick_peak(env, s.dt_s, int(round(lab["apex_trace"])), lab["apex_time_s"], 0.3 / scene.antenna.frequency_hz)
        # the nearest trace is within half a step of the apex: allow that much moveout
        assert abs(t - lab["apex_time_s"]) < 0.05e-9


def _peak_time(tr):
    """The time of a trace's largest |value| (s), refined by a parabola through the three samples around it."""
    k = int(np.argmax(np.abs(tr)))
    a, b, c = np.abs(tr[k - 1 : k + 2])
    return (k + 0.5 * (a - c) / (a - 2 * b + c)) * DT


def test_an_antenna_held_above_the_ground_and_one_bouncing():
    """A layer 0.6 m down (eps_r 4): with the antenna held 0.2 m up the echo comes 2 x 0.2 / c later than on the
    ground (straight down, the legs need no refraction); a sphere 0.3 m off to the side is reached along the
    refracted ray, its time the least over where each leg crosses the surface (brute force here), not the straight
    line; an antenna at z = 0.05 (a bounce) adds its height twice at c."""
    scene = ForwardScene(eps_r=4.0, layers=[Layer(0.6, 16.0)])
    kw = dict(offset_m=0.0, frequency_hz=F, n_samples=NS, dt_s=DT, footprint="none")
    t_ground = _peak_time(forward_model(scene, [[0, 0, 0]], **kw)[0])
    t_air = _peak_time(forward_model(scene, [[0, 0, 0]], air_gap_m=0.2, **kw)[0])
    assert t_air - t_ground == pytest.approx(0.4 / C0, abs=0.02 * DT)
    t_bounce = _peak_time(forward_model(scene, [[0, 0, 0.05]], **kw)[0])
    assert t_bounce - t_ground == pytest.approx(0.1 / C0, abs=0.02 * DT)
    r = 0.02
    sphere = ForwardScene(eps_r=9.0, spheres=[Sphere((0.3, 0.0, -0.4 - r), r)])
    tr = forward_model(sphere, [[0, 0, 0]], air_gap_m=0.25, source_delay_s=0.0, **kw)[0]
    # the nearest point of the sphere to the antenna's ground point (0, 0, 0), and the least-time leg to it
    centre = np.array([0.3, 0.0, -0.4 - r])
    p = centre - r * centre / np.linalg.norm(centre)
    rho, depth = math.hypot(p[0], p[1]), -p[2]
    s = np.linspace(0.0, rho, 200001)  # horizontal distance run in the air
    leg = np.min(np.hypot(0.25, s) / C0 + np.hypot(depth, rho - s) * 3.0 / C0)
    assert _peak_time(tr) == pytest.approx(2 * leg, abs=0.05 * DT)
    straight = 2 * math.hypot(rho, depth + 0.25) * (0.25 / (depth + 0.25) / C0 + depth / (depth + 0.25) * 3 / C0)
    assert abs(2 * leg - straight) > 5 * DT  # the straight line would be a different time
    with pytest.raises(ValueError, match="air_gap_m must be a height >= 0 in metres, got -0.1"):
        forward_model(scene, [[0, 0, 0]], air_gap_m=-0.1, **kw)
