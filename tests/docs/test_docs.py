"""The documentation: the Sphinx site builds with every warning an error (nitpicky: every cross-reference
resolves), and every command the user guide shows parses with the real CLI."""

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[2] / "docs"


def _guide_commands():
    text = (DOCS / "guide.md").read_text(encoding="utf-8")
    out = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        for cmd in block.replace("\\\n", " ").splitlines():
            cmd = cmd.split("  #")[0].strip()
            if cmd.startswith("gpr3d "):
                out.append(cmd)
    return out


def test_the_guide_shows_commands():
    cmds = _guide_commands()
    assert len(cmds) > 25
    assert {c.split()[1] for c in cmds} >= {"info", "show", "process", "migrate", "grid", "cscan", "reconstruct",
                                           "pose", "detect", "depth", "convert", "simulate", "dataset"}


@pytest.mark.parametrize("cmd", _guide_commands())
def test_every_guide_command_parses(cmd):
    from gpr3d.cli.main import build_parser

    try:
        build_parser().parse_args(shlex.split(cmd)[1:])
    except SystemExit as exc:  # argparse's way of refusing
        pytest.fail(f"the guide's {cmd!r} does not parse (exit {exc.code})")


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_the_site_builds_without_a_warning(tmp_path):
    for mod in ("sphinx", "numpydoc", "myst_parser"):
        pytest.importorskip(mod)
    r = subprocess.run([sys.executable, "-m", "sphinx", "-n", "-W", "--keep-going", "-q", "-b", "html", str(DOCS),
                        str(tmp_path / "html")], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    api = (tmp_path / "html" / "api" / "migration.html").read_text(encoding="utf-8")
    # the API pages carry the docstrings (numpydoc sections rendered), not only the names
    assert "ProfileFrame" in api and "extract_profile_targets" in api
    assert "in 3D and extract targets" in api  # reconstruct()'s docstring
    assert "Parameters" in (tmp_path / "html" / "api" / "viz.html").read_text(encoding="utf-8")
    guide = (tmp_path / "html" / "guide.html").read_text(encoding="utf-8")
    assert "Grid surveys, C-scans and 3D" in guide and 'href="api/core.html#gpr3d.core.survey.Survey"' in guide
    conventions = (tmp_path / "html" / "CONVENTIONS.html").read_text(encoding="utf-8")
    assert "targets.json" in conventions


README = DOCS.parent / "README.md"


def test_the_readme_opens_with_the_two_commands_and_stays_short():
    text = README.read_text(encoding="utf-8")
    block = re.search(r"```bash\n(.*?)```", text, flags=re.S).group(1).strip().splitlines()
    ci = (DOCS.parent / ".ci" / "run").read_text(encoding="utf-8").strip().splitlines()[-1]
    assert len(block) == 2 and block[0].endswith("gpr3d demo") and block[1] == ci
    assert len(text.splitlines()) <= 150
    for link in re.findall(r"\]\(([^)#]+)\)", text):  # every relative link names a file of the checkout
        if not link.startswith("http"):
            assert (DOCS.parent / link).exists(), link
    # the quick start's commands parse with the real CLI
    for cmd in re.findall(r"```bash\n(.*?)```", text, flags=re.S)[1].replace("\\\n", " ").splitlines():
        cmd = cmd.split("  #")[0].strip()
        if cmd.startswith("gpr3d "):
            from gpr3d.cli.main import build_parser

            build_parser().parse_args(shlex.split(cmd)[1:])


@pytest.mark.slow  # (run by .ci/run's second command: pytest -m slow)
def test_the_readme_s_python_quick_start_runs_on_the_embedded_recording(tmp_path, monkeypatch):
    pytest.importorskip("onnxruntime")
    import json
    import shutil

    import gpr3d

    code = re.search(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S).group(1)
    shutil.copy(Path(gpr3d.__file__).parent / "data" / "FILE____032.DZT", tmp_path)
    monkeypatch.chdir(tmp_path)
    scope = {}
    exec(compile(code, "README.md", "exec"), scope)
    assert scope["found"]["targets"] and 3 < scope["found"]["permittivity"]["eps_r"] < 12
    names = [t["name"] for t in json.loads((tmp_path / "rec" / "targets.json").read_text())["targets"]]
    assert names and names == [f"T{i + 1}" for i in range(len(names))]
    assert {"volume.h5", "top.png", "view3d.png"} <= {p.name for p in (tmp_path / "rec").iterdir()}
