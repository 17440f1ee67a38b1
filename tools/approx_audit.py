"""pytest plugin (an audit, not a check): lists each pytest.approx call whose expected value holds a number below
1e-6 in magnitude and that gives no ``abs`` (pytest's default abs=1e-12 is then a large part of a time in seconds).

    PYTHONPATH=tools .venv/bin/python -m pytest -q -p approx_audit      # the call sites: build/approx_hits.txt
"""
import traceback

import pytest

_orig = pytest.approx
_hits = set()


def _approx(expected, rel=None, abs=None, nan_ok=False):
    if abs is None:
        try:
            import numpy as np

            a = np.abs(np.asarray(expected, dtype=float))
            if np.any((a > 0) & (a < 1e-6)):
                fr = traceback.extract_stack(limit=2)[0]
                _hits.add(f"{fr.filename}:{fr.lineno}")
        except Exception:
            pass
    return _orig(expected, rel=rel, abs=abs, nan_ok=nan_ok)


def pytest_configure(config):
    pytest.approx = _approx


def pytest_unconfigure(config):
    import os

    os.makedirs("build", exist_ok=True)
    with open(os.path.join("build", "approx_hits.txt"), "w") as f:
        f.write("\n".join(sorted(_hits)) + "\n")
