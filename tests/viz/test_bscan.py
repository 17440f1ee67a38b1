import numpy as np
import pytest

from gpr3d import InvalidDataError
from gpr3d.simulation.synthetic import point_targets_bscan
from gpr3d.viz.bscan import save_bscan_png


@pytest.mark.parametrize("axis, cmap", [("time", "gray"), ("depth", "hot")])
def test_png_is_written_and_shows_the_data(tmp_path, axis, cmap):
    import matplotlib.image as mpimg

    s = point_targets_bscan([[0.5, 0.3]])
    out = tmp_path / f"{axis}.png"
    save_bscan_png(s, out, axis=axis, cmap=cmap, boxes=[(40, 3e-9, 60, 8e-9)], title="t")
    img = mpimg.imread(out)
    assert img.shape[0] > 300 and img.shape[1] > 500
    assert np.std(img[..., :3]) > 0.05  # not a blank canvas
    assert [p.name for p in tmp_path.iterdir()] == [out.name]


def test_depth_axis_needs_permittivity(tmp_path):
    s = point_targets_bscan([[0.5, 0.3]]).replace(eps_r=None)
    with pytest.raises(InvalidDataError, match="eps_r"):
        save_bscan_png(s, tmp_path / "x.png", axis="depth")
    assert not (tmp_path / "x.png").exists()


def test_envelope_is_the_analytic_amplitude_not_the_rectified_trace():
    """A Gaussian-modulated 1 GHz burst: the drawn envelope follows the Gaussian (also where the carrier crosses
    zero), unlike |trace|."""
    from gpr3d import Survey
    from gpr3d.viz._figures import pyplot
    from gpr3d.viz.bscan import plot_bscan

    dt, n = 0.025e-9, 400
    t = np.arange(n) * dt
    gauss = np.exp(-0.5 * ((t - 5e-9) / 1e-9) ** 2)
    trace = gauss * np.cos(2 * np.pi * 1e9 * (t - 5e-9) + np.pi / 2)  # a zero of the carrier at the peak
    s = Survey(data=np.tile(trace, (3, 1)).astype(np.float32), dt_s=dt)
    plt = pyplot()
    fig, ax = plt.subplots()
    try:
        plot_bscan(s, ax, envelope=True)
        drawn = np.asarray(ax.images[0].get_array())[:, 1]
        inner = slice(80, 320)  # away from the record's ends
        np.testing.assert_allclose(drawn[inner], gauss[inner], atol=0.02)
        assert abs(trace[200]) < 1e-6 and drawn[200] == pytest.approx(1.0, abs=0.02)
        assert ax.images[0].colorbar.ax.get_ylabel() == "envelope"
    finally:
        plt.close(fig)
