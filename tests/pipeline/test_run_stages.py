"""gpr3d run names where its time goes (``gpr3d --timings run ...``): the fusion of an IMU recording is 'poses',
writing the placed survey 'write survey', the depth estimation 'depths' (stand-ins for the slow parts)."""

import types
from pathlib import Path

import numpy as np

from gpr3d.core.survey import Survey
from gpr3d.core.timing import collect
from gpr3d.pipeline import run as R


def test_the_survey_stage_times_the_fusion_and_the_write(tmp_path, monkeypatch):
    import gpr3d.io.trajectory as trajectory
    import gpr3d.pipeline.poses as poses
    import gpr3d.pipeline.recording as recording

    s = Survey(data=np.zeros((5, 8), np.float32), dt_s=1e-10, timestamps_s=np.arange(5.0))
    seen = {}
    monkeypatch.setattr(recording, "read_recording", lambda path, **kw: s)

    def fuse(**kw):
        seen["fused"] = kw
        return types.SimpleNamespace(trajectory="the fused trajectory")

    monkeypatch.setattr(poses, "fuse_recordings", fuse)
    monkeypatch.setattr(poses, "poses_at_traces", lambda tr, sv, source: ("poses of", tr))
    monkeypatch.setattr(trajectory, "attach_poses",
                        lambda sv, p, by: sv.replace(positions_xyz=np.c_[np.arange(5.0), np.zeros(5), np.zeros(5)]))
    cfg = R.RunConfig(input="rec.dzt", out=str(tmp_path), imu="imu.csv", odometry="odo.tum")
    with collect(compile_times=False) as t:
        line = R._survey_stage(cfg, Path(tmp_path), log=lambda m: None)
    assert {"poses", "write survey"} <= set(t.seconds) and t.counts["poses"] == 1
    assert seen["fused"]["imu"] == "imu.csv" and (tmp_path / "survey.h5").is_file()
    assert line == "5 traces x 8 samples, placed by poses fused from imu.csv and odo.tum"


def test_the_detections_stage_times_the_depths(tmp_path, monkeypatch):
    import gpr3d
    import gpr3d.pipeline.targets as targets

    s = Survey(data=np.zeros((5, 8), np.float32), dt_s=1e-10)
    s.save(tmp_path / "survey.h5")
    found = {"input": "rec.dzt", "channel": 0, "n_traces": 5, "dt_s": 1e-10, "n_windows": 1, "targets": []}
    det = types.SimpleNamespace(detect=lambda sv, score_threshold, input_name: dict(found))
    monkeypatch.setattr(targets, "load_models", lambda **kw: (det, "net"))
    calls = []

    def add_depths(sv, f, how, net, _):
        calls.append((how, net))
        f["permittivity"] = {"eps_r": 6.5, "sigma_eps_r": 0.5}

    monkeypatch.setattr(targets, "add_depths", add_depths)
    cfg = R.RunConfig(input="rec.dzt", out=str(tmp_path), depth="net")
    with collect(compile_times=False) as t:
        line = R._detections_stage(cfg, Path(tmp_path), log=lambda m: None)
    assert "depths" in t.seconds and calls == [("net", "net")]
    assert line == "0 hyperbolas; host eps_r 6.50 +- 0.50 (net)"
    assert gpr3d.io.detections.read_detections(tmp_path / "detections.json")[0]["targets"] == []
