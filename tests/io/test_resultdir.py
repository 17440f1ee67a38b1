"""Result folders committed as a whole: killed at every step of a commit, a folder holds one run's result."""

import json
import os

import pytest

from gpr3d.core.atomic import file_sha256
from gpr3d.core.errors import FormatError
from gpr3d.io import resultdir
from gpr3d.io.resultdir import (
    JOURNAL,
    MANIFEST,
    check_result,
    open_result,
    result_folder,
)


def _write(folder, files):
    for rel, text in files.items():
        p = folder / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def _state(out):
    """The result's files (not the manifest, the journal or a staging folder)."""
    return {p.relative_to(out).as_posix(): p.read_text() for p in out.rglob("*") if p.is_file()
            and p.name not in (MANIFEST, JOURNAL) and not p.relative_to(out).parts[0].startswith(".gpr3d")}


OLD = {"volume.h5": "old volume", "config.json": "eps 6", "figs/slice.png": "old slice", "only_old.png": "gone later"}
NEW = {"volume.h5": "new volume", "config.json": "eps 9", "figs/slice.png": "new slice", "targets.json": "[]"}


def test_a_commit_replaces_the_previous_result_and_keeps_a_user_s_files(tmp_path):
    out = tmp_path / "r"
    with result_folder(out, command="test") as stage:
        assert stage.parent == out and stage.name.startswith(".gpr3d-staging-")
        _write(stage, OLD)
    (out / "my_notes.txt").write_text("mine")
    assert check_result(out)["files"].keys() == set(OLD)
    with result_folder(out, command="test") as stage:
        _write(stage, NEW)
    assert _state(out) == {**NEW, "my_notes.txt": "mine"}  # only_old.png went with the old result; the notes stay
    m = check_result(out)
    assert m["command"] == "test" and set(m["files"]) == set(NEW)
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []


def test_an_error_while_writing_leaves_the_previous_result(tmp_path):
    out = tmp_path / "r"
    with result_folder(out) as stage:
        _write(stage, OLD)
    with pytest.raises(RuntimeError):
        with result_folder(out) as stage:
            _write(stage, {"volume.h5": "half"})
            raise RuntimeError("killed")
    assert _state(out) == OLD and not [p for p in out.iterdir() if p.name.startswith(".gpr3d")]
    check_result(out)


@pytest.mark.parametrize("cut", range(1, 9))
def test_a_kill_at_any_step_of_the_commit_is_finished_by_the_next_opening(tmp_path, monkeypatch, cut):
    """os.replace and unlink stopped after ``cut`` calls (a kill mid-commit): the folder mixes the two runs until
    opened; opening finishes the commit, and the result is the new one, whole."""
    out = tmp_path / "r"
    with result_folder(out) as stage:
        _write(stage, OLD)
    calls = {"n": 0}
    real_replace, real_unlink = os.replace, os.unlink

    class Killed(BaseException):
        pass

    def counted(fn):
        def inner(*a, **k):
            calls["n"] += 1
            if calls["n"] > cut:
                raise Killed
            return fn(*a, **k)
        return inner

    monkeypatch.setattr(resultdir.os, "replace", counted(real_replace))
    monkeypatch.setattr("pathlib.Path.unlink", lambda self, missing_ok=False: counted(real_unlink)(self))
    try:
        with result_folder(out) as stage:
            _write(stage, NEW)
    except Killed:
        pass
    monkeypatch.undo()
    # before anyone opens it: the old result whole, or a mix that the manifest's hashes show
    try:
        _check_without_opening(out)
        assert _state(out) in (OLD, NEW)
    except FormatError:
        assert (out / JOURNAL).exists()
    open_result(out)
    assert _state(out) in (NEW, OLD)
    if calls["n"] > 1:  # the journal was written (its own replace is call 1): the commit went forward
        assert _state(out) == NEW
    check_result(out)
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def _check_without_opening(out):
    m = json.loads((out / MANIFEST).read_text())
    for rel, digest in m["files"].items():
        if not (out / rel).exists() or file_sha256(out / rel) != digest:
            raise FormatError(out, "mixed")


def test_stale_staging_folders_and_partial_files_are_removed(tmp_path):
    out = tmp_path / "r"
    (out / ".gpr3d-staging-abc").mkdir(parents=True)
    (out / ".gpr3d-staging-abc" / "volume.h5").write_text("half")
    (out / ".volume.h5.x1y2.part").write_text("half")
    (out / ".hidden_user_file").write_text("mine")
    open_result(out)
    assert sorted(p.name for p in out.iterdir()) == [".hidden_user_file"]


def test_what_check_result_refuses(tmp_path):
    out = tmp_path / "r"
    with result_folder(out) as stage:
        _write(stage, NEW)
    (out / "targets.json").write_text("[1]")
    with pytest.raises(FormatError, match=r"targets.json: differs from the result's manifest"):
        check_result(out)
    (out / "targets.json").unlink()
    with pytest.raises(FormatError, match=r"r: holds no targets.json, which its manifest lists"):
        check_result(out)
    (out / MANIFEST).write_text("{not json")
    with pytest.raises(FormatError, match=r"manifest.json: the result's manifest is unreadable"):
        check_result(out)
    with pytest.raises(FormatError, match=r"a result may not hold its own manifest.json"):
        with result_folder(tmp_path / "s") as stage:
            (stage / MANIFEST).write_text("{}")
