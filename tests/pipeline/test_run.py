"""gpr3d.pipeline.run_pipeline: the whole road on a random-motion survey, and a re-run that keeps what is done and
valid and remakes what is not."""

import json

import numpy as np
import pytest

from gpr3d.core.errors import GPR3DError
from gpr3d.pipeline.run import RunConfig, run_pipeline
from tests.conftest import pipe_walk_files


@pytest.fixture(scope="module")
def walk_files(tmp_path_factory):
    pytest.importorskip("onnxruntime")
    return pipe_walk_files(tmp_path_factory.mktemp("run"), 700)


def _lines(log):
    return [m for m in log if m.startswith("[")]


@pytest.fixture(scope="module")
def done_run(walk_files, tmp_path_factory):
    d = walk_files
    out = tmp_path_factory.mktemp("done") / "run"
    cfg = RunConfig(input=str(d / "line.h5"), out=str(out), poses=str(d / "walk.tum"), eps_r="file",
                    reconstruct={"spacing_m": 0.03, "max_depth_m": 0.6})
    log = []
    summary = run_pipeline(cfg, log=log.append)
    return cfg, out, summary, log


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_the_whole_road_then_a_rerun_that_keeps_what_is_done(walk_files, done_run, tmp_path, capsys):
    import shutil

    d = walk_files
    cfg0, out0, summary, log = done_run
    out = tmp_path / "run"
    shutil.copytree(out0, out)  # (this test changes the folder; the report's tests read the fixture's)
    cfg = RunConfig(**{**cfg0.__dict__, "out": str(out)})
    stages = [m.split(":")[0] for m in _lines(log)]
    assert stages == ["[1/3] survey", "[2/3] detections", "[3/3] reconstruction"]
    assert not any(v["kept"] for v in summary["stages"].values())
    targets = json.loads((out / "reconstruction" / "targets.json").read_text())["targets"]
    assert summary["targets"] == targets
    assert json.loads((out / "summary.json").read_text()) == json.loads(json.dumps(summary))
    best = max((t for t in targets if t["kind"] == "line"),
               key=lambda t: np.linalg.norm(np.subtract(t["points_xyz"][1], t["points_xyz"][0])))
    p = np.asarray(best["points_xyz"])
    assert np.allclose(p[:, 1], 0.4, atol=0.05) and np.allclose(p[:, 2], 0.30, atol=0.05)  # the pipe, top 0.30 m
    dets = json.loads((out / "detections.json").read_text())
    assert dets["targets"], "the detector found the pipe's hyperbolas"
    # the survey written is the file with the poses given to its traces
    s = __import__("gpr3d").read(out / "survey.h5")
    from gpr3d.io.trajectory import read_tum

    np.testing.assert_allclose(s.positions_xyz, read_tum(d / "walk.tum").positions_xyz)

    # the same line again: nothing is made again
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    log2 = []
    capsys.readouterr()
    again = run_pipeline(cfg, log=log2.append, progress=True)
    assert all(v["kept"] for v in again["stages"].values()), log2
    bar = capsys.readouterr().err  # the bar over the stages, named after the one running
    assert "gpr3d run: survey" in bar and "gpr3d run: reconstruction" in bar and "3/3" in bar, bar
    assert again["targets"] == summary["targets"]
    assert (out / "survey.h5").stat().st_mtime_ns == before["survey.h5"]

    # another score threshold: the survey is kept, detection and what follows it are made again
    log3 = []
    run_pipeline(RunConfig(**{**cfg.__dict__, "score": 0.6}), log=log3.append)
    kept = [("kept" in m) for m in _lines(log3)]
    assert kept == [True, False, False], log3

    # a damaged stage file is found by its hash and made again
    (out / "detections.json").write_text("{}")
    log4 = []
    run_pipeline(RunConfig(**{**cfg.__dict__, "score": 0.6}), log=log4.append)
    assert [("kept" in m) for m in _lines(log4)] == [True, False, False], log4
    assert json.loads((out / "detections.json").read_text())["targets"]


