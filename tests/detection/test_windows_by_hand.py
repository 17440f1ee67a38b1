"""Windows of a record, by hand: the settings' edges with whole messages, the seconds per row, where windows start
(overlap, the last one flush with the record's end, padding), each window's pixel map and rendered block."""

import re

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.survey import Survey
from gpr3d.detection.windows import WindowConfig, make_window, prepare, rows_interval, windows
from gpr3d.processing.image import network_view, record_scale, render_channels


@pytest.mark.parametrize("kw", [dict(traces=16), dict(traces=4096), dict(rows=32), dict(rows=2048),
                                dict(overlap=0.0), dict(overlap=0.9), dict(style="hot")])
def test_window_settings_at_their_edges_pass(kw):
    assert WindowConfig(**kw).to_dict() == {**WindowConfig().to_dict(), **kw}


@pytest.mark.parametrize("kw, words", [
    (dict(traces=15), "window traces must be an integer in 16..4096, got 15"),
    (dict(traces=4097), "window traces must be an integer in 16..4096, got 4097"),
    (dict(traces=64.0), "window traces must be an integer in 16..4096, got 64.0"),
    (dict(rows=31), "window rows must be an integer in 32..2048, got 31"),
    (dict(rows=2049), "window rows must be an integer in 32..2048, got 2049"),
    (dict(rows="256"), "window rows must be an integer in 32..2048, got '256'"),
    (dict(overlap=-0.01), "window overlap must lie in 0..0.9, got -0.01"),
    (dict(overlap=0.91), "window overlap must lie in 0..0.9, got 0.91"),
    (dict(style="Hot"), "window style must be 'channels' or 'hot', got 'Hot'"),
])
def test_window_settings_outside_are_named_in_full(kw, words):
    with pytest.raises(InvalidDataError, match="^" + re.escape(words) + "$"):
        WindowConfig(**kw)


def _survey(n, ns=200, dt=0.1e-9, seed=0):
    return Survey(data=np.random.default_rng(seed).standard_normal((n, ns)).astype(np.float32), dt_s=dt,
                  frequency_hz=1e9)


@pytest.mark.parametrize("n, traces, overlap, starts", [
    (100, 32, 0.5, [0, 16, 32, 48, 64, 68]),  # steps of 16; the last flush with the end
    (96, 32, 0.5, [0, 16, 32, 48, 64]),  # the steps reach the end exactly
    (100, 32, 0.0, [0, 32, 64, 68]),
    (100, 32, 0.9, list(range(0, 69, 3)) + [68]),  # round(3.2) = 3
    (20, 32, 0.5, [0]),  # shorter than a window: one, padded
])
def test_window_starts(n, traces, overlap, starts):
    s = _survey(n)
    cfg = WindowConfig(traces=traces, rows=64, overlap=overlap)
    wins = windows(s, cfg)
    assert [w.trace_start for w in wins] == starts
    assert [w.n_traces for w in wins] == [min(traces, n - a) for a in starts]


def test_a_window_s_pixels_and_block():
    s = _survey(50, ns=200)
    cfg = WindowConfig(traces=32, rows=64, style="hot")
    spr = rows_interval(s, cfg)
    assert spr == pytest.approx(199 * 0.1e-9 / 63, rel=1e-12, abs=0)
    proc = prepare(s, cfg)
    np.testing.assert_array_equal(proc, network_view(s, 64))
    scale = record_scale(proc)
    wins = windows(s, cfg)
    last = wins[-1]
    assert (last.trace_start, last.n_traces) == (18, 32)
    # column c is trace start + c at its centre, row r time r x spr
    assert last.pixmap.point_to_px(18.0, 0.0) == pytest.approx((0.5, 0.5))
    assert last.pixmap.point_to_px(18.0 + 31, 63 * spr) == pytest.approx((31.5, 63.5))
    np.testing.assert_array_equal(last.image, render_channels(proc[18:50], "hot", scale=scale))
    # past the record's end: zero traces
    w = make_window(proc, 40, cfg, spr, scale)
    assert w.n_traces == 10 and w.image.shape == (3, 64, 32)
    np.testing.assert_array_equal(w.image, render_channels(np.r_[proc[40:], np.zeros((22, 64), np.float32)], "hot",
                                                           scale=scale))
    # windows take the data already prepared when given
    other = proc * 0 + 1.0
    np.testing.assert_array_equal(windows(s, cfg, processed=other)[0].image,
                                  render_channels(other[:32], "hot", scale=record_scale(other)))
    # no settings: the defaults (256 traces, 256 rows)
    assert windows(_survey(300, ns=300))[0].image.shape == (3, 256, 256)
