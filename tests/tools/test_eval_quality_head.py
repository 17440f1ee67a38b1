"""benchmarks/eval_quality_head.py and the evaluations' --quality-weights: a wrong argument, a refiner file that is
not there or has no quality head, are one line each, before any detection."""

import pytest

from tests.tools._script import refusal


@pytest.mark.parametrize("args, line", [
    (["--score", "2"], "--score must lie in 0..1, got 2.0"),
    (["--refiner", "{tmp}/nowhere.pt"], "--refiner {tmp}/nowhere.pt: no such file"),
    (["--sets", "gprmax_survey", "--gprmax-survey", "{tmp}/none.h5"], "--gprmax-survey {tmp}/none.h5: no such file"),
    (["--sets", "pgpr", "--pgpr", "{tmp}"], "--pgpr {tmp}: no val/ folder in it"),
])
def test_wrong_arguments_are_one_line(tmp_path, args, line):
    got = refusal("eval_quality_head.py", *(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert got == "eval_quality_head.py: error: " + line.replace("{tmp}", str(tmp_path))


def test_a_refiner_without_a_quality_head_is_one_line(tmp_path):
    pytest.importorskip("torch")
    from gpr3d.detection.refine import build_refiner, save_refiner

    plain = tmp_path / "plain.pt"
    save_refiner(build_refiner(), plain, provenance={"name": "plain"})
    got = refusal("eval_quality_head.py", "--refiner", str(plain), "--sets", "gprmax_survey", timeout=300)
    assert got == f"eval_quality_head.py: error: --refiner {plain}: it has no quality head"


@pytest.mark.parametrize("weight, says", [("x", "--quality-weights: 'x' is neither own nor a number in 0..8"),
                                          ("9", "--quality-weights: '9' is neither own nor a number in 0..8")])
def test_a_quality_weight_that_is_not_one_is_one_line(weight, says):
    pytest.importorskip("torch")
    got = refusal("eval_detector.py", "default", "--refiner", "default", "--quality-weights", weight, timeout=300)
    assert got == f"eval_detector.py: error: {says}"
