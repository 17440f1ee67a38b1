"""The report's B-scan: every detection drawn as its box (two-way time in ns) with its kind and depth."""

import numpy as np
import pytest

from gpr3d.core.survey import Survey

pytest.importorskip("plotly")


def _figure(targets):
    from gpr3d.pipeline.report import _bscan_figure, _plotly

    go, _, _ = _plotly()
    rng = np.random.default_rng(0)
    s = Survey(data=rng.standard_normal((40, 64)).astype(np.float32), dt_s=0.1e-9)
    return _bscan_figure(go, s, {"targets": targets})


def test_each_detection_is_a_box_with_its_label():
    targets = [{"box": [3, 1.0e-9, 9, 2.5e-9], "kind": "rebar", "depth_m": 0.123},
               {"box": [20, 3.0e-9, 31, 5.0e-9], "kind": None},
               {"box": [0, 0.2e-9, 39, 6.3e-9], "kind": "pvc_pipe", "depth_m": None}]
    fig = _figure(targets)
    shapes = fig.layout.shapes
    assert [(s.type, s.x0, s.x1, s.line.color) for s in shapes] == [("rect", t["box"][0], t["box"][2], "#e4572e")
                                                                    for t in targets]
    np.testing.assert_allclose([(s.y0, s.y1) for s in shapes], [(1.0, 2.5), (3.0, 5.0), (0.2, 6.3)], rtol=1e-12)
    notes = fig.layout.annotations
    assert [n.text for n in notes] == ["rebar 0.12 m", "target", "pvc_pipe"]
    assert [(n.x, n.xanchor, n.yanchor, n.showarrow) for n in notes] == [(3, "left", "bottom", False),
                                                                        (20, "left", "bottom", False),
                                                                        (0, "left", "bottom", False)]
    np.testing.assert_allclose([n.y for n in notes], [1.0, 3.0, 0.2], rtol=1e-12)
    assert "3 detections" in fig.layout.title.text


def test_no_detections_no_boxes():
    fig = _figure([])
    assert len(fig.layout.shapes) == 0 and len(fig.layout.annotations) == 0
    assert "0 detections" in fig.layout.title.text
