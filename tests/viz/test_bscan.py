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
