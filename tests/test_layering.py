"""The packages' floors, written once: each imports only those below it (issue 30, item 5).

    core <- io <- processing <- detection / inversion / pose <- migration <- viz <- pipeline <- cli

``simulation`` stands beside: it may use core, io and processing, and only the top (``demo``, just above the
pipeline, and ``cli``) uses it. Function-level imports count as much as module-level ones (a lazy import is still an
arrow), and so does a plug-in's name in a string (``"gpr3d.io.hdf5:write_survey"``). The arrows that break the floors today are listed in ``KNOWN`` with what removes them; the test fails on
any other, and on a listed one that is gone (take it off the list). Module-level imports between gpr3d modules
must form no cycle.
"""

import ast
import re
from pathlib import Path

import gpr3d

PKG = Path(gpr3d.__file__).parent

#: each package's floor; a package imports only from lower floors (and its own)
FLOOR = {"data": 0, "core": 0, "io": 1, "processing": 2, "detection": 3, "inversion": 3, "pose": 3, "migration": 4, "viz": 5,
         "pipeline": 6, "demo": 6.5, "cli": 7, "__main__": 8, "__init__": 8}
#: simulation beside the stack: what it may use
BESIDE = {"simulation": {"core", "io", "processing"}}
#: packages of one floor that must not import each other either
SIBLINGS_APART = {"detection", "inversion", "pose"}
#: today's exceptions, each with what ends it (issue 30)
KNOWN: dict = {}  # (none left: Survey reaches io and processing through gpr3d.core.survey.PLUGINS)


PLUGIN_NAME = re.compile(r"gpr3d(\.\w+)+:\w+")


def _package(path: Path) -> str:
    rel = path.relative_to(PKG).parts
    return rel[0] if len(rel) > 1 else rel[0][:-3]


def _imports(path: Path, top_level_only: bool = False):
    """Modules imported (``from gpr3d.io import dt1`` names ``gpr3d.io.dt1`` where that is a module)."""
    tree = ast.parse(path.read_text())
    nodes = tree.body if top_level_only else ast.walk(tree)
    for node in nodes:
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            subs = [f"{node.module}.{a.name}" for a in node.names
                    if (PKG.parent / f"{node.module}.{a.name}".replace(".", "/")).with_suffix(".py").exists()]
            yield from subs or [node.module]
        elif isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif (not top_level_only and isinstance(node, ast.Constant) and isinstance(node.value, str)
              and PLUGIN_NAME.fullmatch(node.value)):
            yield node.value.split(":")[0]  # a plug-in named "gpr3d.io.hdf5:write_survey" is an arrow as well


def _arrows() -> dict:
    arrows = {}
    for f in sorted(PKG.rglob("*.py")):
        src = _package(f)
        for m in _imports(f):
            if m.startswith("gpr3d.") and m.split(".")[1] != src:
                arrows.setdefault((src, m.split(".")[1]), []).append(str(f.relative_to(PKG)))
    return arrows


def _allowed(src: str, dst: str) -> bool:
    if src in BESIDE:
        return dst in BESIDE[src]
    if dst in BESIDE:  # only the top (demo, cli) reaches simulation
        return FLOOR.get(src, 0) >= FLOOR["demo"]
    if src in SIBLINGS_APART and dst in SIBLINGS_APART:
        return False
    return FLOOR[dst] < FLOOR[src]


def test_every_package_has_a_floor():
    packages = {_package(f) for f in PKG.rglob("*.py")} - {"data"}
    assert packages <= set(FLOOR) | set(BESIDE), packages - set(FLOOR) - set(BESIDE)


def test_imports_go_down_the_floors_only():
    arrows = _arrows()
    bad = {k: v for k, v in arrows.items() if not _allowed(*k) and k not in KNOWN}
    assert not bad, "\n".join(f"{a} -> {b}: {', '.join(fs)}" for (a, b), fs in bad.items())
    gone = [k for k in KNOWN if k not in arrows]
    assert not gone, f"no longer imported (take them off KNOWN): {gone}"
    assert all(not _allowed(*k) for k in KNOWN)  # (a listed arrow that is allowed belongs nowhere on the list)


def test_the_rule_itself():
    assert _allowed("migration", "core") and _allowed("cli", "simulation") and _allowed("simulation", "io")
    assert not _allowed("io", "processing") and not _allowed("detection", "inversion")
    assert not _allowed("processing", "simulation") and not _allowed("simulation", "migration")
    assert not _allowed("viz", "cli") and _allowed("viz", "migration")
    assert PLUGIN_NAME.fullmatch("gpr3d.io.hdf5:write_survey") and not PLUGIN_NAME.fullmatch("gpr3d.io.hdf5")


def test_no_import_cycle_between_modules():
    graph = {}
    for f in sorted(PKG.rglob("*.py")):
        rel = f.relative_to(PKG).with_suffix("")
        name = ".".join(("gpr3d", *rel.parts)).removesuffix(".__init__")
        graph[name] = {m for m in _imports(f, top_level_only=True) if m.startswith("gpr3d.")}
    modules = set(graph)

    def resolve(m):  # "from gpr3d.io import x" imports the package gpr3d.io
        while m not in modules and "." in m:
            m = m.rsplit(".", 1)[0]
        return m

    state, stack = {}, []

    def visit(n):
        state[n] = 1
        stack.append(n)
        # (a module's own parent packages are initialised before it: no arrow back to them)
        parents = {n.rsplit(".", k)[0] for k in range(1, n.count(".") + 1)}
        for m in sorted({resolve(x) for x in graph.get(n, ())} - {n} - parents):
            if state.get(m) == 1:
                raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(m):] + [m]))
            if m not in state:
                visit(m)
        stack.pop()
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n)
