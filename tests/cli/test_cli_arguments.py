"""Every argument checked where it enters (issue 12): a wrong value gets one line on stderr naming it, before any
work, and leaves no output behind; hostile arguments never give a traceback or a hang."""

import signal
import warnings
from contextlib import contextmanager

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpr3d import Survey
from gpr3d.cli.main import main
from gpr3d.io.trajectory import read_tum, write_tum
from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model
from gpr3d.simulation.paths import random_walk
from tests.conftest import REAL

DZT = "src/gpr3d/data/FILE____032.DZT"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A small random-walk survey with poses (h5), its TUM file, a TUM running backwards, one too short, an empty
    boxes file, a plain file, and a DT1 without its HD."""
    d = tmp_path_factory.mktemp("args")
    walk = random_walk(400, area=((0, 0.6), (0, 0.6)), step_m=0.01, seed=1)
    scene = ForwardScene(eps_r=6.0, pipes=[Pipe((0.1, 0.3, -0.23), (0.5, 0.3, -0.23), 0.03)])
    data = forward_model(scene, walk.positions_xyz, walk.orientations_quat_wxyz, offset_m=0.05, frequency_hz=1e9,
                         n_samples=128, time_window_s=8e-9, air_wave=1.0, ground_wave=0.5)
    Survey(data=data, dt_s=8e-9 / 128, positions_xyz=walk.positions_xyz,
           orientations_quat_wxyz=walk.orientations_quat_wxyz, offset_m=0.05, frequency_hz=1e9,
           eps_r=6.0).save(d / "walk.h5")
    Survey(data=data, dt_s=8e-9 / 128, offset_m=0.05, frequency_hz=1e9, eps_r=6.0).save(d / "noposes.h5")
    write_tum(walk, d / "walk.tum")
    lines = (d / "walk.tum").read_text().splitlines()
    (d / "short.tum").write_text("\n".join(lines[:51]) + "\n")  # the header and 50 poses
    lines[6], lines[7] = lines[7], lines[6]  # two poses swapped: time runs backwards once
    (d / "back.tum").write_text("\n".join(lines) + "\n")
    (d / "empty_boxes.json").write_text("[]")
    (d / "plain.txt").write_text("not a folder")
    dt1 = REAL / "gpro_sns_100MHz_grid" / "XLINE15.DT1"
    if dt1.exists():  # (without the real data folder only that case is skipped)
        (d / "LINE.DT1").write_bytes(dt1.read_bytes())
    return d


def one_line_error(capsys, argv, *needles):
    """Run the CLI; it must fail with exit code 1 and one stderr line holding every needle."""
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert rc == 1, (argv, err)
    assert len(err.strip().splitlines()) == 1 and err.startswith("gpr3d: error: "), err
    assert "Traceback" not in err
    for n in needles:
        assert n in err, (n, err)
    return err


@pytest.mark.parametrize("argv, needles", [
    (["show", DZT, "--out", "{d}/a.png", "--axis", "depth", "--eps-r", "0.5"], ["eps_r", "0.5"]),
    (["show", DZT, "--out", "{d}/a.png", "--clip", "150"], ["--clip", "(0, 100]"]),
    (["show", DZT, "--out", "{d}/a.png", "--clip", "0"], ["--clip"]),
    (["show", DZT, "--out", "{d}/a.png", "--cmap", "notacmap"], ["--cmap", "notacmap"]),
    (["show", DZT, "--out", "{d}/a.txt"], ["--out", ".png"]),
    (["process", DZT, "--out", "{d}/p.h5", "--steps", "gain_tpow:power=abc"], ["gain_tpow: power", "'abc'"]),
    (["process", DZT, "--out", "{d}/p.h5", "--steps", "remove_dc:sample_range=5"], ["remove_dc: sample_range"]),
    (["process", DZT, "--out", "{d}/p.h5", "--steps", "remove_dc:sample_range=[10,5]"], ["start < stop"]),
    (["process", DZT, "--out", "{d}/p.h5", "--steps", "dewow:window_s=1"], ["dewow: window_s", "record"]),
    (["process", DZT, "--out", "{d}/p.h5", "--steps", "bandpass:order=0"], ["bandpass: order", "1 to 10"]),
    (["process", DZT, "--out", "{d}/p.h5", "--steps", "gain_agc:window_s=0"], ["gain_agc: window_s"]),
    (["process", DZT, "--out", "{d}/p.h5", "--steps", "gain_tpow:t_ref_s=0"], ["gain_tpow: t_ref_s", "positive"]),
    (["process", DZT, "--out", "{d}/p.h5", "--steps", "time_zero:shift=maybe"], ["time_zero: shift", "true or false"]),
    (["process", DZT, "--out", "{d}/p.h5", "--steps", "remove_background:method=mode"], ["'mean' or 'median'"]),
    (["process", DZT, "--out", "{d}/p.h5", "--steps", "remove_background:window_traces=1"], ["window_traces", ">= 2"]),
    (["simulate", "--engine", "forward", "--n", "1", "--workers", "-2", "--out", "{d}/sim"], ["--workers", "-2"]),
    (["simulate", "--engine", "forward", "--n", "1", "--workers", "0", "--out", "{d}/sim"], ["--workers", ">= 1"]),
    (["simulate", "--engine", "forward", "--n", "1", "--scheduler", "notaurl", "--out", "{d}/sim"], ["--scheduler"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--threshold", "5"], ["--threshold", "<= 1"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--threshold", "-1"], ["--threshold", "> 0"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--aperture", "200"], ["--aperture", "< 90"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--aperture", "-5"], ["--aperture"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--aperture-radius", "-1"],
     ["--aperture-radius must be positive, got -1.0"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--aperture-radius", "1", "--method", "pseudo3d"],
     ["--method must be 'backprojection' for an aperture radius (--aperture-radius;"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--min-line", "-1"], ["--min-line", ">= 0"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--max-depth", "-1"], ["--max-depth"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--spacing", "0.00002"], ["GiB", "--spacing"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--boxes", "{d}/empty_boxes.json"],
     ["empty_boxes.json lists no boxes"]),
    (["reconstruct", "{d}/noposes.h5", "--eps-r", "6", "--out", "{d}/r", "--poses", "{d}/back.tum"],
     ["back.tum", "backwards"]),
    (["reconstruct", "{d}/noposes.h5", "--eps-r", "6", "--out", "{d}/r", "--poses", "{d}/short.tum"],
     ["short.tum", "noposes.h5", "50 poses", "400 traces"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/plain.txt"], ["--out", "is a file"]),
    (["dataset", "preview", "{d}", "{d}/x.txt"], ["x.txt", ".png"]),
    (["migrate", DZT, "--out", "{d}/m"], ["--eps-r or --velocity"]),
    (["migrate", DZT, "--out", "{d}/m", "--velocity", "5"], ["--velocity", "0.2998"]),
    (["migrate", DZT, "--out", "{d}/m", "--eps-r", "6", "--max-depth", "-2"], ["--max-depth"]),
    (["migrate", DZT, "--out", "{d}/m", "--eps-r", "6", "--air-gap", "-0.1"], ["--air-gap", ">= 0"]),
    (["migrate", DZT, "--out", "{d}/m", "--eps-r", "6", "--air-gap", "0.3", "--method", "stolt"],
     ["--air-gap", "kirchhoff"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--air-gap", "nan"], ["--air-gap", "finite"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--air-gap", "-1"], ["--air-gap", ">= 0"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--signal-depth", "--max-depth", "1"],
     ["give --max-depth or --signal-depth, not both"]),
    (["run", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/run", "--signal-depth", "--max-depth", "1"],
     ["give --max-depth or --signal-depth, not both"]),
    (["show", DZT, "--out", "{d}/a.png", "--ascan", "99999"], ["--ascan", "0..1039"]),
    (["convert", DZT, "{d}/c.h5", "--marks-every", "-1"], ["--marks-every", "positive"]),
    (["convert", DZT, "{d}/c.h5", "--marks", "0,5"], ["--marks needs --marks-every"]),
    (["convert", DZT, "{d}/c.h5", "--marks-every", "1", "--marks", "a,b"], ["--marks", "whole numbers"]),
    (["convert", DZT, "{d}/c.h5", "--marks-every", "1", "--marks", "9,3"], ["marks", "increasing"]),
    (["convert", DZT, "{d}/c.h5", "--marks-every", "1", "--track", "{d}/t.xyz"], ["--track or --marks-every"]),
    # issue 31: values that once started hours of work, filled memory, or won silently
    (["train", "detector", "--out", "{d}/t", "--steps", "0"], ["--steps must be a number of optimiser steps (1..1e+07)"]),
    (["train", "detector", "--out", "{d}/t", "--batch", "0"], ["--batch must be a number of windows per step (1..4096)"]),
    (["train", "depthnet", "--out", "{d}/t", "--steps", "-5"], ["--steps", "got -5"]),
    (["train", "detector", "--out", "{d}/t", "--lr", "nan"], ["--lr must be a positive learning rate"]),
    (["train", "detector", "--out", "{d}/t", "--labels-fraction", "1.5"], ["--labels-fraction must lie in 0..1"]),
    (["pose", "simulate", "--out", "{d}/ps", "--duration", "1e9"], ["--duration must be seconds of motion (20..3600)"]),
    (["pose", "simulate", "--out", "{d}/ps", "--duration", "nan"], ["--duration", "got nan"]),
    (["pose", "fuse", "--imu", "{d}/walk.tum", "--at", "{d}/noposes.h5", "--out", "{d}/f.tum"],
     ["--at", "noposes.h5", "its traces have no times"]),
    (["cscan", "{d}/walk.h5", "--out", "{d}/c", "--fill", "-1"], ["--fill must be a distance in metres, 0 to 20 cells"]),
    (["cscan", "{d}/walk.h5", "--out", "{d}/c", "--fill", "1e9"], ["--fill", "got 1e+09"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "{d}/r", "--tile", "0.0001"],
     ["--tile must be a tile side in metres, at least 10 voxels (the data's voxels are 0.02 m or more) (0.2..100000), "
      "got 0.0001"]),
    (["process", DZT, "--out", "{d}/p.h5", "--steps", "gain_tpow:power=1:power=2"], ["'power' given twice"]),
    (["reconstruct", "{d}/walk.h5", "--eps-r", "6", "--out", "/sys/gpr3d_x"], ["--out /sys/gpr3d_x: cannot write in /sys"]),
    (["detect", DZT, "--out", "/sys/gpr3d_x/d.json"], ["--out /sys/gpr3d_x/d.json: cannot write in /sys"]),
    (["process", DZT, "--out", "/sys/gpr3d_x/p.h5", "--steps", "dewow"], ["--out /sys/gpr3d_x/p.h5: cannot write"]),
    (["convert", DZT, "{d}/c.txt"], ["output ", "c.txt: expected a .h5 or .hdf5 or .sgy or .segy or .png file"]),
    (["train", "detector", "--out", "/sys/gpr3d_t"], ["--out /sys/gpr3d_t: cannot write in /sys"]),
    (["simulate", "--engine", "forward", "--n", "1", "--out", "/sys/gpr3d_s"], ["--out /sys/gpr3d_s: cannot write"]),
    (["depth", DZT, "--out", "{d}/d.txt"], ["--out", "d.txt: expected a .json file"]),
    (["detect", DZT, "--out", "{d}/d.json", "--refiner", "{d}/none.pt"], ["none.pt", "no such box refiner weights file"]),
    (["detect", DZT, "--out", "{d}/d.json", "--refiner", "{d}/none.onnx"], ["none.onnx", "no such ONNX refiner file"]),
    (["run", DZT, "--out", "{d}/run", "--refiner", "{d}/none.pt"], ["--refiner", "none.pt: no such file"]),
    (["live", "tcp://127.0.0.1:1", "--out", "{d}/live", "--refiner", "{d}/none.onnx"],
     ["none.onnx", "no such ONNX refiner file"]),
])
def test_a_wrong_argument_is_one_line_naming_it_and_leaves_nothing(files, capsys, argv, needles):
    """Each case the issue lists (tracebacks, a hang, wrong results with no error, unhelpful messages)."""
    argv = [a.format(d=files) for a in argv]
    before = {p.name for p in files.iterdir()}
    one_line_error(capsys, argv, *needles)
    assert {p.name for p in files.iterdir()} == before  # no output, partial or not


def test_a_dt1_without_its_header_names_the_missing_file(files, capsys):
    if not (files / "LINE.DT1").exists():
        pytest.skip("../shared/data/real is absent")
    one_line_error(capsys, ["info", files / "LINE.DT1"], "LINE.HD", "missing")


def test_step_arguments_mean_what_they_say(files):
    """``shift=no`` is false (it used to be taken as true), ``[start, stop]`` parses, the history records the values
    used."""
    s = Survey.load(files / "walk.h5")
    kept = s.apply("time_zero", method="peak", shift="no")
    assert kept.n_samples == s.n_samples and kept.t0_s > 0 and kept.history[-1]["args"]["shift"] is False
    cut = s.apply("time_zero", method="peak", shift="yes")
    assert cut.n_samples < s.n_samples and cut.t0_s == 0
    from gpr3d.processing.steps import parse_step

    name, kw = parse_step("remove_dc:sample_range=[0,10]")
    out = s.apply(name, **kw)
    np.testing.assert_allclose(out.data[:, :10].mean(axis=1), 0, atol=1e-5)
    assert out.history[-1]["args"]["sample_range"] == [0, 10]


def test_a_backwards_trajectory_is_refused_by_the_reader(files):
    from gpr3d.core.errors import FormatError

    assert len(read_tum(files / "walk.tum")) == 400
    with pytest.raises(FormatError, match="timestamps run backwards at pose 6"):
        read_tum(files / "back.tum")


def test_one_straight_profile_in_3d_warns(files):
    """Targets beside a single straight line come out mirrored on both sides of it: say so."""
    from gpr3d.core.errors import GeometryWarning
    from gpr3d.migration.reconstruct import ReconstructConfig, cross_line_extent, reconstruct

    s = Survey.load(files / "walk.h5")
    line = s.replace(positions_xyz=np.c_[np.linspace(0, 1, s.n_traces), np.zeros(s.n_traces), np.zeros(s.n_traces)])
    assert cross_line_extent(line.positions_xyz) == pytest.approx(0.0, abs=1e-9)
    assert cross_line_extent(s.positions_xyz) > 0.3
    # the warning comes before the migration: raised as an error, it stops the run there (the 2D profile's image is
    # tested in tests/migration)
    with warnings.catch_warnings():
        warnings.simplefilter("error", GeometryWarning)
        with pytest.raises(GeometryWarning, match="one straight profile"):
            reconstruct(line, ReconstructConfig(eps_r=6.0, spacing_m=0.04, max_depth_m=0.3))


def test_the_memory_estimate_refuses_before_allocating():
    from gpr3d.core.errors import InvalidDataError
    from gpr3d.core.grid import Grid3D
    from gpr3d.migration.reconstruct import BYTES_PER_VOXEL, check_grid_fits

    g = Grid3D(0, 0, 0, 0.01, 0.01, 0.01, 100, 100, 100)  # 1 M voxels
    check_grid_fits(g, available_bytes=10 * g.size * BYTES_PER_VOXEL)
    with pytest.raises(InvalidDataError, match=r"100 x 100 x 100 voxels .* about 0.0 GiB"):
        check_grid_fits(g, available_bytes=g.size * BYTES_PER_VOXEL)


@contextmanager
def time_limit(seconds):
    def stop(signum, frame):
        raise TimeoutError(f"the CLI ran past {seconds} s")

    old = signal.signal(signal.SIGALRM, stop)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


_hostile = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers(-10**9, 10**9).map(str),
                     st.sampled_from(["", "abc", "-0", "nan", "inf", "1e400", "[0,10]", "true", "none", "0x10",
                                      "--", "-1", "0", "1e-30", "☃"]))
_SHOW = {"--clip": _hostile, "--cmap": st.sampled_from(["gray", "hot", "notacmap", "", "jet_r"]) | _hostile,
         "--axis": st.sampled_from(["time", "depth", "width"]), "--eps-r": _hostile, "--marks-every": _hostile,
         "--marks": st.sampled_from(["0,100", "100,0", "", "0", "5,99999"]) | _hostile}
_STEPS = st.sampled_from(["dewow:window_s", "gain_tpow:power", "gain_tpow:t_ref_s", "gain_agc:window_s",
                          "bandpass:order", "bandpass:fmin_hz", "remove_dc:sample_range", "time_zero:threshold",
                          "time_zero:shift", "time_zero:search_s", "remove_background:window_traces",
                          "gain_sec:alpha_per_s", "resample_spacing:spacing_m", "topo_correct:eps_r",
                          "topo_correct:velocity_m_s"])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_hostile_arguments_never_crash_or_hang(files, capsys, data, tmp_path_factory):
    """Random and hostile values for show's options and processing-step arguments: exit 0, or 1 with one stderr
    line naming the problem; never a traceback, never past 60 s, no output file after a failure."""
    out_dir = tmp_path_factory.mktemp("prop")
    if data.draw(st.booleans()):
        out = out_dir / "x.png"
        argv = ["show", DZT, "--out", str(out)]
        for flag, strat in _SHOW.items():
            if data.draw(st.booleans()):
                argv += [flag, data.draw(strat)]
    else:
        out = out_dir / "x.h5"
        steps = [f"{data.draw(_STEPS)}={data.draw(_hostile)}" for _ in range(data.draw(st.integers(1, 3)))]
        argv = ["process", DZT, "--out", str(out), "--steps", *steps]
    with time_limit(60):
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse: a value its type cannot take (its usage line, exit code 2)
            rc = exc.code
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert rc in (0, 1, 2), (argv, rc, err)
    if rc == 1:
        lines = [ln for ln in err.strip().splitlines() if not ln.startswith("gpr3d: warning:")]
        assert len(lines) == 1 and lines[0].startswith("gpr3d: error: "), (argv, err)
    if rc != 0:
        assert not out.exists(), argv


def test_migrate_a_profile_and_draw_wiggles_and_an_ascan(tmp_path, capsys):
    """gpr3d migrate writes the migrated profile (HDF5 + figure); show draws wiggles and one A-scan."""
    import h5py

    assert main(["migrate", DZT, "--eps-r", "6", "--max-depth", "2", "--steps", "time_zero", "dewow",
                 "remove_background", "--out", str(tmp_path / "m")]) == 0
    with h5py.File(tmp_path / "m" / "profile.h5") as f:
        assert f.attrs["method"] == "kirchhoff" and f.attrs["eps_r"] == 6.0
        assert f["image"].shape == (f["along_m"].shape[0], f["depth_m"].shape[0])
        assert f["depth_m"][-1] <= 2.0 + 1e-9 and np.isfinite(f["image"][()]).all()
    assert (tmp_path / "m" / "profile.png").stat().st_size > 10_000
    for extra, name in ((["--style", "wiggle"], "w.png"), (["--ascan", "500"], "a.png"),
                        (["--envelope", "--axis", "depth", "--cmap", "hot"], "e.png")):
        assert main(["show", DZT, "--out", str(tmp_path / name), *extra]) == 0
        assert (tmp_path / name).stat().st_size > 5_000
    capsys.readouterr()


@pytest.mark.parametrize("argv, message", [
    (["detect", "x.DZT", "--out", "d.json", "--runtime", "nosuch"],
     "gpr3d detect: error: argument --runtime: invalid choice: 'nosuch' (choose from 'auto', 'torch', 'onnx', 'int8') "
     "(usage: gpr3d detect --help)"),
    (["simulate", "--seed", "abc", "--out", "s"],
     "gpr3d simulate: error: argument --seed: invalid int value: 'abc' (usage: gpr3d simulate --help)"),
    (["dataset", "nosuch", "a", "b"], "gpr3d dataset: error: argument action: invalid choice: 'nosuch'"),
    (["grid"], "gpr3d grid: error: the following arguments are required: lines, --out (usage: gpr3d grid --help)"),
    (["nosuch"], "gpr3d: error: argument COMMAND: invalid choice: 'nosuch'"),
])
def test_argparse_errors_are_one_line_without_the_usage(capsys, argv, message):
    # issue 31: 4-11 lines of usage came before the one line that mattered
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(message), err
