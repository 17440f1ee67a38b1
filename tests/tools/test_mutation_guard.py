"""tools/mutation.py: its equivalents list stays true to the code, and the CI guard re-runs every module of the
stored results that changed since the commit it was scored at (none changed: nothing to run)."""

import re
import shutil
import subprocess
import sys

import pytest

from tests.tools._script import ROOT, load_script


def _tool():
    return load_script("tools/mutation.py")


def test_every_listed_equivalent_is_still_in_its_module():
    tool = _tool()
    eq = tool.load_equivalents(ROOT / "tools" / "mutation_equivalents.toml")
    assert len(eq) >= 10
    for module, rows in eq.items():
        assert module in tool.MODULES, module
        source = (ROOT / tool.source_of(module)).read_text(encoding="utf-8")
        lines = {ln.strip() for ln in source.splitlines()}
        for removed, added, reason in rows:
            assert removed != added and reason.strip(), (module, removed)
            for part in removed.split(" ¶ "):
                assert part in lines, f"{module}: '{part}' is no longer in the code: take it off the list"


def test_stored_results_keep_their_commit_and_make_the_report(tmp_path):
    tool = _tool()
    store, report = tmp_path / "store", tmp_path / "m.md"
    row = {"module": "processing.dewow", "total": 10, "killed": 9, "survived": 1, "equivalent": 0, "score": 0.9,
           "wall_s": 1.0, "survivors": [{"removed": "a", "added": "b", "why": None}], "equivalents": []}
    tool.save_result(row, store, "python tools/mutation.py processing.dewow")
    tool.save_result({**row, "module": "io.dt1", "total": 20, "killed": 15, "survived": 2, "equivalent": 3,
                      "score": 15 / 17, "survivors": [], "timed_out": 4}, store, "python tools/mutation.py io.dt1")
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    assert tool.guarded(store) == {"io.dt1": head or None, "processing.dewow": head or None}
    rows = tool.load_results(store)
    assert [r["module"] for r in rows] == ["io.dt1", "processing.dewow"]  # the order of MODULES
    tool.write_report(rows, report, "python tools/mutation.py")
    text = report.read_text()
    assert "- `a` -> `b`" in text
    # killed, of which timed out ('?': a result stored before the count was kept), survived, equivalent, unclassified
    assert "| io.dt1 | 20 | 15 | 4 | 2 | 3 | 0 | 88.2 % |" in text
    assert "| processing.dewow | 10 | 9 | ? | 1 | 0 | 0 | 90.0 % |" in text
    # the total: 24 killed of 30 - 3 equivalent
    assert "| **all 2** | 30 | 24 | 4 (in 1 modules) | 3 | 3 | 0 | 88.9 % |" in text
    tool.save_result({**row, "timed_out": 1}, store, "python tools/mutation.py processing.dewow")
    tool.write_report(tool.load_results(store), report, "python tools/mutation.py")
    assert "| **all 2** | 30 | 24 | 5 | 3 | 3 | 0 | 88.9 % |" in report.read_text()


