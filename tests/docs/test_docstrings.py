"""Every name a package exports (its ``__all__``) is documented in numpydoc's sections: ``Parameters`` where it
takes any, ``Returns`` (or ``Yields``) where a function gives something back, ``Raises`` where its own code raises
(issue 30, item 6). Sections are read by numpydoc's own parser, so a heading it would not render fails here."""

import ast
import importlib
import inspect
import textwrap

import pytest

numpydoc = pytest.importorskip("numpydoc.docscrape")

PACKAGES = ["gpr3d", "gpr3d.data", "gpr3d.io", "gpr3d.processing", "gpr3d.detection", "gpr3d.inversion", "gpr3d.pose",
            "gpr3d.migration", "gpr3d.viz", "gpr3d.pipeline"]


def _exported():
    for pkg in PACKAGES:
        mod = importlib.import_module(pkg)
        for name in mod.__all__:
            obj = getattr(mod, name)
            if inspect.isfunction(obj) or inspect.isclass(obj):
                yield pytest.param(obj, id=f"{pkg}.{name}")


def _own_source(obj):
    try:
        return ast.parse(textwrap.dedent(inspect.getsource(obj)))
    except (OSError, TypeError, SyntaxError):
        return None


def _own_nodes(func):
    """The nodes of a function's own body (not those of a function or class defined in it), and its tree."""
    tree = _own_source(func)
    if tree is None:
        return None, []
    stack, nodes = list(tree.body[0].body), []
    while stack:
        node = stack.pop()
        nodes.append(node)
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            stack.extend(ast.iter_child_nodes(node))
    return tree.body[0], nodes


def _raises(func) -> bool:
    """Whether the function's own body has a ``raise`` that is not a bare re-raise."""
    return any(isinstance(n, ast.Raise) and n.exc is not None for n in _own_nodes(func)[1])


def _returns(func) -> bool:
    """Whether the function gives something back: its annotation (not ``None``), or a ``return`` of a value."""
    top, nodes = _own_nodes(func)
    if top is not None and top.returns is not None:
        return not (isinstance(top.returns, ast.Constant) and top.returns.value is None)
    return any(isinstance(n, ast.Return) and n.value is not None for n in nodes)


def _needs(obj):
    """The sections ``obj``'s docstring must have."""
    need = set()
    if inspect.isclass(obj):
        init = obj.__init__ if "__init__" in vars(obj) else None
        try:
            params = [p for p in inspect.signature(obj).parameters if p not in ("self", "args", "kwargs")]
        except ValueError:  # (an exception class that keeps the built-in constructor)
            params = []
        if params:
            need.add("Parameters")
        if init is not None and _raises(init):
            need.add("Raises")
        return need
    params = [p for p in inspect.signature(obj).parameters if p not in ("args", "kwargs")]
    if params:
        need.add("Parameters")
    if _returns(obj):
        need.add("Returns")
    if _raises(obj):
        need.add("Raises")
    return need


@pytest.mark.parametrize("obj", list(_exported()))
def test_an_exported_name_has_its_sections(obj):
    doc = numpydoc.FunctionDoc(obj) if inspect.isfunction(obj) else numpydoc.ClassDoc(obj)
    have = {k for k in ("Parameters", "Returns", "Yields", "Raises", "Attributes") if doc[k]}
    if "Yields" in have:
        have.add("Returns")
    if inspect.isclass(obj) and "Attributes" in have:  # (a dataclass documents its fields as attributes)
        have.add("Parameters")
    missing = _needs(obj) - have
    assert not missing, f"{obj.__module__}.{obj.__qualname__}: no {', '.join(sorted(missing))} section"
    if "Parameters" in have and not inspect.isclass(obj):
        named = {n.strip() for p in doc["Parameters"] for n in p.name.split(",")}
        real = set(inspect.signature(obj).parameters) - {"args", "kwargs"}
        assert not (named - real - {"*args", "**kwargs"}), f"documents parameters it does not take: {named - real}"


def test_the_checks_themselves():
    def f(a, b=1):
        """Sum.

        Parameters
        ----------
        a, b : int

        Returns
        -------
        int
        """
        if a is None:
            raise ValueError("a")
        return a + b

    def g(x) -> None:
        def inner():
            raise KeyError
        return None

    assert _needs(f) == {"Parameters", "Returns", "Raises"} and _needs(g) == {"Parameters"}
