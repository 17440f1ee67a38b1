"""The reconstruction's figures: what each image shows and how it is drawn."""

import numpy as np
import pytest

from gpr3d.core.grid import Grid3D
from gpr3d.migration.reconstruct import Reconstruction
from gpr3d.migration.targets import Target3D
from gpr3d.viz import volume as V


def _rec(nx, ny=30, nd=12):
    g = Grid3D(0.0, 0.0, 0.02, 0.02, 0.02, 0.02, nx, ny, nd)
    env = np.zeros(g.shape, np.float32)
    env[:, ny // 2, nd // 2] = 1.0  # a line along x at mid-depth
    env[nx // 3, 3, 2] = 0.5
    t = Target3D(kind="line", points_xyz=[[0.0, ny // 2 * 0.02, 0.14], [(nx - 1) * 0.02, ny // 2 * 0.02, 0.14]],
                 score=1.0, depth_m=0.14)
    return Reconstruction(image=env, envelope=env, noise_map=None, fold=None, grid=g, targets=[t], eps_r=9.0,
                          config={"threshold": 0.3}, n_traces=10, timings_s={}, updates_per_s=None)


@pytest.mark.parametrize("nx, want", [(40, "nearest"), (V.NEAREST_UP_TO, "nearest"),
                                      (V.NEAREST_UP_TO + 1, "antialiased")])
def test_top_and_front_views_show_the_envelope_maxima_cell_by_cell_unless_too_large(tmp_path, monkeypatch, nx, want):
    saved = {}
    monkeypatch.setattr(V, "save_figure", lambda fig, path, **kw: saved.__setitem__(path.name, fig))
    rec = _rec(nx)
    assert V.reconstruction_figures(rec, tmp_path) == ["front.png", "top.png", "view3d.png"]
    top = saved["top.png"].axes[0].images[0]
    np.testing.assert_array_equal(top.get_array(), rec.envelope.max(axis=2).T)
    front = saved["front.png"].axes[0].images[0]
    np.testing.assert_array_equal(front.get_array(), rec.envelope.max(axis=1).T)
    assert top.get_interpolation() == want and front.get_interpolation() == want


@pytest.mark.parametrize("noise", [False, True])
def test_the_views_of_a_3d_image_are_laid_out_by_hand_with_every_label_inside_the_picture(tmp_path, monkeypatch,
                                                                                         noise):
    """The three views skip tight_layout (it draws each figure twice); their fixed margins must still hold every
    title, tick label and colour-bar label inside the written picture (one panel, or two with the noise map)."""
    real = V.save_figure
    kept = {}

    def keep(fig, path, **kw):
        kept[path.name] = (fig, kw)
        real(fig, path, close=False, **kw)

    monkeypatch.setattr(V, "save_figure", keep)
    rec = _rec(60, 40)
    if noise:
        rec.noise_map = 0.5 * rec.envelope
    V.reconstruction_figures(rec, tmp_path)
    assert set(kept) == {"top.png", "front.png", "view3d.png"}
    for name, (fig, kw) in kept.items():
        assert kw.get("tight") is False, name
        assert (tmp_path / name).stat().st_size > 10_000
        fig.canvas.draw()  # (at the figure's own dpi: savefig's renderer drew at another)
        renderer = fig.canvas.get_renderer()
        box = fig.bbox
        texts = []
        for ax in fig.axes:  # titles, axis labels and the tick labels inside each axis' view (colour bars too)
            texts += [ax.title, ax.xaxis.label, ax.yaxis.label] + ([ax.zaxis.label] if hasattr(ax, "zaxis") else [])
            for axis in (ax.xaxis, ax.yaxis):
                lo, hi = sorted(axis.get_view_interval())
                texts += [tk.label1 for tk in axis.get_major_ticks() if lo <= tk.get_loc() <= hi]
        texts = [t for t in texts if t.get_visible() and t.get_text().strip()]
        assert len(texts) > 10, name
        for t in texts:
            e = t.get_window_extent(renderer)
            assert e.x0 >= box.x0 - 1 and e.x1 <= box.x1 + 1 and e.y0 >= box.y0 - 1 and e.y1 <= box.y1 + 1, \
                (name, t.get_text(), e.bounds, box.bounds)


@pytest.mark.parametrize("noise", [False, True])
def test_a_profile_gets_its_map_and_its_migrated_section_with_the_noise_map_below(tmp_path, monkeypatch, noise):
    from gpr3d.migration.reconstruct import ProfileFrame

    saved = {}
    monkeypatch.setattr(V, "save_figure", lambda fig, path, **kw: saved.__setitem__(path.name, (fig, kw)))
    g = Grid3D(0.0, 0.0, 0.02, 0.02, 0.02, 0.02, 50, 1, 20)  # along the profile, one column across it
    env = np.zeros(g.shape, np.float32)
    env[20, 0, 8] = 1.0
    env[35, 0, 3] = 0.4
    t = Target3D(kind="point", points_xyz=[[1.0 + 0.4 * 0.6, 2.0 + 0.4 * 0.8, 0.18]], score=1.0, depth_m=0.18,
                 extra={"along_m": [0.4]})
    rec = Reconstruction(image=env, envelope=env, noise_map=0.5 * env[::-1] if noise else None, fold=None, grid=g,
                         targets=[t], eps_r=9.0, config={"threshold": 0.3}, n_traces=10, timings_s={},
                         updates_per_s=None, frame=ProfileFrame((1.0, 2.0), (0.6, 0.8)))
    assert V.reconstruction_figures(rec, tmp_path) == ["front.png", "top.png", "view3d.png"]
    fig, kw = saved["front.png"]
    panels = [ax for ax in fig.axes if ax.images]
    assert len(panels) == (2 if noise else 1) and kw.get("tight") is not False  # a profile's figures keep tight_layout
    np.testing.assert_array_equal(panels[0].images[0].get_array(), env[:, 0, :].T)
    if noise:
        np.testing.assert_array_equal(panels[1].images[0].get_array(), rec.noise_map[:, 0, :].T)
        assert "noise map" in panels[1].get_title()
    # the target at its place along the profile and depth, its name beside it
    mark = panels[0].lines[0].get_xydata()
    np.testing.assert_allclose(mark, [[0.4, 0.18]], atol=1e-12)
    # the map: the profile's ends in the world (from the frame), the target in the world
    top = saved["top.png"][0].axes[0]
    np.testing.assert_allclose(top.lines[0].get_xydata(), [[1.0, 2.0], [1.0 + 0.98 * 0.6, 2.0 + 0.98 * 0.8]],
                               atol=1e-12)
    np.testing.assert_allclose(top.lines[1].get_xydata(), [[1.24, 2.32]], atol=1e-12)
    from gpr3d.viz._figures import pyplot

    for f, _ in saved.values():
        pyplot().close(f)


def test_the_3d_view_draws_every_point_once_in_the_colour_of_its_bin_dimmest_first(tmp_path, monkeypatch):
    import matplotlib as mpl

    saved = {}
    monkeypatch.setattr(V, "save_figure", lambda fig, path, **kw: saved.__setitem__(path.name, fig))
    rng = np.random.default_rng(3)
    pts = rng.random((500, 3))
    vals = rng.random(500) * 2.0 + 1.0
    fi = V.figure_inputs(_rec(20))
    fi.points, fi.values, fi.targets = pts, vals, []
    V.draw_figures(fi, tmp_path, split=False)
    ax = saved["view3d.png"].axes[0]
    lines = ax.get_lines()
    assert 20 < len(lines) <= V.COLOUR_BINS
    cm = mpl.colormaps["hot"]
    drawn, lows = [], []
    lo, hi = vals.min(), vals.max()
    for ln in lines:
        x, y, z = (np.asarray(a) for a in ln.get_data_3d())
        got = np.column_stack([x, y, z])
        idx = [int(np.flatnonzero((pts == p).all(axis=1))[0]) for p in got]
        drawn += idx
        v = vals[idx]
        b = min(int(np.floor((v.min() - lo) / (hi - lo) * V.COLOUR_BINS)), V.COLOUR_BINS - 1)  # its dimmest one's
        assert np.all((v - lo) / (hi - lo) * V.COLOUR_BINS < b + 1 + 1e-9), "one bin per line"
        np.testing.assert_allclose(mpl.colors.to_rgba(ln.get_color()), cm((b + 0.5) / V.COLOUR_BINS))
        assert ln.get_alpha() == 0.5 and ln.get_marker() == "o"
        lows.append(v.min())
    assert sorted(drawn) == list(range(500))  # every point once
    assert lows == sorted(lows)  # the brightest drawn last, on top
    bar = saved["view3d.png"].axes[1]  # the colour bar spans the values
    np.testing.assert_allclose(bar.get_ylim(), (lo, hi))


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="no fork here")
@pytest.mark.parametrize("fails", [False, True])
def test_a_split_drawing_writes_the_same_files_and_draws_here_what_its_fork_did_not(tmp_path, monkeypatch, fails):
    import os

    from gpr3d.viz import worker as W

    fi = V.figure_inputs(_rec(40))
    V.draw_figures(fi, tmp_path / "one", split=False)
    me, here = os.getpid(), []
    real = V._view3d

    def view3d(fi, out):
        if os.getpid() != me and fails:
            raise RuntimeError("the forked drawing failed")
        if os.getpid() == me:
            here.append(out)
        real(fi, out)

    monkeypatch.setattr(V, "_view3d", view3d)
    assert V.draw_figures(fi, tmp_path / "split", split=True) == ["front.png", "top.png", "view3d.png"]
    assert here == ([tmp_path / "split"] if fails else [])  # drawn by the fork, or here when it failed
    for name in ("top.png", "front.png", "view3d.png"):
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "split" / name).read_bytes(), name
    monkeypatch.setattr(W, "fork_job", lambda *a: None)  # no process to be had: drawn here
    here.clear()
    V.draw_figures(fi, tmp_path / "nofork", split=True)
    assert here == [tmp_path / "nofork"]
    assert (tmp_path / "nofork" / "view3d.png").read_bytes() == (tmp_path / "one" / "view3d.png").read_bytes()