def test_wrong_settings_are_one_line_before_any_work(walk_files, tmp_path):
    d = walk_files
    base = dict(input=str(d / "line.h5"), out=str(tmp_path / "r"))
    for kw, msg in (({"poses": str(d / "walk.tum"), "track": str(d / "walk.tum")}, "give one of --poses, --imu, --track"),
                    ({"odometry": str(d / "walk.tum")}, "give --imu"),
                    ({"trace_spacing_m": -1.0}, "--trace-spacing must be"),
                    ({"score": 2.0}, "--score must lie in 0..1"),
                    ({"depth": "guess"}, "--depth must be"),
                    ({"poses": str(d / "walk.tum"), "trace_spacing_m": 0.01}, "leave it out with --poses"),
                    ({"poses": str(d / "nosuch.tum")}, "nosuch.tum: no such file"),
                    ({"input": str(d / "nosuch.h5")}, "nosuch.h5: no such file")):
        with pytest.raises(GPR3DError, match=msg):
            run_pipeline(RunConfig(**{**base, **kw}))
        assert not (tmp_path / "r").exists()  # refused before the folder is made
    with pytest.raises(GPR3DError, match="holds no trace positions"):
        run_pipeline(RunConfig(**base, eps_r=6.0))


def _page_targets(page: str) -> list:
    import re

    return re.findall(r'<tr data-name="([^"]+)">', page)


def _fetched(page: str) -> list:
    """What a page's tags load from elsewhere (script src, link href, img src); script bodies are not tags."""
    from html.parser import HTMLParser

    got = []

    class P(HTMLParser):
        def handle_starttag(self, tag, attrs):
            a = dict(attrs)
            if (tag in ("script", "img", "iframe") and a.get("src")) or (tag == "link" and a.get("href")):
                got.append((tag, a.get("src") or a.get("href")))

    P().feed(page)
    return got


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_the_report_lists_the_targets_of_targets_json_and_each_section(done_run):
    _, out, summary, _ = done_run
    page = (out / "report.html").read_text()
    names = [t["name"] for t in json.loads((out / "reconstruction" / "targets.json").read_text())["targets"]]
    assert names and _page_targets(page) == names
    for section in ("Targets", "Host permittivity", "B-scan and detections", "Depth slices and noise map", "3D view",
                    "Settings and provenance"):
        assert f"<h2>{section}</h2>" in page, section
    assert 'id="fig-view3d"' in page and 'id="fig-bscan"' in page
    assert _fetched(page) == []  # self-contained: no script, style or image fetched from anywhere
    assert page.count("used for the migration (file header)") == 1


