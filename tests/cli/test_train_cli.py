"""``gpr3d train detector`` builds the record sources the options ask for, and names them in the weights."""

import pytest

pytest.importorskip("torch")

import gpr3d.detection.train as train_mod  # noqa: E402
import gpr3d.detection.weights as weights_mod  # noqa: E402
from gpr3d.cli.main import build_parser  # noqa: E402


@pytest.fixture
def caught(monkeypatch):
    got = {}

    def fake_train(cfg, source, *, wall_source=None, progress=True, max_seconds=None):
        got.update(cfg=cfg, source=source, wall=wall_source)
        return {"model": "m", "steps": cfg.steps, "wall_s": 1.0, "kinds": None}

    def fake_save(model, name, window, path, kinds=None, provenance=None):
        got.update(provenance=provenance)

    monkeypatch.setattr(train_mod, "train_detector", fake_train)
    monkeypatch.setattr(weights_mod, "save_weights", fake_save)
    return got


def _run(*argv):
    args = build_parser().parse_args(["train", "detector", *argv])
    return args.func(args)


@pytest.mark.parametrize("share", [0.25, 1.0])
def test_a_wall_share_draws_wall_scans_of_the_same_seed(tmp_path, caught, share):
    from gpr3d.simulation.surveys import SurveySource

    assert _run("--out", str(tmp_path / "t"), "--steps", "3", "--data-seed", "41", "--wall-fraction", str(share)) == 0
    assert caught["cfg"].wall_fraction == share
    src, wall = caught["source"], caught["wall"]
    assert isinstance(src, SurveySource) and (src.seed, src.profile) == (41, "train")
    assert isinstance(wall, SurveySource) and (wall.seed, wall.profile) == (41, "wall")
    assert caught["provenance"]["data"] == f"survey_sample(seed=41, i) ({share:.0%} of them profile='wall')"
    assert caught["provenance"]["config"]["wall_fraction"] == share


def test_no_wall_share_no_wall_source(tmp_path, caught):
    assert _run("--out", str(tmp_path / "t"), "--steps", "3") == 0
    assert caught["cfg"].wall_fraction == 0.0 and caught["wall"] is None
    assert caught["provenance"]["data"] == "survey_sample(seed=1000, i)"
