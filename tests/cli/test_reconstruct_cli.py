"""gpr3d reconstruct: a radar file plus a TUM trajectory in, a volume and targets.json out."""

import json
import subprocess
import sys

import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.io.trajectory import Trajectory, write_tum
from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model
from gpr3d.simulation.paths import random_walk


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "gpr3d", *map(str, args)], capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="module")
def pipe_survey(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    walk = random_walk(2500, area=((0, 1.2), (0, 1.2)), step_m=0.01, seed=2)
    top = 0.4
    scene = ForwardScene(eps_r=6.0, pipes=[Pipe((0.1, 0.6, -top - 0.03), (1.1, 0.6, -top - 0.03), 0.03)])
    data = forward_model(scene, walk.positions_xyz, walk.orientations_quat_wxyz, offset_m=0.08, frequency_hz=800e6,
                         n_samples=256, time_window_s=16e-9, air_wave=1.0, ground_wave=0.5)
    s = Survey(data=data, dt_s=16e-9 / 256, offset_m=0.08, frequency_hz=800e6, eps_r=6.0)  # no poses in the file
    s.save(d / "line.h5")
    write_tum(walk, d / "walk.tum")
    return d, top


def test_reconstruct_with_a_tum_trajectory(pipe_survey):
    d, top = pipe_survey
    # coarse-to-fine by default (here at a refine level of its own), config.json saying what it did
    r = run_cli("reconstruct", d / "line.h5", "--poses", d / "walk.tum", "--out", d / "out", "--max-depth", "0.7",
                "--eps-r", "file", "--refine-level", "0.4")
    assert "eps_r 6 (the file header)" in r.stdout
    assert r.returncode == 0, r.stderr
    out = d / "out"
    for name in ("volume.h5", "volume.vti", "targets.json", "config.json", "top.png", "front.png", "view3d.png"):
        assert (out / name).stat().st_size > 0, name
    assert (out / "volume.vti").read_text(errors="ignore").startswith("<?xml")
    targets = json.loads((out / "targets.json").read_text())["targets"]
    lines = [t for t in targets if t["kind"] == "line"]
    assert lines, targets
    best = max(lines, key=lambda t: np.linalg.norm(np.subtract(t["points_xyz"][1], t["points_xyz"][0])))
    p = np.array(best["points_xyz"])
    assert np.allclose(p[:, 1], 0.6, atol=0.03)  # along x at y = 0.6
    assert np.allclose(p[:, 2], top, atol=0.03)  # depth to the top, positive down
    assert abs(p[1, 0] - p[0, 0]) > 0.6
    doc = json.loads((out / "config.json").read_text())
    assert doc["config"]["coarse_to_fine"] is True and doc["config"]["refine_level"] == 0.4
    refine = doc["refine"]
    assert refine["stride"] == 2 and refine["level"] == pytest.approx(0.4 * doc["config"]["threshold"]), refine
    # 2500 traces 1 cm apart along the walk, a quarter wavelength 3.8 cm: the coarse pass read every third trace,
    # so the fine pass migrated the coarse columns' refined depths too
    assert refine["coarse_trace_step"] == 3 and "thinned" not in refine, refine
    assert refine["fine_fraction"] == pytest.approx(refine["refined_fraction"]) and 0 < refine["refined_fraction"] < 0.7
    assert (f"coarse-to-fine: every 2 columns at every depth, then {refine['refined_fraction']:.0%} of the voxels at "
            "full resolution where that image holds energy" in r.stdout)
    assert "voxel-trace updates/s counted over every voxel)" in r.stdout
    # --no-coarse-to-fine: every voxel migrated, the same targets to the millimetre
    r = run_cli("reconstruct", d / "line.h5", "--poses", d / "walk.tum", "--out", d / "every", "--max-depth", "0.7",
                "--eps-r", "file", "--no-coarse-to-fine")
    assert r.returncode == 0, r.stderr
    doc = json.loads((d / "every" / "config.json").read_text())
    assert doc["config"]["coarse_to_fine"] is False and doc["refine"] is None
    assert "coarse-to-fine" not in r.stdout and "counted over every voxel" not in r.stdout
    every = json.loads((d / "every" / "targets.json").read_text())["targets"]
    assert [t["kind"] for t in every] == [t["kind"] for t in targets]
    for a, b in zip(targets, every):
        np.testing.assert_allclose(b["points_xyz"], a["points_xyz"], atol=1e-3)


def test_where_coarse_to_fine_cannot_gain_the_command_says_why(pipe_survey, tmp_path):
    d, _ = pipe_survey
    # 3 cm columns, a third of the 15 cm wavelength (800 MHz, eps_r 6) apart already: every voxel migrated
    r = run_cli("reconstruct", d / "line.h5", "--poses", d / "walk.tum", "--out", tmp_path / "o", "--max-depth", "0.5",
                "--eps-r", "file", "--spacing", "0.03")
    assert r.returncode == 0, r.stderr
    assert "coarse-to-fine: the grid's columns are within a third of a wavelength of each other already" in r.stdout
    assert "counted over every voxel" not in r.stdout and "coarse-to-fine left out" not in r.stdout
    assert json.loads((tmp_path / "o" / "config.json").read_text())["refine"]["stride"] == 1


def test_reconstruct_errors_are_one_line(pipe_survey, tmp_path):
    d, _ = pipe_survey
    r = run_cli("reconstruct", d / "line.h5", "--out", tmp_path / "o")
    assert r.returncode == 1 and "no antenna positions" in r.stderr and "Traceback" not in r.stderr
    short = Trajectory([0, 1], [[0, 0, 0], [1, 0, 0]], [[1, 0, 0, 0]] * 2)
    write_tum(short, tmp_path / "short.tum")
    r = run_cli("reconstruct", d / "line.h5", "--poses", tmp_path / "short.tum", "--out", tmp_path / "o")
    assert r.returncode == 1 and "short.tum holds 2 poses but" in r.stderr and "line.h5 has 2500 traces" in r.stderr
    (tmp_path / "boxes.json").write_text("[[1, 2, 3]]")
    r = run_cli("reconstruct", d / "line.h5", "--poses", d / "walk.tum", "--boxes", tmp_path / "boxes.json",
                "--out", tmp_path / "o")
    assert r.returncode == 1 and "box 0 must be 4 numbers" in r.stderr


def test_boxes_make_a_noise_map(pipe_survey, tmp_path):
    """The noise map is the data outside the boxes, migrated: with a box around the pipe's echo (2-12 ns) the pipe
    (0.4 m deep along y = 0.6) is in the envelope and not in the noise map; with the box after the echo (12-16 ns)
    it is the other way round."""
    from gpr3d.io.volume import read_volume

    d, top = pipe_survey
    maps = {}
    for name, box in (("around", [0, 2e-9, 2499, 12e-9]), ("after", [0, 12e-9, 2499, 16e-9])):
        (tmp_path / f"{name}.json").write_text(json.dumps({"targets": [{"box": box}]}))
        r = run_cli("reconstruct", d / "line.h5", "--poses", d / "walk.tum", "--boxes", tmp_path / f"{name}.json",
                    "--out", tmp_path / name, "--max-depth", "0.7", "--eps-r", "6")
        assert r.returncode == 0, r.stderr
        vol = read_volume(tmp_path / name / "volume.h5")
        y, depth = vol.grid.y, vol.grid.depth
        maps[name] = (vol.arrays["envelope"], vol.arrays["noise_map"])
    j = int(np.argmin(abs(y - 0.6)))
    k = int(np.argmin(abs(depth - top)))
    for name, (inside, outside) in maps.items():
        at_pipe = (inside[:, j, k - 2 : k + 3].max(), outside[:, j, k - 2 : k + 3].max())
        strong, weak = at_pipe if name == "around" else at_pipe[::-1]
        assert weak < 0.2 * strong, (name, at_pipe)
    # the pipe in the noise map when the box misses it: its maximum along y = 0.6 lies at the pipe's depth
    _, outside = maps["after"]
    assert abs(depth[int(np.argmax(outside[:, j, :].max(axis=0)))] - top) < 0.05


@pytest.mark.parametrize("extra, words", [
    (["--eps-r", "-3"], "--eps-r must be a relative permittivity >= 1 or 'file', got '-3'"),
    (["--eps-r", "six"], "--eps-r must be a relative permittivity >= 1 or 'file', got 'six'"),
    (["--spacing", "0"], "--spacing must be positive"),
    (["--boxes", "{box}"], "no 'targets' list"),
    (["--boxes", "{ns_box}"], "box 0 [10, 5, 40, 9] lies outside the data"),
    (["--tile", "0"], "--tile must be a tile side in metres, at least 10 voxels (the data's voxels are 0.02 m or more) "
                      "(0.2..100000), got 0"),
    (["--tile", "0.1", "--spacing", "0.02"], "--tile must be a tile side in metres, at least 10 voxels of --spacing "
                                              "0.02 (0.2..100000), got 0.1"),
    (["--workers", "-2"], "workers must be a whole number >= 0, got -2"),
    (["--scheduler", "localhost:8786"], "scheduler must be an address such as tcp://host:8786"),
    (["--coarse-to-fine", "--refine-level", "0"], "--refine-level must be > 0.0, got 0.0"),
    (["--coarse-to-fine", "--refine-level", "1.5"], "--refine-level must be <= 1.0, got 1.5"),
    (["--no-coarse-to-fine", "--refine-level", "0.4"],
     "--refine-level sets how coarse-to-fine imaging refines: leave --no-coarse-to-fine out"),
])
def test_bad_reconstruct_arguments_are_one_line_errors(pipe_survey, tmp_path, extra, words):
    d, _ = pipe_survey
    (tmp_path / "box.json").write_text(json.dumps({"boxes": [[10, 5e-9, 40, 9e-9]]}))
    (tmp_path / "ns_box.json").write_text(json.dumps([[10, 5, 40, 9]]))
    extra = [e.format(box=tmp_path / "box.json", ns_box=tmp_path / "ns_box.json") for e in extra]
    r = run_cli("reconstruct", d / "line.h5", "--poses", d / "walk.tum", "--out", tmp_path / "o", *extra)
    assert r.returncode == 1 and words in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def test_tiles_resume_and_give_the_volume_of_one_pass(pipe_survey, tmp_path):
    """--tile cuts the grid into tiles migrated from the traces that reach them; --resume keeps them in OUT/tiles
    and a second run reuses them. The volume equals the one-pass volume with every voxel migrated exactly (tiles
    leave coarse-to-fine out, and config.json says so)."""
    import h5py

    d, _ = pipe_survey
    common = ["--poses", d / "walk.tum", "--max-depth", "0.7", "--eps-r", "6"]
    r = run_cli("reconstruct", d / "line.h5", *common, "--out", tmp_path / "one", "--no-coarse-to-fine")
    assert r.returncode == 0, r.stderr
    r = run_cli("reconstruct", d / "line.h5", *common, "--out", tmp_path / "tiled", "--tile", "0.5", "--resume")
    assert r.returncode == 0, r.stderr
    tiles = sorted((tmp_path / "tiled" / "tiles" / "image").glob("*.npz"))
    assert len(tiles) == 9  # 1.4 m x 1.4 m of columns in tiles of 24 columns (0.48 m)
    tiles[0].unlink()
    r = run_cli("reconstruct", d / "line.h5", *common, "--out", tmp_path / "tiled", "--tile", "0.5", "--resume")
    assert r.returncode == 0 and "resumed 8 of 9 tiles" in r.stdout, r.stdout + r.stderr
    assert "coarse-to-fine left out: site tiles migrate every voxel" in r.stdout
    with h5py.File(tmp_path / "one" / "volume.h5") as a, h5py.File(tmp_path / "tiled" / "volume.h5") as b:
        np.testing.assert_array_equal(a["image"][()], b["image"][()])
    one = json.loads((tmp_path / "one" / "targets.json").read_text())
    assert json.loads((tmp_path / "tiled" / "targets.json").read_text()) == one
    doc = json.loads((tmp_path / "tiled" / "config.json").read_text())
    assert doc["config"]["coarse_to_fine"] is True and doc["refine"] == {"skipped": "site tiles migrate every voxel"}


def test_mask_detect_migrates_the_detected_boxes(pipe_survey, tmp_path):
    pytest.importorskip("torchvision")
    import h5py

    d, top = pipe_survey
    out = tmp_path / "o"
    r = run_cli("reconstruct", d / "line.h5", "--poses", d / "walk.tum", "--mask", "detect", "--out", out,
                "--max-depth", "0.7", "--eps-r", "file")
    assert r.returncode == 0, r.stderr
    det = json.loads((out / "detections.json").read_text())
    assert det["n_traces"] == 2500 and det["targets"]
    # the boxes hold the pipe's echo: two-way time to its top at eps_r 6 plus the source delay
    twt = 2 * top / (299792458 / 6**0.5) + 2**0.5 / 800e6
    assert any(t["box"][1] <= twt <= t["box"][3] for t in det["targets"])
    with h5py.File(out / "volume.h5") as f:
        assert "noise_map" in f
    lines = [t for t in json.loads((out / "targets.json").read_text())["targets"] if t["kind"] == "line"]
    assert any(abs(t["depth_m"] - top) < 0.05 for t in lines), lines
    r = run_cli("reconstruct", d / "line.h5", "--mask", "detect", "--boxes", out / "detections.json", "--out", out)
    assert r.returncode == 1 and "not both" in r.stderr


def test_without_eps_r_the_velocity_is_estimated_from_the_data_and_said(pipe_survey, tmp_path):
    pytest.importorskip("torchvision")
    d, top = pipe_survey
    out = tmp_path / "o"
    r = run_cli("reconstruct", d / "line.h5", "--poses", d / "walk.tum", "--out", out, "--max-depth", "0.7",
                "--depth", "net")
    assert r.returncode == 0, r.stderr
    line = [x for x in r.stdout.splitlines() if x.startswith("eps_r ")][0]
    assert "estimated from the data (net" in line and "the file's header says 6" in line
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["eps_r_source"] == "estimated (net)"
    assert cfg["eps_r"] == pytest.approx(float(line.split()[1]), abs=0.006)
    assert 4.0 < cfg["eps_r"] < 9.0  # the truth is 6; a random walk's B-scan bends its hyperbolas


def test_eps_r_file_needs_a_header(pipe_survey, tmp_path):
    d, _ = pipe_survey
    Survey(data=np.zeros((10, 64), np.float32), dt_s=1e-10, positions_xyz=np.zeros((10, 3))).save(tmp_path / "n.h5")
    r = run_cli("reconstruct", tmp_path / "n.h5", "--out", tmp_path / "o", "--eps-r", "file")
    assert r.returncode == 1 and "gives no eps_r" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_timings_name_every_stage_of_reconstruct_and_add_up(pipe_survey, tmp_path):
    """``gpr3d --timings FILE``: the stages in the order they ran, each its own time; with the compilations and
    'other' they add up to the command's time, and the migration's stages agree with the result's own clock."""
    d, _ = pipe_survey
    r = run_cli("--timings", tmp_path / "t.json", "reconstruct", d / "line.h5", "--poses", d / "walk.tum",
                "--out", tmp_path / "out", "--max-depth", "0.7", "--eps-r", "6")
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "t.json").read_text())
    stages = doc["stages"]
    ran = [k for k in stages if k not in ("compile", "other")]
    # (the figures: their views taken and handed to the worker before the volume is written, then waited for)
    assert ran == ["load models", "read", "processing", "poses", "prepare", "grid", "migrate", "fold", "envelope", "targets",
                   "write folder", "figures", "write volume", "write vti"]
    assert doc["command"][:4] == ["gpr3d", "--timings", str(tmp_path / "t.json"), "reconstruct"]
    assert all(v >= 0 for v in stages.values())
    assert sum(stages.values()) == pytest.approx(doc["wall_s"], abs=1e-5 * len(stages))
    assert doc["counts"]["migrate"] == 1 and doc["counts"]["figures"] == 2
    # the migration's own clock (config.json) is read outside each stage's, so it spans the stage (and any
    # compilation inside it): an inequality that holds on any machine (1e-6: the file's rounding)
    own = json.loads((tmp_path / "out" / "config.json").read_text())["timings_s"]
    assert stages["migrate"] + stages.get("compile", 0.0) <= own["migrate"] + 1e-6
    assert 0 < stages["prepare"] <= own["prepare"] + 1e-6
    assert 0 < doc["startup_s"] < 120
    lines = r.stderr.strip().splitlines()
    assert lines[0] == f"gpr3d reconstruct: where the time went ({doc['host_cpu']})"
    assert lines[2].split()[0] == "start-up" and lines[-1].split()[0] == "total"
    assert "migrated 2500 traces" in r.stdout  # the command's own output is unchanged
    # an unwritable timings file: one line, before any work
    r = run_cli("--timings", "/proc/t.json", "reconstruct", d / "line.h5", "--poses", d / "walk.tum",
                "--out", tmp_path / "out2", "--eps-r", "6")
    assert r.returncode == 1 and r.stderr.startswith("gpr3d: error: --timings /proc/t.json: cannot write in /proc")
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "out2").exists()
    r = run_cli("--timings", tmp_path, "reconstruct", d / "line.h5", "--poses", d / "walk.tum",
                "--out", tmp_path / "out3", "--eps-r", "6")
    assert r.returncode == 1 and r.stderr == f"gpr3d: error: --timings {tmp_path}: is a folder; give a file name " \
        "(e.g. timings.json)\n" and not (tmp_path / "out3").exists()


