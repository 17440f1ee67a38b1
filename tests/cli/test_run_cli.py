"""gpr3d run: the whole system in one command gives the targets the separate commands give, and resumes."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

import gpr3d

DZT = Path(gpr3d.__file__).parent / "data" / "FILE____032.DZT"


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "gpr3d", *map(str, args)], capture_output=True, text=True,
                          timeout=900)


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_run_on_the_real_dzt_finds_the_targets_of_reconstruct_with_the_detector_mask(tmp_path):
    pytest.importorskip("onnxruntime")
    r = run_cli("run", DZT, "--out", tmp_path / "run")
    assert r.returncode == 0, r.stderr
    assert "[3/3] reconstruction" in r.stdout and "report.html" in r.stdout
    ref = run_cli("reconstruct", DZT, "--mask", "detect", "--out", tmp_path / "rec")
    assert ref.returncode == 0, ref.stderr
    got = json.loads((tmp_path / "run" / "reconstruction" / "targets.json").read_text())
    assert got == json.loads((tmp_path / "rec" / "targets.json").read_text()) and got["targets"]
    a = json.loads((tmp_path / "run" / "reconstruction" / "config.json").read_text())
    b = json.loads((tmp_path / "rec" / "config.json").read_text())
    assert a["eps_r"] == b["eps_r"]  # the same estimate, carried from detections.json
    assert a["eps_r_source"].startswith("estimated (hybrid")
    again = run_cli("run", DZT, "--out", tmp_path / "run")
    assert again.returncode == 0, again.stderr
    assert again.stdout.count("kept from an earlier run") == 3


@pytest.mark.parametrize("args, msg", [
    (["--score", "2"], "--score must lie in 0..1"),
    (["--trace-spacing", "0"], "--trace-spacing must be a distance"),
    (["--poses", "nosuch.tum"], "--poses nosuch.tum: no such file"),
    (["--odometry", "x.tum"], "give --imu"),
    (["--eps-r", "0.5"], "--eps-r must be a relative permittivity"),
    (["--spacing", "-1"], "--spacing must be"),
])
def test_wrong_arguments_are_one_line_before_any_work(tmp_path, args, msg):
    import contextlib
    import io

    from gpr3d.cli.main import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main(["run", str(DZT), "--out", str(tmp_path / "o"), *args])
    assert rc != 0 and msg in err.getvalue() and len(err.getvalue().strip().splitlines()) == 1, err.getvalue()
    assert not (tmp_path / "o").exists()


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_run_fuses_a_cart_s_recordings_and_gives_the_targets_of_pose_fuse_then_reconstruct(tmp_path):
    """A synthetic cart (IMU, camera odometry, survey wheel) over a pipe: ``gpr3d run --imu ...`` equals
    ``pose fuse --at`` followed by ``reconstruct --poses --mask detect``; its traces lie where the antenna was and
    its targets are those the true poses give (the fused frame carried to the site by the cart's true start, as a
    surveyor marks it)."""
    pytest.importorskip("onnxruntime")
    import numpy as np

    from gpr3d import Survey
    from gpr3d.core.trajectory import Trajectory
    from gpr3d.pipeline.poses import write_rig_recordings
    from gpr3d.pose.rig import RigConfig, simulate_rig
    from gpr3d.pose.sync import trajectory_triggers
    from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model

    rig = RigConfig(duration_s=45.0, area=((0.0, 1.4), (0.0, 1.4)), stops=1, vo_keyframe_m=0.1,
                    imu_T_antenna=np.array([[1.0, 0, 0, -0.3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    cart = simulate_rig(rig, seed=5)
    files = write_rig_recordings(cart, tmp_path / "rig")
    truth = cart.truth_trajectory()
    trig = trajectory_triggers(truth, 0.01)
    true = truth.at(trig)
    scene = ForwardScene(eps_r=6.0, pipes=[Pipe((0.1, 0.7, -0.33), (1.3, 0.7, -0.33), 0.03)])
    data = forward_model(scene, true.positions_xyz, true.orientations_quat_wxyz, offset_m=0.08, frequency_hz=800e6,
                         n_samples=192, time_window_s=12e-9, air_wave=1.0, ground_wave=0.5)
    Survey(data=data, dt_s=12e-9 / 192, offset_m=0.08, frequency_hz=800e6, eps_r=6.0,
           timestamps_s=trig).save(tmp_path / "cart.h5")
    rigs = [a for f, name in zip(files, ("--imu", "--odometry", "--wheel", None, "--rig")) if name
            for a in (name, tmp_path / "rig" / f)]
    r = run_cli("run", tmp_path / "cart.h5", *rigs, "--eps-r", "file", "--out", tmp_path / "run")
    assert r.returncode == 0, r.stderr
    assert "placed by poses fused from imu.csv and odometry.tum" in r.stdout
    f = run_cli("pose", "fuse", *rigs, "--at", tmp_path / "cart.h5", "--out", tmp_path / "antenna.tum")
    assert f.returncode == 0 and "(one per trace of" in f.stdout, f.stderr
    ref = run_cli("reconstruct", tmp_path / "cart.h5", "--poses", tmp_path / "antenna.tum", "--eps-r", "file",
                  "--mask", "detect", "--out", tmp_path / "rec")
    assert ref.returncode == 0, ref.stderr
    got = json.loads((tmp_path / "run" / "reconstruction" / "targets.json").read_text())
    assert got == json.loads((tmp_path / "rec" / "targets.json").read_text()) and got["targets"]
    # the run's traces, carried into the site frame by the cart's true start, lie where the antenna was
    placed = gpr3d.read(tmp_path / "run" / "survey.h5")
    site = cart.to_world(Trajectory(trig, placed.positions_xyz, placed.orientations_quat_wxyz))
    err = np.linalg.norm(site.positions_xyz - true.positions_xyz, axis=1)
    assert err.mean() < 0.03 and err.max() < 0.06, (err.mean(), err.max())
    # and its targets are those of the same commands run from the true poses, to the fusion's few centimetres
    from gpr3d.io.trajectory import write_tum

    write_tum(true, tmp_path / "truth_at_traces.tum")
    tr = run_cli("reconstruct", tmp_path / "cart.h5", "--poses", tmp_path / "truth_at_traces.tum", "--eps-r", "file",
                 "--mask", "detect", "--out", tmp_path / "true")
    assert tr.returncode == 0, tr.stderr

    def to_site(t):
        p = np.asarray(t["points_xyz"], float)
        p[:, 2] *= -1  # (targets: depth positive down; the world: z up)
        p = cart.to_world(Trajectory(np.arange(2.0), p, np.tile([1.0, 0, 0, 0], (2, 1)))).positions_xyz
        p[:, 2] *= -1
        return p

    def apart(p, q):  # the farther of the two ends, the line taken either way round
        return min(np.linalg.norm(p - q, axis=1).max(), np.linalg.norm(p[::-1] - q, axis=1).max())

    # the true poses' strongest line has its like among the fused run's lines (which of two lines of about the same
    # length is the longer is no property of the poses: one ranked by length flipped with a change to the refiner)
    best = max((t for t in json.loads((tmp_path / "true" / "targets.json").read_text())["targets"]
                if t["kind"] == "line"), key=lambda t: t["score"])
    q = np.asarray(best["points_xyz"], float)
    assert np.linalg.norm(q[1] - q[0]) > 0.5, q  # (a line, not a blob: it must be placed along its length)
    gaps = [apart(to_site(t), q) for t in got["targets"] if t["kind"] == "line"]
    assert min(gaps) < 0.08, (gaps, q)
