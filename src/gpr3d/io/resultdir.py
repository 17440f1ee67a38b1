"""Result folders committed as a whole: a kill at any moment leaves one run's result, never a mix of two.

A command that writes several files into ``--out`` (``reconstruct``, ``cscan``, ``migrate``) writes them into a
staging folder inside it, then commits:

1. ``.gpr3d-commit.json`` is written (atomically): the new result's files with their SHA-256;
2. each staged file is moved into place (``os.replace``, atomic per file), the previous result's files that
   the new one lacks are removed;
3. ``manifest.json`` (the same list) is written, the journal and the staging folder removed.

A kill during staging leaves the previous result as it was (the staging folder is removed by the next run); a
kill during steps 2-3 leaves the journal, and whoever opens the folder next (the next run, or
:func:`open_result`) finishes the commit from it: the new result, complete. Files in the folder that no result
listed (a user's own) are never touched. :func:`check_result` compares the files with the manifest.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path

from gpr3d.core.atomic import atomic_write_text, file_sha256
from gpr3d.core.errors import FormatError

__all__ = ["result_folder", "open_result", "check_result", "MANIFEST", "JOURNAL"]

MANIFEST = "manifest.json"
JOURNAL = ".gpr3d-commit.json"
_STAGE_PREFIX = ".gpr3d-staging-"


def _files(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def _read_json(path: Path, what: str) -> dict:
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise FormatError(path, f"the result's {what} is unreadable ({exc.__class__.__name__}): remove the folder "
                                "or run the command again into a new one") from None
    if not isinstance(d, dict) or not isinstance(d.get("files"), dict):
        raise FormatError(path, f"the result's {what} lists no files")
    return d


def _roll_forward(out: Path) -> None:
    """Finish a commit whose journal is in ``out`` (idempotent: a kill here is finished by the next call)."""
    journal = _read_json(out / JOURNAL, "commit journal")
    stage = out / journal["stage"]
    old = _read_json(out / MANIFEST, "manifest")["files"] if (out / MANIFEST).exists() else {}
    for rel in journal["files"]:
        src = stage / rel
        if src.exists():
            (out / rel).parent.mkdir(parents=True, exist_ok=True)
            os.replace(src, out / rel)
    for rel in set(old) - set(journal["files"]):
        with contextlib.suppress(FileNotFoundError):
            (out / rel).unlink()
    manifest = {k: v for k, v in journal.items() if k != "stage"}
    atomic_write_text(out / MANIFEST, json.dumps(manifest, indent=1))
    shutil.rmtree(stage, ignore_errors=True)
    (out / JOURNAL).unlink()


def open_result(out) -> Path:
    """``out`` after finishing an interrupted commit and removing stale staging folders and partial files."""
    out = Path(out)
    if (out / JOURNAL).exists():
        _roll_forward(out)
    if out.is_dir():
        for p in out.iterdir():
            if p.name.startswith(_STAGE_PREFIX) and p.is_dir():
                shutil.rmtree(p, ignore_errors=True)
            elif p.name.startswith(".") and p.name.endswith(".part") and p.is_file():
                p.unlink()  # an atomic write cut short (atomic_path's temporary file)
    return out


@contextlib.contextmanager
def result_folder(out, *, command: str = ""):
    """Yield a staging folder to write a result into; on success it becomes ``out``'s result as a whole.

    On an exception (or a kill) nothing of the new result reaches ``out``; the previous result stays.
    """
    out = open_result(out)
    out.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=_STAGE_PREFIX, dir=out))
    try:
        yield stage
        files = {rel: file_sha256(stage / rel) for rel in _files(stage)}
        if MANIFEST in files or JOURNAL in files:
            raise FormatError(out, f"a result may not hold its own {MANIFEST}")
        atomic_write_text(out / JOURNAL, json.dumps({"command": command, "stage": stage.name, "files": files},
                                                    indent=1))
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    _roll_forward(out)


def check_result(out) -> dict:
    """The manifest of a committed result after checking every file it lists (present, same SHA-256)."""
    out = open_result(out)
    manifest = _read_json(out / MANIFEST, "manifest")
    for rel, digest in manifest["files"].items():
        p = out / rel
        if not p.is_file():
            raise FormatError(out, f"holds no {rel}, which its manifest lists: an incomplete result")
        if file_sha256(p) != digest:
            raise FormatError(p, "differs from the result's manifest (changed after the run, or from another run)")
    return manifest