def test_the_grid_ends_where_the_signal_does_and_says_so(tmp_path):
    walk = random_walk(1500, area=((0, 1.0), (0, 1.0)), step_m=0.01, seed=4)
    scene = ForwardScene(eps_r=6.0, pipes=[Pipe((0.1, 0.5, -0.23), (0.9, 0.5, -0.23), 0.03)])
    data = forward_model(scene, walk.positions_xyz, walk.orientations_quat_wxyz, offset_m=0.08, frequency_hz=800e6,
                         n_samples=384, time_window_s=30e-9, air_wave=1.0, ground_wave=0.5, noise=0.02, seed=1)
    Survey(data=data, dt_s=30e-9 / 384, offset_m=0.08, frequency_hz=800e6, eps_r=6.0).save(tmp_path / "s.h5")
    write_tum(walk, tmp_path / "w.tum")
    base = ("reconstruct", tmp_path / "s.h5", "--poses", tmp_path / "w.tum", "--eps-r", "file", "--spacing", "0.04")
    r = run_cli(*base, "--out", tmp_path / "cut", "--signal-depth")
    assert r.returncode == 0, r.stderr
    depth = json.loads((tmp_path / "cut" / "config.json").read_text())["depth"]
    assert depth["how"] == "signal" and depth["depth_m"] < 0.65 * depth["record_m"], depth
    said = [line for line in r.stdout.splitlines() if line.startswith("depth range")]
    assert said == [f"depth range to {depth['depth_m']:.2f} m of the record's {depth['record_m']:.2f} m: "
                    f"{depth['why']} (--signal-depth)"]
    r = run_cli(*base, "--out", tmp_path / "full")  # the default: the whole record
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "full" / "config.json").read_text())
    assert doc["depth"]["how"] == "record" and doc["config"]["signal_depth"] is False
    assert "depth range" not in r.stdout
    cut = json.loads((tmp_path / "cut" / "targets.json").read_text())["targets"]
    full = json.loads((tmp_path / "full" / "targets.json").read_text())["targets"]
    assert [t["kind"] for t in cut] == [t["kind"] for t in full] and "line" in [t["kind"] for t in cut]
    for a, b in zip(cut, full):
        np.testing.assert_allclose(a["points_xyz"], b["points_xyz"], atol=0.021)
