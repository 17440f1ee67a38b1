"""gpr3d.pipeline's last stages: a survey with poses migrated, its targets found where the scene put them, and the
result folder written as one whole; the ways it is refused, each in one line before the migration."""

import json

import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.core.errors import GPR3DError
from gpr3d.migration.reconstruct import ReconstructConfig
from gpr3d.pipeline import reconstruct_recording, write_reconstruction_folder


@pytest.fixture(scope="module")
def pipe():
    from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model
    from gpr3d.simulation.paths import random_walk

    walk = random_walk(900, area=((0, 0.8), (0, 0.8)), step_m=0.01, seed=4)
    scene = ForwardScene(eps_r=6.0, pipes=[Pipe((0.1, 0.4, -0.33), (0.7, 0.4, -0.33), 0.03)])
    data = forward_model(scene, walk.positions_xyz, walk.orientations_quat_wxyz, offset_m=0.08, frequency_hz=800e6,
                         n_samples=192, time_window_s=12e-9, air_wave=1.0, ground_wave=0.5)
    return Survey(data=data, dt_s=12e-9 / 192, offset_m=0.08, frequency_hz=800e6, eps_r=6.0,
                  positions_xyz=walk.positions_xyz, orientations_quat_wxyz=walk.orientations_quat_wxyz)


def test_the_pipe_comes_out_where_it_lies_and_the_folder_holds_one_run(pipe, tmp_path):
    lines = []
    run = reconstruct_recording(pipe, ReconstructConfig(spacing_m=0.03, max_depth_m=0.6), eps_r="file",
                                input_name="pipe.h5", log=lines.append)
    assert lines[0] == "eps_r 6 (the file header)"
    assert run.result.eps_r_source == "file header" and run.found is None and run.mask == "none"
    best = max((t for t in run.result.targets if t.kind == "line"),
               key=lambda t: np.linalg.norm(np.subtract(t.points_xyz[1], t.points_xyz[0])))
    p = np.asarray(best.points_xyz)
    assert np.allclose(p[:, 1], 0.4, atol=0.04) and np.allclose(p[:, 2], 0.30, atol=0.04)  # top at 0.33 - 0.03
    files = write_reconstruction_folder(run, tmp_path / "out", source="pipe.h5")
    # the migration's data and the figures drawn above it, each figure a picture with something on it
    assert {"config.json", "targets.json", "volume.h5", "volume.vti", "top.png", "front.png", "view3d.png"} <= set(files)
    from PIL import Image

    for name in ("top.png", "front.png", "view3d.png"):
        px = np.asarray(Image.open(tmp_path / "out" / name).convert("L"), float)
        assert px.shape[0] > 200 and px.std() > 10, name
    from gpr3d.io.resultdir import check_result

    check_result(tmp_path / "out")  # every file named, with its hash
    assert json.loads((tmp_path / "out" / "config.json").read_text())["eps_r"] == 6.0


def test_refusals_come_before_any_migration(pipe, tmp_path):
    cfg = ReconstructConfig(spacing_m=0.05, max_depth_m=0.5)
    bare = Survey(data=pipe.data, dt_s=pipe.dt_s, frequency_hz=pipe.frequency_hz)
    with pytest.raises(GPR3DError, match="the survey has no antenna positions"):
        reconstruct_recording(bare, cfg, eps_r=6.0)
    no_header = pipe.replace(eps_r=None)
    with pytest.raises(GPR3DError, match="--eps-r file: line.h5 gives no eps_r"):
        reconstruct_recording(no_header, cfg, eps_r="file", input_name="line.h5")
    (tmp_path / "empty.json").write_text("[]")
    with pytest.raises(GPR3DError, match="empty.json lists no boxes"):
        reconstruct_recording(pipe, cfg, eps_r=6.0, boxes_file=tmp_path / "empty.json")
    with pytest.raises(GPR3DError, match="give --boxes or --mask detect, not both"):
        reconstruct_recording(pipe, cfg, eps_r=6.0, boxes_file=tmp_path / "empty.json", mask="detect")
    (tmp_path / "far.json").write_text(json.dumps([[5000, 1e-9, 6000, 2e-9]]))
    with pytest.raises(GPR3DError, match="box"):
        reconstruct_recording(pipe, cfg, eps_r=6.0, boxes_file=tmp_path / "far.json")
