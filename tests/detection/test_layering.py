"""detection/ (and inversion/, pose/ when they land) depend on core and io, never on simulation."""

import ast
from pathlib import Path

import gpr3d

PKG = Path(gpr3d.__file__).parent


def _imports(path: Path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            yield node.module
        elif isinstance(node, ast.Import):
            yield from (a.name for a in node.names)


def test_detection_does_not_import_simulation_or_cli():
    offenders = []
    for sub in ("detection", "inversion", "pose"):
        for f in sorted((PKG / sub).rglob("*.py")) if (PKG / sub).exists() else []:
            bad = [m for m in _imports(f) if m.startswith(("gpr3d.simulation", "gpr3d.cli", "gpr3d.migration"))]
            offenders += [f"{f.relative_to(PKG)}: {m}" for m in bad]
    assert (PKG / "detection").exists()
    assert not offenders, offenders


def test_processing_does_not_import_the_survey_module():
    # core.survey calls processing lazily; processing must not import it back (no cycle)
    for f in sorted((PKG / "processing").rglob("*.py")):
        assert "gpr3d.core.survey" not in set(_imports(f)), f
