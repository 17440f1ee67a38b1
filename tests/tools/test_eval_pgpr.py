"""benchmarks/eval_pgpr.py names a P-GPR folder it cannot read in one line, before it loads a detector."""

import pytest

from tests.tools._script import refusal


@pytest.mark.parametrize("make, args, says", [
    ((), ("--pgpr", "{tmp}/absent"), "--pgpr {tmp}/absent: no val/ folder in it (P-GPR's train/ and val/)"),
    (("val",), ("--pgpr", "{tmp}", "--split", "val,test"), "--pgpr {tmp}: no test/ folder in it"),
    (("val",), ("--pgpr", "{tmp}"), "val: not a YOLO dataset: no data.yaml and no images/ folder"),
])
def test_a_p_gpr_folder_it_cannot_read_is_one_line(tmp_path, make, args, says):
    for part in make:
        (tmp_path / part).mkdir()
    last = refusal("eval_pgpr.py", "default", *(a.replace("{tmp}", str(tmp_path)) for a in args))
    assert says.replace("{tmp}", str(tmp_path)) in last
