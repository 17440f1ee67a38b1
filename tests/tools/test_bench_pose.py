"""benchmarks/bench_pose.py refuses a wrong setting in one line, before it simulates or fuses anything."""

import pytest

from tests.tools._script import refusal


@pytest.mark.parametrize("args, says", [
    (("--repeat", "0"), "--repeat must be 1 or more, got 0"),
    (("--seconds", "5"), "--seconds must lie in 10..3600, got 5"),
    (("--seconds", "nan"), "--seconds must lie in 10..3600, got nan"),
    (("--out", "{file}"), "not a folder"),
    (("--out", "{file}/sub"), "/f/sub: Not a directory"),  # (a folder under a file: on any POSIX system)
])
def test_a_wrong_setting_is_one_line_naming_it(tmp_path, args, says):
    (tmp_path / "f").write_text("")
    assert says in refusal("bench_pose.py", *(a.replace("{file}", str(tmp_path / "f")) for a in args))
