"""benchmarks/eval_refiner_fine.py: a wrong setting is one line before any work, and the network sees each record
once however many fine stages refine its boxes."""

import pytest

from tests.tools._script import load_script, refusal


@pytest.mark.parametrize("args, says", [
    (("--fine", "{tmp}/absent.pt"), "--fine {tmp}/absent.pt: neither none, default nor an existing file"),
    (("--fine", "none", "none"), "--fine none none: each fine stage once"),
    (("--refiner", "{tmp}/absent.pt"), "--refiner {tmp}/absent.pt: no such file"),
    (("--pgpr", "{tmp}/absent"), "--pgpr {tmp}/absent: no val/ folder in it (P-GPR's validation split)"),
    (("--set", "{tmp}/absent.h5"), "--set {tmp}/absent.h5: no such file"),
    (("--name", "sub/x.md"), "--name sub/x.md: a file name ending in .md (no folder: --out says where)"),
    (("--name", "x.txt"), "--name x.txt: a file name ending in .md (no folder: --out says where)"),
    (("--out", "{tmp}/absent"), "--out {tmp}/absent: not a folder"),
    (("--fine", "{tmp}/junk.pt"), "junk.pt: not a readable weights file"),
])
def test_a_wrong_setting_is_one_line_naming_it(tmp_path, args, says):
    (tmp_path / "val").mkdir()
    (tmp_path / "junk.pt").write_bytes(b"junk")
    base = ["--pgpr", str(tmp_path)] if "--pgpr" not in args else []
    given = [a.replace("{tmp}", str(tmp_path)) for a in args]
    assert says.replace("{tmp}", str(tmp_path)) in refusal("eval_refiner_fine.py", *base, *given)


def test_the_network_sees_each_record_once_whatever_refines_its_boxes_after():
    mod = load_script("benchmarks/eval_refiner_fine.py")
    calls = []

    class Det:
        def _views(self, survey):
            calls.append(survey)
            return ("views of", survey)

    det = mod.network_once(Det())
    a, b = object(), object()
    assert det._views(a) == ("views of", a) and det._views(b) == ("views of", b)
    assert det._views(a) == ("views of", a) and det._views(b)[1] is b
    assert calls == [a, b]
