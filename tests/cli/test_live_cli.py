"""gpr3d replay feeds gpr3d live over TCP: the last line live prints is the issue's, its numbers the run's (that
the volume equals the batch one, and how the rate and lag are counted, tests/pipeline/test_live.py checks); wrong
arguments get one line before any work."""

import json
import re
import socket
import subprocess
import sys

import numpy as np
import pytest

from gpr3d.io.hdf5 import write_survey
from gpr3d.io.trajectory import Trajectory, write_tum
from tests.pipeline.test_live import fused_bag, rig_run, survey  # noqa: F401  (the fixtures)


def _free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def run_cli(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "gpr3d", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.slow  # (two processes start gpr3d: seconds each)
def test_replay_into_live_prints_traces_rate_and_lag(survey, tmp_path):  # noqa: F811
    write_survey(survey.replace(positions_xyz=None, orientations_quat_wxyz=None), tmp_path / "s.h5")
    write_tum(Trajectory(np.arange(survey.n_traces) * 0.01, survey.positions_xyz, survey.orientations_quat_wxyz),
              tmp_path / "s.tum")
    port = _free_port()
    server = subprocess.Popen([sys.executable, "-m", "gpr3d", "replay", tmp_path / "s.h5", "--poses",
                               tmp_path / "s.tum", "--to", f"tcp://127.0.0.1:{port}", "--rate", "2000"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        r = run_cli("live", f"tcp://127.0.0.1:{port}", "--out", tmp_path / "live", "--no-detect",
                    "--background-window", "32", "--aperture", "45", "--until-idle", "3")
    finally:
        out, err = server.communicate(timeout=60)
    assert r.returncode == 0, r.stderr
    assert server.returncode == 0, err
    assert f"sent {survey.n_traces} traces" in out
    last = r.stdout.strip().splitlines()[-1]
    m = re.fullmatch(r"(\d+) traces, (\d+) traces/s, lag (\d+\.\d\d) s", last)
    assert m, last
    status = json.loads((tmp_path / "live" / "live.json").read_text())["summary"]
    assert int(m.group(1)) == survey.n_traces == status["n_traces"]
    assert int(m.group(2)) == round(status["traces_per_s"]) and float(m.group(3)) == round(status["lag_s"], 2)
    cfg = json.loads((tmp_path / "live" / "config.json").read_text())["config"]
    assert (cfg["background_window"], cfg["background_trailing"], cfg["aperture_deg"]) == (32, True, 45.0)


@pytest.mark.parametrize("args, message", [
    (["live", "tcp://127.0.0.1:1", "--out", "{tmp}/o", "--aperture", "0"], "--aperture must lie in (0, 90)"),
    (["live", "tcp://127.0.0.1:1", "--out", "{tmp}/o", "--aperture-radius", "-2", "--no-detect"],
     "--aperture-radius must be positive, got -2.0"),
    (["live", "tcp://127.0.0.1:1", "--out", "{tmp}/o", "--background-window", "1"],
     "--background-window must be at least 2"),
    (["live", "tcp://127.0.0.1:1", "--out", "{tmp}/o", "--refresh", "0"], "--refresh must be seconds"),
    (["live", "tcp://127.0.0.1:1", "--out", "{tmp}/o", "--spacing", "-1", "--no-detect"], "--spacing must be positive"),
    (["live", "tcp:/bad", "--out", "{tmp}/o", "--no-detect"], "live mode reads growing DZT or DT1 files"),
    (["live", "{tmp}/r.bag", "--out", "{tmp}/o", "--no-detect"], "a bag's traces carry no sample interval: give it"),
    (["live", "tcp://127.0.0.1:1", "--out", "{tmp}/o", "--no-detect", "--detect-in-turn"],
     "--detect-in-turn is for the detector: drop it or --no-detect"),
    (["live", "tcp://127.0.0.1:1", "--out", "{tmp}/o", "--no-detect", "--runtime", "onnx"],
     "--runtime is for the detector: drop it or --no-detect"),
    (["live", "tcp://127.0.0.1:1", "--out", "{tmp}/o", "--runtime", "int8", "--weights", "w.pt"],
     "--runtime int8 runs the shipped detector's 8-bit graph; for w.pt make one with"),
    (["live", "tcp://127.0.0.1:1", "--out", "{tmp}/o", "--dt", "0.1", "--no-detect"], "--dt are for a ROS bag"),
    (["live", "{tmp}/r.bag", "--out", "{tmp}/o", "--dt", "-1", "--no-detect"], "--dt must be ns"),
    (["live", "{tmp}/r.bag", "--out", "{tmp}/o", "--dt", "0.1", "--speed", "-2", "--no-detect"], "--speed must be"),
    (["live", "{tmp}/missing.bag", "--out", "{tmp}/o", "--dt", "0.1", "--no-detect"], "no such bag"),
    (["live", "{tmp}/r.bag", "--out", "{tmp}/o", "--dt", "0.1", "--rig", "r.json", "--still", "2", "--no-detect"],
     "--rig, --still are for --fuse (poses fused from an IMU and odometry)"),
    (["live", "tcp://127.0.0.1:1", "--out", "{tmp}/o", "--fuse", "--imu-topic", "/imu", "--no-detect"],
     "--imu-topic are for a ROS bag"),
    (["live", "{tmp}/x.DZT", "--poses", "{tmp}/p.tum", "--out", "{tmp}/o", "--fuse", "--no-detect"],
     "--fuse is for a ROS bag or a tcp:// stream carrying IMU samples"),
    (["replay", "{tmp}/x.h5", "--to", "tcp://h:1", "--rate", "5", "--odometry", "o.tum"],
     "--odometry and --wheel go with --imu"),
    (["replay", "{tmp}/x.DZT", "--to", "{tmp}/y.DZT", "--rate", "5", "--imu", "i.csv"],
     "--imu, --odometry and --wheel are for --to tcp://"),
    (["replay", "{tmp}/x.h5", "--to", "tcp://h:1", "--rate", "5", "--imu", "i.csv", "--loops", "2"],
     "--loops: a replay with sensor records (--imu) plays once"),
    (["live", "{tmp}/r.bag", "--out", "{tmp}/o", "--dt", "0.1", "--fuse", "--still", "0", "--no-detect"],
     "--still must be"),
    (["live", "{tmp}/r.bag", "--out", "{tmp}/o", "--dt", "0.1", "--fuse", "--pose-topic", "/o", "--no-detect"],
     "poses fused from the IMU and odometry (--fuse) or given (--pose-topic): give one"),
    (["replay", "{tmp}/x.h5", "--to", "tcp://127.0.0.1:1"], "give --rate"),
    (["replay", "{tmp}/x.h5", "--to", "out.dzt", "--rate", "5"], "replays a DZT or DT1 recording into a file of its"),
    (["replay", "{tmp}/x.dt1", "--to", "out.dzt", "--rate", "5"], "replays a DZT or DT1 recording into a file of its"),
    (["live", "{tmp}/x.DT1", "--out", "{tmp}/o", "--poses", "{tmp}/p.tum", "--offset", "-1", "--no-detect"],
     "--offset must be metres"),
    (["replay", "{tmp}/x.h5", "--to", "tcp://h:1", "--rate", "5", "--loops", "0"], "--loops must be at least 1"),
    (["replay", "{tmp}/x.h5", "--to", "tcp://h:1", "--rate", "5", "--accept-timeout", "-1"],
     "--accept-timeout must be seconds"),
    (["replay", "{tmp}/x.h5", "--to", "tcp://h:1", "--rate", "5", "--poses-out", "p.tum"], "--poses-out is for"),
    (["replay", "{tmp}/x.dzt", "--to", "o.dzt", "--rate", "5", "--loop-shift", "5"], "--loops and --loop-shift"),
    (["replay", "{tmp}/x.dzt", "--to", "o.dzt", "--rate", "5", "--poses", "p.tum"],
     "takes --poses and --poses-out together"),
])
def test_wrong_arguments_get_one_line(tmp_path, capsys, args, message):
    from gpr3d.cli.main import main

    code = main([a.replace("{tmp}", str(tmp_path)) for a in args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1 and message in err[0], err


def test_live_replays_a_ros_bag_given_its_sample_interval_and_topics(survey, tmp_path, capsys):  # noqa: F811
    from gpr3d.cli.main import main
    from tests.pipeline.test_live import DT, EPS, _bag_of

    bag = _bag_of(survey, tmp_path / "run.bag", ros1=True)
    code = main(["live", str(bag), "--dt", str(DT * 1e9), "--trace-topic", "/gpr/traces", "--pose-topic",
                 "/odometry", "--speed", "0", "--eps-r", str(EPS), "--offset", "0.05", "--no-detect",
                 "--background-window", "32", "--aperture", "45", "--out", str(tmp_path / "live")])
    out = capsys.readouterr().out.strip().splitlines()
    assert code == 0
    assert re.fullmatch(rf"{survey.n_traces} traces, \d+ traces/s, lag \d+\.\d\d s", out[-1]), out[-1]
    cfg = json.loads((tmp_path / "live" / "config.json").read_text())["config"]
    assert cfg["eps_r"] == EPS and cfg["background_window"] == 32


@pytest.mark.parametrize("flag, in_thread", [((), True), (("--detect-in-turn",), False)])
def test_live_runs_its_detector_in_a_thread_unless_told_to_take_turns(survey, tmp_path, monkeypatch, flag,  # noqa: F811
                                                                      in_thread):
    import gpr3d.pipeline
    from gpr3d.cli.main import main
    from tests.pipeline.test_live import DT, EPS, _bag_of

    seen = {}

    def run_live(source, out, cfg, *, detector=None, log=None):
        seen.update(cfg=cfg, detector=detector)
        raise gpr3d.core.errors.GPR3DError("stopped by the test")

    monkeypatch.setattr(gpr3d.pipeline, "run_live", run_live)
    bag = _bag_of(survey, tmp_path / "run.bag", ros1=True)
    code = main(["live", str(bag), "--dt", str(DT * 1e9), "--trace-topic", "/gpr/traces", "--pose-topic",
                 "/odometry", "--eps-r", str(EPS), "--out", str(tmp_path / "live"), *flag])
    assert code != 0 and seen["cfg"].detect and seen["detector"] is not None
    assert seen["cfg"].detect_thread is in_thread


@pytest.mark.parametrize("flags, graph", [((), "default_detector_int8.onnx"),
                                          (("--runtime", "onnx"), "default_detector.onnx"),
                                          (("--runtime", "torch"), None)])
def test_live_runs_the_8bit_detector_graph_unless_told_otherwise(survey, tmp_path, monkeypatch, flags,  # noqa: F811
                                                                 graph):
    pytest.importorskip("onnxruntime")
    import gpr3d.pipeline
    from gpr3d.cli.main import main
    from gpr3d.detection.ort import OnnxDetector
    from tests.pipeline.test_live import DT, EPS, _bag_of

    seen = {}

    def run_live(source, out, cfg, *, detector=None, log=None):
        seen.update(detector=detector)
        raise gpr3d.core.errors.GPR3DError("stopped by the test")

    monkeypatch.setattr(gpr3d.pipeline, "run_live", run_live)
    bag = _bag_of(survey, tmp_path / "run.bag", ros1=True)
    code = main(["live", str(bag), "--dt", str(DT * 1e9), "--trace-topic", "/gpr/traces", "--pose-topic",
                 "/odometry", "--eps-r", str(EPS), "--out", str(tmp_path / "live"), *flags])
    det = seen["detector"]
    assert code != 0 and det.refiner is not None  # (the shipped refiner with the shipped detector, either way)
    if graph is None:
        assert not isinstance(det, OnnxDetector) and det.model is not None
    else:
        assert isinstance(det, OnnxDetector) and det.path.name == graph
        assert det.provenance["name"].endswith(" (8-bit)") is ("int8" in graph)


def test_live_fuses_a_bag_s_poses_as_the_replay_comes(fused_bag, tmp_path, capsys):  # noqa: F811
    from gpr3d.cli.main import main
    from tests.pipeline.test_live import DT, EPS

    code = main(["live", str(fused_bag / "run"), "--dt", str(DT * 1e9), "--fuse", "--rig", str(fused_bag / "rig.json"),
                 "--still", "1", "--speed", "0", "--eps-r", str(EPS), "--offset", "0.05", "--no-detect",
                 "--background-window", "32", "--aperture", "45", "--out", str(tmp_path / "live")])
    out = capsys.readouterr().out.strip().splitlines()
    assert code == 0 and re.fullmatch(r"350 traces, \d+ traces/s, lag \d+\.\d\d s", out[-1]), out[-1]


@pytest.mark.slow  # (two processes start gpr3d: seconds each)
def test_replay_sends_a_cart_s_sensors_and_live_fuses_its_poses_from_them(rig_run, tmp_path):  # noqa: F811
    folder, _, survey = rig_run
    write_survey(survey, tmp_path / "s.h5")
    port = _free_port()
    server = subprocess.Popen([sys.executable, "-m", "gpr3d", "replay", tmp_path / "s.h5", "--imu", folder / "imu.csv",
                               "--odometry", folder / "odometry.tum", "--wheel", folder / "wheel.csv",
                               "--to", f"tcp://127.0.0.1:{port}", "--speed", "20"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        r = run_cli("live", f"tcp://127.0.0.1:{port}", "--fuse", "--rig", folder / "rig.json", "--out",
                    tmp_path / "live", "--no-detect", "--background-window", "32", "--until-idle", "3")
    finally:
        out, err = server.communicate(timeout=60)
    assert r.returncode == 0, r.stderr
    assert server.returncode == 0, err
    assert f"sent {survey.n_traces} traces" in out and "at 500 traces/s" in out  # (25 a second in the record)
    last = r.stdout.strip().splitlines()[-1]
    assert re.fullmatch(rf"{survey.n_traces} traces, \d+ traces/s, lag \d+\.\d\d s", last), last
    from gpr3d.io.volume import read_volume
    from gpr3d.pipeline.poses import fuse_recordings

    # the volume spans the cart's fused path, the pipe found (where, in the fusion's world: tests/pipeline)
    at = fuse_recordings(imu=folder / "imu.csv", odometry=folder / "odometry.tum", wheel=folder / "wheel.csv",
                         rig=folder / "rig.json", log=None).trajectory.at(survey.timestamps_s)
    g = read_volume(tmp_path / "live" / "volume.h5").grid
    lo, hi = at.positions_xyz.min(axis=0), at.positions_xyz.max(axis=0)
    assert g.x0 <= lo[0] + 0.03 and g.x0 + (g.nx - 1) * g.dx >= hi[0] - 0.03
    assert g.y0 <= lo[1] + 0.03 and g.y0 + (g.ny - 1) * g.dy >= hi[1] - 0.03
    assert [t["kind"] for t in json.loads((tmp_path / "live" / "targets.json").read_text())["targets"]] == ["line"]


def test_replay_grows_a_dt1_without_its_hd_given_a_rate_and_asks_for_the_hd_only_for_speed(tmp_path):
    from tests.io.makers import write_dt1

    src = write_dt1(tmp_path / "line", n_traces=40, n_points=20)
    src.with_suffix(".HD").unlink()  # (a DT1 whose header was never written: --rate needs none)
    out = tmp_path / "grown" / "LINE.DT1"
    out.parent.mkdir()
    r = run_cli("replay", src, "--to", out, "--rate", "100000")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == f"wrote 40 traces to {out} at 100000 traces/s"
    assert out.read_bytes() == src.read_bytes() and sorted(p.name for p in out.parent.iterdir()) == ["LINE.DT1"]
    r = run_cli("replay", src, "--to", out, "--speed", "2")
    assert r.returncode != 0 and len(r.stderr.strip().splitlines()) == 1 and "HD" in r.stderr
