"""The command line: what a user types and sees."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest

import gpr3d
from gpr3d.cli.main import main
from tests.conftest import real_file, real_files

# (traces, samples, range ns, antenna text) from ../shared/data/real/README.md
FACTS = {
    "FILE____032.DZT": (1040, 512, 48, "400MHz"),
    "test_gssi.DZT": (345, 2048, 2300, "5106"),
    "ten_col.rd3": (10, 512, 211.03, "500_shielded_egrip"),
    "ten_col_nogps.rd3": (10, 512, 211.03, "500_shielded_egrip"),
}


def run_cli(*args):
    # the limit only stops a hang: the demo takes about 220 s on 2 cores beside another test worker (not a speed check;
    # its stage times are in its summary)
    return subprocess.run([sys.executable, "-m", "gpr3d", *map(str, args)], capture_output=True, text=True,
                          timeout=1500)


def test_info_on_every_real_file():
    files = real_files()
    if not files:
        pytest.skip("real data not available")
    r = run_cli("info", *files)
    assert r.returncode == 0, r.stderr
    blocks = re.split(r"\n(?=\S)", r.stdout.strip())
    assert len(blocks) == len(files)
    for path, block in zip(files, blocks):
        assert block.startswith(str(path))
        n, m = map(int, re.search(r"traces x samples : (\d+) x (\d+)", block).groups())
        rng = float(re.search(r"range: ([\d.]+) ns", block).group(1))
        ant = re.search(r"antenna\s+: (.*) \(", block).group(1)
        if path.name in FACTS:
            fn, fm, frange, fant = FACTS[path.name]
        elif path.suffix == ".DT1":
            hd = dict(line.split("=", 1) for line in path.with_suffix(".HD").read_text().splitlines() if "=" in line)
            hd = {k.strip(): v.strip() for k, v in hd.items()}
            fn, fm = int(hd["NUMBER OF TRACES"]), int(hd["NUMBER OF PTS/TRC"])
            frange, fant = float(hd["TOTAL TIME WINDOW"]), f"{float(hd['NOMINAL FREQUENCY']):g} MHz pulseEKKO"
        else:
            raise AssertionError(f"no facts for {path}")
        assert (n, m) == (fn, fm), path
        assert rng == pytest.approx(frange, rel=1e-4), path
        assert ant == fant, path
    assert "header window    : 422.061 ns" in r.stdout  # the MALA header's own TIMEWINDOW is shown too


def test_info_json(capsys):
    p = real_file("gprpy_sns_50MHz/XLINE00.DT1")
    assert main(["info", str(p), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows[0]["n_traces"] == 531 and rows[0]["frequency_hz"] == 50e6


def test_user_errors_are_one_line_without_traceback(tmp_path):
    bad = tmp_path / "junk.DZT"
    bad.write_bytes(b"\x00" * 100)
    r = run_cli("info", bad)
    assert r.returncode == 1
    assert r.stderr.strip().count("\n") == 0 and "Traceback" not in r.stderr
    assert r.stderr.startswith("gpr3d: error: junk.DZT:")
    r = run_cli("process", bad, "--steps", "dewow", "--out", tmp_path / "x.h5")
    assert r.returncode == 1 and "Traceback" not in r.stderr
    good = real_file("impdar_mala_500MHz/ten_col.rd3")
    for args, msg in [
        (("process", good, "--steps", "wiggle", "--out", tmp_path / "x.h5"), "unknown processing step 'wiggle'"),
        (("process", good, "--steps", "bandpass:fmin_hz=9e9", "--out", tmp_path / "x.h5"), "Nyquist"),
        (("convert", good, tmp_path / "x.xyz"), "x.xyz: expected a .h5 or .hdf5 or .sgy or .segy or .png file"),
        (("show", good, "--out", tmp_path / "x.png", "--axis", "depth"), "needs --eps-r"),
        (("info", tmp_path / "missing.DZT"), "no such file"),
        (("info", good, "--format", "dzt"), "not a DZT file"),
    ]:
        r = run_cli(*args)
        assert r.returncode == 1, args
        assert msg in r.stderr and "Traceback" not in r.stderr, (args, r.stderr)
        assert len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_truncated_file_warns_in_one_line(tmp_path):
    src = real_file("gprpy_gssi_400MHz/FILE____032.DZT")
    cut = tmp_path / "cut.DZT"
    cut.write_bytes(src.read_bytes()[:-300])
    r = run_cli("info", cut)
    assert r.returncode == 0
    assert "gpr3d: warning: cut.DZT: recording ends mid-trace; dropped 1 partial trace" in r.stderr
    assert "1039 x 512" in r.stdout


def test_process_convert_show(tmp_path):
    src = real_file("gprpy_gssi_400MHz/FILE____032.DZT")
    out = tmp_path / "p.h5"
    assert main(["process", str(src), "--steps", "time_zero:threshold=0.3", "dewow", "remove_background",
                 "gain_tpow:power=1.5", "bandpass:fmin_hz=1.5e8:fmax_hz=8e8", "--out", str(out)]) == 0
    s = gpr3d.read(out)
    assert [h["step"] for h in s.history] == ["time_zero", "dewow", "remove_background", "gain_tpow", "bandpass"]
    assert s.history[3]["args"] == {"power": 1.5}
    ref = gpr3d.read(src).time_zero(threshold=0.3).dewow().remove_background().gain_tpow(power=1.5).bandpass(
        fmin_hz=1.5e8, fmax_hz=8e8)
    np.testing.assert_array_equal(s.data, ref.data)
    assert main(["convert", str(src), str(tmp_path / "c.sgy")]) == 0
    assert main(["show", str(src), "--out", str(tmp_path / "s.png"), "--axis", "depth", "--cmap", "hot",
                 "--steps", "time_zero", "dewow"]) == 0
    assert (tmp_path / "s.png").stat().st_size > 10_000


def test_help_has_examples():
    r = run_cli("--help")
    assert r.returncode == 0 and "examples:" in r.stdout and "gpr3d demo" in r.stdout
    r = run_cli("process", "--help")
    assert "time_zero" in r.stdout and "example:" in r.stdout


def test_the_parser_is_built_without_processing_or_migration_and_its_help_lists_the_steps():
    # the steps' list and the reconstruction defaults once imported SciPy's signal and stats and numba at every start
    code = ("import sys; from gpr3d.cli.main import build_parser; p = build_parser(); "
            "print(sorted(m for m in ('gpr3d.processing', 'gpr3d.migration.reconstruct', 'gpr3d.migration.operator', "
            "'scipy.signal', 'numba') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"
    for cmd in ("show", "process"):
        out = run_cli(cmd, "--help").stdout
        assert "known steps:" in out and "gain_tpow[:power,t_ref_s]" in out and "dewow" in out, cmd
    # the package's names, imported on first use
    import gpr3d.migration as mig
    from gpr3d.core.grid import Grid3D
    from gpr3d.migration.operator import BackProjection

    assert mig.Grid3D is Grid3D and mig.BackProjection is BackProjection
    with pytest.raises(AttributeError, match="has no attribute 'nosuch'"):
        mig.nosuch


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_demo_end_to_end(tmp_path):
    r = run_cli("demo", "--out", tmp_path / "d")
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "d" / "summary.json").read_text())
    real = summary["stages"]["real"]
    assert (real["n_traces"], real["n_samples"]) == (1040, 512)
    # the voxel reconstruct would take for it: a tenth of 400 MHz's wavelength in the header's eps_r 6 (30.6 cm)
    assert real["voxel_m"] == 0.031
    assert "reconstruct's voxel for it: 3.1 cm, a tenth of the 400 MHz wavelength in the host" in r.stdout
    for row in summary["stages"]["synthetic"]["apexes"]:
        assert abs(row["apex_time_error_s"]) < 0.1e-9  # two samples
        assert abs(row["apex_trace_found"] - row["apex_trace_true"]) <= 1
    assert summary["stages"]["reconstruction"]["excess_fraction"] < 0.25
    rtm = summary["stages"]["synthetic"]["rtm"]  # the wave-equation step focuses each point target
    assert len(rtm["focus_error_m"]) == 2 and max(rtm["focus_error_m"]) <= 2 * rtm["cell_m"]
    # the depth range reconstruct would choose: the demo's clutter is coherent to the record's end (nothing cut)
    depth = summary["stages"]["reconstruction"]["depth_range"]
    assert depth["how"] == "record" and depth["why"] == "the signal reaches the record's end"
    assert depth["depth_m"] == depth["record_m"] == pytest.approx(0.5 * 0.95 * 299792458.0 / 3 * 37.1e-9, abs=0.02)
    rec_tiles = summary["stages"]["reconstruction"]["tiles"]  # site tiles give the one-pass volume exactly
    assert rec_tiles["equal_to_one_pass"] and rec_tiles["n"] > 1
    rec = summary["stages"]["reconstruction"]
    # coarse-to-fine, the default: every-voxel's targets, within a voxel, from part of the work; no more false ones
    c2f = rec["coarse_to_fine"]
    assert c2f["refine"]["stride"] > 1 and 0 < c2f["refine"]["refined_fraction"] < 0.5
    assert c2f["matched"] == c2f["every_voxel"]["n_targets"] <= rec["n_targets"] and c2f["largest_move_m"] <= 0.02
    assert rec["false_targets"] <= c2f["every_voxel"]["false_targets"]
    # an aperture radius of 0.5 m: the pipes the whole cone finds over most of their length are still found so
    rad = rec["aperture_radius"]
    full = [r["completeness"] for r in rec["truth"]]
    assert rad["radius_m"] == 0.5 and len(rad["completeness"]) == len(full) >= 2 and max(full) >= 0.9
    assert all(c >= 0.9 for c, f in zip(rad["completeness"], full) if f >= 0.9)
    assert rad["false_targets"] <= rec["false_targets"] + 2
    walk = summary["stages"]["random_motion"]
    # a trace every 1 cm of the antenna's path: the count follows the path length
    assert walk["n_traces"] == pytest.approx(100 * walk["path_m"], abs=2) and walk["path_m"] > 50
    poses = walk["poses"]  # the survey's poses are the fusion's (smoothed, loops closed), mm to cm off the truth
    assert 0.001 < poses["antenna_error_mean_m"] < 0.03 and poses["vo_rejected"] >= poses["vo_outliers"] > 0
    assert poses["loop_closures"] > 20
    rec = summary["stages"]["reconstruction"]
    assert rec["poses"].startswith("estimated")
    for key, rows in (("fused poses", rec["truth"]), ("true poses", rec["with_true_poses"]["truth"])):
        found = [row for row in rows[:3] if "position_error_m" in row]
        assert len(found) == 3, key  # both legs of the L and the diagonal: the migration targets
        for row in found:
            assert row["position_error_m"] <= 0.03 and row["orientation_error_deg"] <= 3.0, (key, row)
            assert row["completeness"] >= 0.9 and row["depth_error_m"] < 0.05, (key, row)
            assert row["endpoint_error_m"] < 0.25, (key, row)  # the demo scores overshoot too
    names = {p.name for p in (tmp_path / "d").iterdir()}
    assert {"summary.json", "config.json", "real_raw.png", "real_processed.png", "real_processed.h5",
            "synthetic_processed.png", "synthetic_rtm.png", "random_walk_survey.h5", "random_walk.tum", "random_walk_truth.tum",
            "random_walk_map.png",
            "reconstruction"} <= names
    # the names the summary gives the targets found (and the false ones) are those of targets.json and the figures
    listed = [t["name"] for t in json.loads((tmp_path / "d" / "reconstruction" / "targets.json").read_text())["targets"]]
    assert listed == [f"T{i + 1}" for i in range(rec["n_targets"])]
    named = [n for row in rec["truth"] for n in row["found_as"]] + rec["false"]
    assert sorted(named) == sorted(listed) and len(rec["false"]) == rec["false_targets"]
    assert not [n for n in names if n.endswith(".part")]
    det = summary["stages"]["detection"]
    if "skipped" not in det:  # PyTorch installed: depth from the data, and the masked migration uses it
        depth = det["depth"]["random_walk"]
        assert depth["eps_r_true"] == 9.0
        for m in ("net", "fit", "hybrid"):
            assert 1.0 <= depth[m]["eps_r"] <= 81.0 and depth[m]["n_depths"] > 0
        assert depth["hybrid"]["eps_r"] == depth["eps_r"]
        # the masked migration uses the eps_r that focuses it best: the truth within 10 % on oblique crossings
        assert det["masked_eps_r"] == depth["focus"]["eps_r"] and abs(depth["focus"]["eps_r"] - 9.0) < 0.9
        cfg = json.loads((tmp_path / "d" / "reconstruction_masked" / "config.json").read_text())
        assert cfg["eps_r"] == pytest.approx(depth["focus"]["eps_r"])
        assert det["depth"]["real"]["eps_r_header"] == 6.0
        # the survey's boxes by gpr3d's rule, their scores weighed by the refiner's quality head (a recording)
        assert det["refine"] == {"mirror": True, "passes": 2, "fine": None, "duplicate_iou": 0.5, "rule": "gpr3d",
                                 "quality_weight": 1.0}
        assert "each score times the box's predicted fit (IoU with its label) to the power 1" in r.stdout
        pg = det["pgpr"]  # the real P-GPR B-scan against its label file (9 lines: 7 steel, 2 pipe)
        assert (pg["image"], pg["n_labelled"]) == ("IECAS_0032.png", 9) and "detections_pgpr.png" in names
        assert 0 <= pg["right_kind"] <= pg["found_iou50"] <= 9 and sum(pg["kinds"].values()) == pg["n_detections"]
        # how sure of the kinds: the least sure box's two best shares are at most the mean best share, and its best
        sure = pg["kind_shares"]
        best, second = sure["least_sure"].values()
        assert 0.2 <= best <= sure["mean"] <= 1 and 0 <= second <= best and best + second <= 1 + 1e-3
        assert f"kinds named with a mean share of {sure['mean']:.2f}; the least sure box: " in r.stdout
        # its boxes placed by the shipped refiner, beside the network's own (one image: either may fit better)
        assert pg["refiner"] == "refiner_pgpr_synth_gprmax_whole_rules_quality"
        assert set(pg["mean_iou"]) == {"refined", "network", "no_fine", "mirrored"}
        assert "then its fine stage refiner_fine_pgpr_5): mean IoU with the labels" in r.stdout
        assert f"({pg['mean_iou']['no_fine']:.2f} without the fine stage)" in r.stdout
        assert pg["mean_iou"]["no_fine"] != pg["mean_iou"]["refined"]  # the fine stage moved the boxes
        # the default application, as detect reports it: P-GPR's head for a picture, its quality not weighing the scores
        assert pg["refine"] == {"mirror": True, "passes": 2, "fine": "refiner_fine_pgpr_5", "duplicate_iou": 0.5,
                                "rule": "pgpr", "quality_weight": 0.0}
        assert all(0.3 < v <= 1 for v in pg["mean_iou"].values()) and pg["mean_iou"]["refined"] != pg["mean_iou"]["network"]
        # and seen mirrored too: the two views' boxes fused move them
        assert 0 <= pg["found_iou50_mirrored"] <= 9 and pg["mean_iou"]["mirrored"] != pg["mean_iou"]["refined"]
    pose = summary["stages"]["pose"]  # the fused path beats chained odometry that a gap and gross errors break
    assert {"pose_fused.tum", "pose_vo_alone.tum", "pose_truth.tum", "pose_paths.png"} <= names
    # where its time went: each of its stages, the library's inside them, adding up to its wall time
    times = json.loads((tmp_path / "d" / "timings.json").read_text())
    demo_rows = [k for k in times["stages"] if k.startswith("demo")]
    assert demo_rows == ["demo 1: real recording", "demo 2: synthetic B-scan", "demo 3: random-motion survey",
                         "demo 4: reconstruction", "demo 5-6: detection, depths, masked migration", "demo 7: pose",
                         "demo 8: live", "demo: report"]
    live = summary["stages"]["live"]  # the survey streamed into live mode: its volume is the batch one
    assert live["n_traces"] == walk["n_traces"] and live["same_grid"] and live["max_difference"] < 1e-4
    # counted from the first poll that brings traces, which may come a few hundredths of a second after the
    # first was sent (a scheduling delay, not the CPU's speed): a fifth over the rate is far more than that
    assert 0 < live["traces_per_s"] <= 1.2 * live["rate"] and live["n_targets"] >= 3
    assert live["n_detections"] is None if "skipped" in summary["stages"]["detection"] else live["n_detections"] > 10
    assert {"migrate", "targets", "figures", "network"} <= set(times["stages"])
    assert sum(times["stages"].values()) == pytest.approx(times["wall_s"], abs=1e-3)
    assert summary["timings_s"] == pytest.approx(times["stages"], abs=1e-6)
    assert "where the demo's time went" in r.stdout and r.stdout.rstrip().splitlines()[-1].split()[0] == "total"
    assert pose["path_m"] > 12 and pose["vo_rejected"] >= pose["vo_outliers"] > 0
    if "fused_ape_m" in pose:
        assert pose["fused_ape_m"] < 0.005 * pose["path_m"] and pose["fused_ape_m"] < 0.5 * pose["vo_alone_ape_m"]


def test_pose_simulate_then_fuse_writes_a_trajectory_close_to_the_truth(tmp_path):
    pytest.importorskip("evo")
    from gpr3d.io.trajectory import read_tum
    from gpr3d.pose.metrics import ape

    rig = tmp_path / "rig"
    r = run_cli("pose", "simulate", "--out", rig, "--duration", "40", "--seed", "2")
    assert r.returncode == 0, r.stderr
    r = run_cli("pose", "fuse", "--imu", rig / "imu.csv", "--odometry", rig / "odometry.tum", "--wheel",
                rig / "wheel.csv", "--rig", rig / "rig.json", "--still", "2", "--out", tmp_path / "a.tum",
                "--truth", rig / "truth.tum", "--figure", tmp_path / "p.png")
    assert r.returncode == 0, r.stderr
    est, truth = read_tum(tmp_path / "a.tum"), read_tum(rig / "truth.tum")
    path = float(np.sum(np.linalg.norm(np.diff(truth.positions_xyz, axis=0), axis=1)))
    assert path > 8 and ape(est, truth)["rmse"] < 0.005 * path
    assert (tmp_path / "p.png").stat().st_size > 10_000
    # without the rig's mounts and latency the same data fuse worse: the file's values are used
    r = run_cli("pose", "fuse", "--imu", rig / "imu.csv", "--odometry", rig / "odometry.tum", "--still", "2",
                "--out", tmp_path / "b.tum")
    assert r.returncode == 0, r.stderr
    assert ape(read_tum(tmp_path / "b.tum"), truth)["rmse"] > 1.5 * ape(est, truth)["rmse"]
    for bad, msg in ((["--imu", rig / "wheel.csv"], "IMU CSV header lacks"),
                     (["--imu", rig / "imu.csv", "--odometry", rig / "odometry.tum", "--odometry-sigma", "a,b,c"],
                      "--odometry-sigma"),
                     (["--imu", rig / "imu.csv", "--flat-ground", "-1"], "--flat-ground"),
                     (["--imu", rig / "imu.csv", "--keyframe", "nan"], "--keyframe"),
                     (["--imu", rig / "imu.csv", "--keyframe", "-0.1"], "--keyframe")):
        r = run_cli("pose", "fuse", *bad, "--out", tmp_path / "x.tum")
        assert r.returncode != 0 and msg in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_pose_simulate_bag_then_fuse_from_the_bag(tmp_path):
    pytest.importorskip("evo")
    pytest.importorskip("rosbags")
    from gpr3d.io.trajectory import read_tum
    from gpr3d.pose.metrics import ape

    rig = tmp_path / "rig"
    r = run_cli("pose", "simulate", "--out", rig, "--duration", "30", "--seed", "1", "--bag")
    assert r.returncode == 0, r.stderr
    r = run_cli("pose", "fuse", "--bag", rig / "bag", "--rig", rig / "rig.json", "--still", "2", "--out",
                tmp_path / "a.tum")
    assert r.returncode == 0, r.stderr
    # the same recordings from CSV/TUM files give the same poses (to the 7 digits the CSV keeps)
    r = run_cli("pose", "fuse", "--imu", rig / "imu.csv", "--odometry", rig / "odometry.tum", "--rig", rig / "rig.json",
                "--still", "2", "--out", tmp_path / "b.tum")
    assert r.returncode == 0, r.stderr
    a, b, truth = read_tum(tmp_path / "a.tum"), read_tum(tmp_path / "b.tum"), read_tum(rig / "truth.tum")
    assert np.max(np.abs(a.positions_xyz - b.positions_xyz)) < 5e-3
    path = float(np.sum(np.linalg.norm(np.diff(truth.positions_xyz, axis=0), axis=1)))
    assert ape(a, truth)["rmse"] < 0.005 * path
    r = run_cli("pose", "fuse", "--bag", rig / "bag", "--imu", rig / "imu.csv", "--out", tmp_path / "c.tum")
    assert r.returncode != 0 and r.stderr.count("\n") == 1 and "not both" in r.stderr


def test_the_demo_pairs_targets_by_kind_shape_and_distance():
    from types import SimpleNamespace as T

    from gpr3d.demo import _counterparts

    full = [T(kind="line", points_xyz=[[0, 0, 0.5], [1, 0, 0.5]]), T(kind="point", points_xyz=[[2, 2, 0.3]])]
    fast = [T(kind="line", points_xyz=[[0.01, 0, 0.5], [1, 0.02, 0.5]]),  # 2 cm off at one end
            T(kind="point", points_xyz=[[2, 2, 0.33]]),                   # 3 cm deeper
            T(kind="line", points_xyz=[[2, 2, 0.3], [2, 3, 0.3]]),        # a line where full has a point
            T(kind="point", points_xyz=[[0, 0, 0.5]])]                    # a point where full has a line end
    n, far = _counterparts(fast, full)
    assert n == 2 and far == pytest.approx(0.03)
    assert _counterparts(fast, full, within_m=0.025) == (1, pytest.approx(0.02))
    assert _counterparts([], full) == (0, 0.0) and _counterparts(fast, []) == (0, 0.0)
