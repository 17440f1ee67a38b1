"""benchmarks/gprmax_misses.py: its groups' figures from hand-made rows, and wrong settings in one line."""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))
import gprmax_misses as G  # noqa: E402

from tests.tools._script import refusal  # noqa: E402


def _row(**kw):
    r = {"record": 0, "kind": "rebar", "found": False, "iou": 0.0, "score": 0.0, "apex_off": None, "masked": False,
         "cut": False, "contrast": 1.0}
    r.update(kw)
    return r


def test_a_group_s_line_counts_what_the_columns_say():
    rows = [_row(found=True, iou=0.9, score=0.95, apex_off=False), _row(iou=0.6, score=0.3, apex_off=True),
            _row(iou=0.8, score=0.7, apex_off=True), _row(iou=0.2)]
    # 4 targets: 1 apex found; 3 at IoU >= 0.5, 2 at >= 0.75; 2 sure (0.95, 0.7), one of them with its apex off;
    # median score of (0.95, 0.3, 0.7, 0) = 0.5
    assert G.group_line("g", rows, 0.5) == "| g | 4 | 0.25 | 0.75 | 0.50 | 0.50 | 0.50 | 0.50 |"
    assert G.group_line("none", [], 0.5) == "| none | 0 | - | - | - | - | - | - |"
    assert G.group_line("unsure", [_row(iou=0.6, score=0.2, apex_off=False)], 0.5).endswith("| 0.00 | - | 0.20 |")


def test_the_table_splits_by_kind_echo_cut_and_contrast():
    rows = [_row(kind="void", masked=True, contrast=1.0), _row(kind="void", cut=True, contrast=2.0, iou=0.8,
            score=0.9, apex_off=True), _row(kind="pvc_pipe", contrast=3.0), _row(contrast=4.0, found=True, iou=0.9,
            score=0.9, apex_off=False), _row(kind="tank", contrast=5.0)]
    lines = G.table(rows, 0.5)
    byname = {line.split(" | ")[0][2:]: line for line in lines[2:]}
    assert byname["void"].startswith("| void | 2 |") and byname["rebar"].startswith("| rebar | 1 | 1.00 |")
    assert byname["under a stronger echo"].startswith("| under a stronger echo | 1 |")
    assert byname["void, isolated"].startswith("| void, isolated | 1 |")
    assert byname["cut by the record's first or last trace"] == \
        "| cut by the record's first or last trace | 1 | 0.00 | 1.00 | 1.00 | 1.00 | 1.00 | 0.90 |"
    bands = [line for line in lines if line.startswith("| contrast")]
    assert len(bands) == 5 and bands[0].startswith("| contrast 1.0-1.8 | 1 |")


@pytest.mark.parametrize("args, says", [
    (("--score", "0"), "--score must lie in (0, 1], got 0.0"),
    (("--set", "/no/such.h5"), "--set /no/such.h5: no such file"),
    (("--refiner", "/no/r.pt"), "--refiner /no/r.pt: no such file (or default, none)"),
    (("--detector", "/no/d.pt"), "--detector /no/d.pt: no such file (or default)"),
    (("--out", "/no/such/folder"), "--out /no/such/folder: not a folder"),
    (("--threads", "0"), "--threads must lie in 1..256, got 0"),
    (("--name", "../x.md"), "--name ../x.md: a file name ending in .md (no folder: --out says where)"),
    (("--name", "table.txt"), "--name table.txt: a file name ending in .md (no folder: --out says where)"),
])
def test_a_wrong_setting_is_one_line_naming_it(args, says):
    assert refusal("gprmax_misses.py", *args).endswith(says)


@pytest.mark.parametrize("option", ["--detector", "--refiner"])
def test_a_file_that_is_not_weights_is_one_line_naming_it(option):
    pytest.importorskip("torch")
    says = refusal("gprmax_misses.py", option, str(ROOT / "README.md"), "--out", str(ROOT / "benchmarks" / "results"))
    assert "README.md: not a readable weights file" in says
