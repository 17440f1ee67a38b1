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


def test_a_label_preview_draws_the_visible_labels_only(tmp_path, monkeypatch):
    import matplotlib.image as mpimg

    import gpr3d.viz.bscan as vb

    s = point_targets_bscan([[0.5, 0.3]])
    labels = {"eps_r": 6.0, "labels": [
        {"box": [40, 3e-9, 60, 8e-9], "apex_trace": 50, "apex_time_s": 4e-9, "kind": "rebar", "depth_m": 0.3,
         "visible": True},
        {"box": [1, 1e-9, 5, 2e-9], "apex_trace": 3, "apex_time_s": 1.5e-9, "kind": "pipe", "depth_m": 0.1,
         "visible": False}]}
    vb.save_label_preview(s, labels, tmp_path / "p.png")
    img = mpimg.imread(tmp_path / "p.png")
    assert img.shape[0] > 300 and np.std(img[..., :3]) > 0.05
    seen = {}
    monkeypatch.setattr(vb, "save_bscan_png", lambda survey, path, **kw: seen.update(kw, data=survey.data))
    vb.save_label_preview(s, labels, tmp_path / "q.png")
    assert seen["boxes"] == [[40, 3e-9, 60, 8e-9]] and seen["apexes"] == [(50, 4e-9)]
    assert seen["title"] == "labels (box, + apex): rebar 30 cm; eps_r 6"
    # drawn with the mean trace removed
    np.testing.assert_allclose(seen["data"], s.data - s.data.mean(axis=0, keepdims=True), atol=1e-5 * np.abs(s.data).max())
