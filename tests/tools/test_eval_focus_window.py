"""benchmarks/eval_focus_window.py: wrong arguments and a damaged demo folder are one line each, before any work."""

import pytest

from tests.tools._script import refusal


@pytest.mark.parametrize("args, line", [
    (["--eps", "-3"], "--eps must be relative permittivities in 1..80, got [-3.0]"),
    (["--eps", "nan"], "--eps must be relative permittivities in 1..80, got [nan]"),
    (["--spacings", "0"], "--spacings must be cell sizes in 0.005..0.2 m, got [0.0]"),
    (["--seeds", "-1"], "--seeds must be whole numbers >= 0, got [-1]"),
])
def test_wrong_arguments_are_one_line(args, line):
    assert refusal("eval_focus_window.py", *args) == f"eval_focus_window.py: error: {line}"


def test_a_missing_or_damaged_demo_folder_is_one_line(tmp_path):
    assert refusal("eval_focus_window.py", "--demo", str(tmp_path)).endswith(
        f"{tmp_path / 'random_walk_survey.h5'} is missing: run `gpr3d demo --out {tmp_path}` with the dl extra first")
    (tmp_path / "random_walk_survey.h5").write_bytes(b"")
    (tmp_path / "detections.json").write_text('{"targets": [{"box": [1, 2]}, {"nobox": 0}]}')
    assert refusal("eval_focus_window.py", "--demo", str(tmp_path)) == (
        f"eval_focus_window.py: error: {tmp_path / 'detections.json'} is not a gpr3d detect output (KeyError: 'box')")
    (tmp_path / "detections.json").write_text("{truncated")
    assert "is not a gpr3d detect output (JSONDecodeError" in refusal("eval_focus_window.py", "--demo", str(tmp_path))
