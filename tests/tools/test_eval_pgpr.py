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


def test_an_ensemble_member_it_cannot_load_is_one_line_before_any_detection(tmp_path):
    import numpy as np
    from PIL import Image

    for sub in ("images", "labels"):
        (tmp_path / "val" / sub).mkdir(parents=True)
    Image.fromarray(np.full((256, 40), 128, np.uint8)).save(tmp_path / "val" / "images" / "AIR_0001.png")
    (tmp_path / "val" / "labels" / "AIR_0001.txt").write_text("0 0.5 0.5 0.2 0.2\n")
    last = refusal("eval_pgpr.py", "default", "--pgpr", str(tmp_path), "--members", str(tmp_path / "nope.pt"),
                   "--out", str(tmp_path / "out"))
    assert last.endswith("--members: nope.pt: no such detector weights file"), last
    assert not (tmp_path / "out").exists()
