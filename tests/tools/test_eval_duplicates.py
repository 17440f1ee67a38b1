"""benchmarks/eval_duplicates.py: a wrong setting is one line before any work, and each rule does to a record's
refined boxes what it says (the shipped rule through ``soften_duplicates`` itself)."""

import pytest

from tests.tools._script import load_script, refusal


@pytest.mark.parametrize("args, says", [
    (("--ious", "0"), "--ious must be numbers in (0, 1], separated by commas, got '0'"),
    (("--ious", "0.5,1.5"), "--ious must be numbers in (0, 1], separated by commas, got '0.5,1.5'"),
    (("--ious", "half"), "--ious must be numbers in (0, 1], separated by commas, got 'half'"),
    (("--ious", "nan"), "--ious must be numbers in (0, 1], separated by commas, got 'nan'"),
    (("--pgpr", "{tmp}/absent"), "--pgpr {tmp}/absent: no val/ folder in it (P-GPR's validation split)"),
    (("--set", "{tmp}/absent.h5"), "--set {tmp}/absent.h5: no such file"),
    (("--name", "sub/x.md"), "--name sub/x.md: a file name ending in .md (no folder: --out says where)"),
    (("--out", "{tmp}/absent"), "--out {tmp}/absent: not a folder"),
])
def test_a_wrong_setting_is_one_line_naming_it(tmp_path, args, says):
    (tmp_path / "val").mkdir()
    base = ["--pgpr", str(tmp_path)] if "--pgpr" not in args else []
    given = [a.replace("{tmp}", str(tmp_path)) for a in args]
    assert says.replace("{tmp}", str(tmp_path)) in refusal("eval_duplicates.py", *base, *given)


def test_each_rule_on_a_record_s_boxes_by_hand():
    mod = load_script("benchmarks/eval_duplicates.py")
    dt = 1e-10
    # A (0.9); B on A, IoU 9/11; C alone; D on A at IoU 0.6 (A's upper 60 %: the same traces, 0.6 of its time)
    boxes = [[10.0, 1e-9, 20.0, 3e-9], [11.0, 1e-9, 21.0, 3e-9], [40.0, 5e-9, 44.0, 6e-9], [10.0, 1e-9, 20.0, 2.2e-9]]
    result = {"dt_s": dt, "targets": [{"box": b, "score": s, "kind": "rebar"} for b, s in
                                      zip(boxes, [0.9, 0.8, 0.7, 0.6])]}
    assert mod.apply("kept", None, result) is result
    soft = [t["score"] for t in mod.apply("soft", 0.5, result)["targets"]]
    assert soft == pytest.approx([0.9, 0.8 * (1 - 9 / 11), 0.7, 0.6 * (1 - 0.6)], rel=1e-9)
    assert [t["score"] for t in mod.apply("soft", 0.7, result)["targets"]] == pytest.approx(
        [0.9, 0.8 * (1 - 9 / 11), 0.7, 0.6], rel=1e-9)
    removed = mod.apply("removed", 0.5, result)["targets"]
    assert [t["box"] for t in removed] == [boxes[0], boxes[2]] and [t["score"] for t in removed] == [0.9, 0.7]
    assert [t["box"] for t in mod.apply("removed", 0.7, result)["targets"]] == [boxes[0], boxes[2], boxes[3]]
    assert [t["score"] for t in result["targets"]] == [0.9, 0.8, 0.7, 0.6]  # the record's own results untouched
    assert mod.apply("soft", 0.5, {"dt_s": dt, "targets": []})["targets"] == []
    # the stand-in detector gives back what it was given, in order, and the kinds it was told
    rep = mod.Replay(["rebar"], [result, {"targets": []}])
    assert rep.kinds == ["rebar"] and rep.detect(None, score_threshold=0.0) is result
    assert rep.detect(None)["targets"] == []