def test_mutants_forked_after_one_was_killed_drawing_a_bar_do_not_wait_on_its_lock(tmp_path):
    """The copied tests' conftest gives each process its own tqdm lock: a child killed while holding it (here: a
    child that exits holding it) leaves the next one free to draw a bar."""
    tool = _tool()
    conftest = tmp_path / "conftest.py"
    conftest.write_text("X = 1\n")
    tool.fork_safe_tqdm(conftest)
    code = conftest.read_text() + (
        "import os, tqdm\n"
        "tqdm.tqdm.get_lock().acquire()\n"  # the parent draws; its first child dies in the middle of a bar
        "tqdm.tqdm.get_lock().release()\n"
        "pid = os.fork()\n"
        "if pid == 0:\n"
        "    tqdm.tqdm.get_lock().acquire()\n"
        "    os._exit(0)\n"
        "os.waitpid(pid, 0)\n"
        "pid = os.fork()\n"
        "if pid == 0:\n"
        "    with tqdm.tqdm(total=1, disable=True) as bar:\n"
        "        bar.update(1)\n"
        "    os._exit(7)\n"
        "print(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]), X, tqdm.tqdm.monitor_interval)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=20)
    assert r.stdout.split() == ["7", "1", "0"], r.stderr[-500:]


def test_the_guard_passes_on_this_checkout():
    pytest.importorskip("mutmut")
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    r = subprocess.run([sys.executable, str(ROOT / "tools" / "mutation.py"), "--guard", "--max-children", "2"],
                       cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert re.search(r"^guard: \d+ modules scored", r.stdout, flags=re.M) or "no stored results" in r.stdout


def test_the_guard_refuses_runs_over_its_budget(tmp_path):
    """A stored result measured at the repository's first commit: its module has changed since, and re-running it
    (100 s by its stored time) is over a 50 s budget: the guard fails and names the command to run."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    first = subprocess.run(["git", "rev-list", "--max-parents=0", "HEAD"], cwd=ROOT, capture_output=True,
                           text=True).stdout.split()
    if not first:
        pytest.skip("no git history")
    tool = _tool()
    row = {"module": "processing.steps", "total": 1, "killed": 1, "survived": 0, "equivalent": 0, "score": 1.0,
           "wall_s": 100.0, "survivors": [], "equivalents": []}
    path = tool.save_result(row, tmp_path, "x")
    rec = __import__("json").loads(path.read_text())
    rec["commit"] = first[0]
    path.write_text(__import__("json").dumps(rec))
    r = subprocess.run([sys.executable, str(ROOT / "tools" / "mutation.py"), "--guard", "--store", str(tmp_path),
                        "--budget-s", "50"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 1, r.stdout + r.stderr
    assert "processing.steps takes about 100 s, over the 50 s budget: run python tools/mutation.py " \
           "processing.steps" in r.stdout


def test_survivors_listed_later_as_equivalent_leave_the_score():
    tool = _tool()
    row = {"module": "processing.dewow", "total": 10, "killed": 7, "survived": 2, "equivalent": 1, "score": 7 / 9,
           "equivalents": [{"name": "a", "removed": "x = 1", "added": "x = 2", "why": "old"}],
           "survivors": [{"name": "b", "removed": "y = 1", "added": "y = 2"},
                         {"name": "c", "removed": "z = 1", "added": "z = 0"}]}
    eq = {"processing.dewow": [("y = 1", "y = 2", "the same"), ("z = 1", "z = 3", "another mutant")]}
    out = tool.reclassify(row, eq)
    assert (out["survived"], out["equivalent"], out["score"]) == (1, 2, 7 / 8)
    assert [s["name"] for s in out["survivors"]] == ["c"] and out["equivalents"][-1]["why"] == "the same"
    assert row["survived"] == 2  # the stored result itself is left as measured
    assert tool.reclassify(row, {}) is row and tool.reclassify({"module": "m", "error": "x"}, eq) == {"module": "m",
                                                                                                      "error": "x"}


def test_the_guard_looks_at_the_code_not_the_docstrings():
    tool = _tool()
    a = '"""Mod."""\nimport os\n\n\ndef f(x):\n    """Doc."""\n    return x + 1  # one\n\n\nclass C:\n    """C."""\n'
    b = ('"""Another text, longer,\nover two lines."""\nimport os\n\n\ndef f(x):\n    """Parameters\n    ----------\n'
         '    x : int\n    """\n\n    return x + 1  # two\n\n\nclass C:\n    """Other."""\n')
    assert tool.code_of(a) == tool.code_of(b)
    for code in ("return x + 2", "return x - 1", "return (x + 1)  or 0"):
        assert tool.code_of(a) != tool.code_of(a.replace("return x + 1", code)), code
    assert tool.code_of(a) != tool.code_of(a.replace("import os", "import sys"))
    # a string that is not a docstring is code
    assert tool.code_of(a) != tool.code_of(a.replace('    return x + 1', '    y = "s"\n    return x + 1'))
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    if head:
        committed = subprocess.run(["git", "show", f"HEAD:{tool.source_of('processing.dewow')}"], cwd=ROOT,
                                   capture_output=True, text=True).stdout
        now = (ROOT / tool.source_of("processing.dewow")).read_text(encoding="utf-8")
        assert tool.code_changed("processing.dewow", head) is (tool.code_of(committed) != tool.code_of(now))
        assert tool.code_changed("processing.dewow", "0" * 40) is True  # (a commit not here: re-run)