def _browser():
    import shutil

    exe = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None)
    if exe is None:
        pytest.skip("no Chromium here (Debian: apt-get install chromium)")
    sync = pytest.importorskip("playwright.sync_api")
    return exe, sync


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_the_report_opens_in_a_real_browser_draws_its_3d_view_and_names_the_targets(done_run, tmp_path):
    exe, sync = _browser()
    _, out, _, _ = done_run
    names = [t["name"] for t in json.loads((out / "reconstruction" / "targets.json").read_text())["targets"]]
    errors = []
    with sync.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=exe, args=["--no-sandbox", "--use-angle=swiftshader",
                                                                "--enable-unsafe-swiftshader"])
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto((out / "report.html").as_uri())
        page.wait_for_selector("#fig-view3d canvas", timeout=60_000)
        page.wait_for_timeout(1500)
        shown = page.eval_on_selector_all("#targets tbody tr", "rows => rows.map(r => r.cells[0].textContent)")
        view = page.locator("#fig-view3d")
        view.scroll_into_view_if_needed()
        view.screenshot(path=str(tmp_path / "view3d.png"))
        browser.close()
    assert errors == []
    assert shown == names
    from PIL import Image

    img = np.asarray(Image.open(tmp_path / "view3d.png").convert("RGB")).reshape(-1, 3)
    colours = {tuple(c) for c in img[:: max(1, len(img) // 50_000)]}
    assert len(colours) > 50, len(colours)  # a drawn scene, not a blank canvas


def test_the_detections_key_follows_the_shipped_models_files(tmp_path, monkeypatch):
    """With the shipped models (no --weights, --refiner auto, no --depthnet) the detection stage's key holds the
    shipped files' hashes: a gpr3d that ships another refiner, fine stage, detector or DepthNet makes the detections
    again."""
    from gpr3d.detection import refine, weights
    from gpr3d.inversion import depthnet
    from gpr3d.pipeline import run

    cfg = RunConfig(input="x.h5", out=str(tmp_path / "r"))
    before = run._models_key(cfg)
    assert before["refiner"][0] == run._sha(refine.DEFAULT_REFINER)
    for module, name in ((refine, "DEFAULT_REFINER"), (refine, "DEFAULT_FINE_REFINER"),
                         (refine, "DEFAULT_FINE_REFINER_ONNX"), (weights, "DEFAULT_WEIGHTS"),
                         (depthnet, "DEFAULT_DEPTHNET")):
        other = tmp_path / f"{name}.bin"
        other.write_bytes(b"another model")
        with monkeypatch.context() as m:
            m.setattr(module, name, other)
            assert run._models_key(cfg) != before, name
    assert run._models_key(cfg) == before
    mine = tmp_path / "mine.pt"
    mine.write_bytes(b"weights")
    own = run._models_key(RunConfig(input="x.h5", out=str(tmp_path / "r"), weights=str(mine)))
    assert own["weights"] == run._sha(mine) and own["refiner"] == "auto"  # no refiner with other weights
    assert run._models_key(RunConfig(input="x.h5", out=str(tmp_path / "r"), refiner="none"))["refiner"] == "none"


def test_a_figure_worker_draws_the_reconstruction_figures_of_a_run(done_run, tmp_path):
    import shutil

    from gpr3d.viz.worker import FigureWorker

    cfg0, out0, summary, _ = done_run
    out = tmp_path / "run"
    shutil.copytree(out0, out)
    shutil.rmtree(out / "reconstruction")  # the journal's files gone: that stage made again, the others kept
    log = []
    with FigureWorker() as w:
        again = run_pipeline(RunConfig(**{**cfg0.__dict__, "out": str(out)}), log=log.append, figures=w)
        drawn = w.answered
    assert [("kept" in m) for m in _lines(log)] == [True, True, False], log
    assert drawn == (1 if w.enabled else 0)  # the worker drew them (where fork is to be had)
    assert sorted(p.name for p in (out / "reconstruction").iterdir()) == sorted(
        p.name for p in (out0 / "reconstruction").iterdir())
    assert again["targets"] == summary["targets"]


def test_a_stage_stopped_while_it_writes_leaves_a_journal_naming_only_whole_stages(tmp_path, monkeypatch):
    """The journal forgets a stage before its files are written again: a run stopped inside the detection stage,
    after it has replaced detections.json (a kill between the file and the journal), leaves a journal that names
    the survey (whole) and neither the detections nor the reconstruction made from the old ones."""
    from gpr3d.pipeline import report, run

    rec = tmp_path / "line.h5"
    rec.write_bytes(b"a recording")
    out = tmp_path / "run"
    calls = []

    def survey(cfg, out, log):
        calls.append("survey")
        (out / "survey.h5").write_bytes(b"survey")
        return "survey line"

    def detections(cfg, out, log):
        calls.append("detections")
        (out / "detections.json").write_text(json.dumps({"score": cfg.score}))
        if cfg.score == 0.6:
            raise KeyboardInterrupt  # (stopped after the file, before the journal's record)
        return "detections line"

    def reconstruction(cfg, out, log, figures=None):
        calls.append("reconstruction")
        (out / "reconstruction").mkdir(exist_ok=True)
        (out / "reconstruction" / "targets.json").write_text(json.dumps({"targets": [], "score": cfg.score}))
        return "reconstruction line"

    monkeypatch.setattr(run, "_survey_stage", survey)
    monkeypatch.setattr(run, "_detections_stage", detections)
    monkeypatch.setattr(run, "_reconstruction_stage", reconstruction)
    monkeypatch.setattr(report, "write_report", lambda out: out / "report.html")
    cfg = RunConfig(input=str(rec), out=str(out), eps_r=6.0)
    run_pipeline(cfg, log=lambda m: None)
    j = run._Journal(out)
    assert list(j.stages) == ["survey", "detections", "reconstruction"]
    assert all(j.done(s, r["key"]) for s, r in j.stages.items())
    with pytest.raises(KeyboardInterrupt):
        run_pipeline(RunConfig(**{**cfg.__dict__, "score": 0.6}), log=lambda m: None)
    assert calls == ["survey", "detections", "reconstruction", "detections"]  # (the survey kept)
    j = run._Journal(out)
    assert list(j.stages) == ["survey"], j.stages  # (the old detections' record is gone with their file)
    assert j.done("survey", j.stages["survey"]["key"])
    # the next run makes detection and reconstruction again and keeps the survey
    calls.clear()
    run_pipeline(RunConfig(**{**cfg.__dict__, "score": 0.55}), log=lambda m: None)
    assert calls == ["detections", "reconstruction"]
    j = run._Journal(out)
    assert list(j.stages) == ["survey", "detections", "reconstruction"]
    assert all(j.done(s, r["key"]) for s, r in j.stages.items())
    assert json.loads((out / "reconstruction" / "targets.json").read_text())["score"] == 0.55
