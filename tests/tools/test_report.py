"""benchmarks/_report.py: a result table is written with the command that remakes it, quoted for a shell."""

import shlex
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

from _report import write_table  # noqa: E402


def test_the_command_line_keeps_each_argument_whole(tmp_path, capsys):
    argv = ["--rates", "800", "--live-args", "--weights /tmp/a b.onnx --refiner none", "--out", str(tmp_path)]
    path = write_table(tmp_path / "r", "t.md", "| a |\n|---|", "bench_live.py", argv)
    assert path == tmp_path / "r" / "t.md" and capsys.readouterr().out == "| a |\n|---|\n"
    table, command = path.read_text().split("\n\ncommand: ")
    assert table == "| a |\n|---|" and command.endswith("\n")
    assert shlex.split(command) == ["python", "benchmarks/bench_live.py", *argv]
