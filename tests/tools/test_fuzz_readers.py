"""A few hundred seeded cases of the reader fuzzer (the full 10,000 per reader: ``python tools/fuzz_readers.py``),
and the fuzzer's own parts: its mutations change what they say, and anything but a one-line refusal counts."""

from pathlib import Path

import numpy as np
import pytest

import gpr3d

from tests.tools._script import ROOT, load_script


@pytest.fixture(scope="module")
def fz():
    return load_script("tools/fuzz_readers.py")


def test_seeded_cases_of_every_reader_have_no_escapes(fz):
    rows = fz.fuzz(["dzt", "dt1", "rd3", "segy", "gprmax", "gpr3d"], 50, seed=2026, timeout_s=60, log=lambda *a: None)
    assert [r["cases"] for r in rows] == [50] * 6
    for r in rows:
        assert r["escape"] == 0, r["escapes"][:3]
        assert r["read"] + r["refused"] == 50
        assert r["refused"] > 0, r["reader"]  # the damage reaches the readers' checks
    assert sum(r["read"] for r in rows) > 0


def test_the_byte_mutations_do_what_they_say(fz):
    data = bytes(range(256)) * 8
    seen = set()
    for i in range(400):
        rng = np.random.default_rng(i)
        new, kind = fz.mutate_bytes(rng, data, text=False)
        seen.add(kind)
        if kind == "cut":
            assert len(new) <= len(data) and data.startswith(new)
        elif kind == "insert":
            assert len(data) < len(new) <= len(data) + 64
        elif kind == "delete":
            assert len(data) - 256 <= len(new) < len(data)
        elif kind == "append":
            assert new.startswith(data) and len(new) > len(data)
        elif kind == "flip":
            assert len(new) == len(data)
            assert sum(bin(a ^ b).count("1") for a, b in zip(new, data)) <= 8  # (one bit flipped twice cancels)
        elif kind == "field":
            assert len(new) == len(data)
    assert seen == {"flip", "cut", "insert", "delete", "field", "append"}
    text = b"SAMPLES:512\nFREQUENCY:2000.0\nLAST TRACE:10\n"
    kinds = set()
    for i in range(200):
        new, kind = fz.mutate_bytes(np.random.default_rng(i), text, text=True)
        kinds.add(kind)
        if kind == "number":
            assert new != text and new.count(b"\n") == 3
        if kind == "line":
            assert abs(new.count(b"\n") - 3) == 1
    assert {"number", "line"} <= kinds


def test_what_counts_as_an_escape(fz, tmp_path, monkeypatch):
    p = tmp_path / "a.DZT"
    p.write_bytes((Path(gpr3d.__file__).parent / "data" / "FILE____032.DZT").read_bytes())
    assert fz.run_case(p, 30) == ("read", "")
    p.write_bytes(b"\0" * 10)
    outcome, msg = fz.run_case(p, 30)
    assert outcome == "refused" and msg.startswith("a.DZT: ")

    def boom(path):
        raise ValueError("not ours")

    monkeypatch.setattr(gpr3d, "read_all", boom)
    outcome, detail = fz.run_case(p, 30)
    assert outcome == "escape" and detail.startswith("ValueError at ") and "not ours" in detail

    def two_lines(path):
        raise gpr3d.FormatError(path, "first\nsecond")

    monkeypatch.setattr(gpr3d, "read_all", two_lines)
    assert fz.run_case(p, 30)[0] == "escape"

    def nameless(path):
        raise gpr3d.GPR3DError("something, somewhere")

    monkeypatch.setattr(gpr3d, "read_all", nameless)
    assert fz.run_case(p, 30)[0] == "escape"

    def slow(path):
        import time

        time.sleep(5)

    monkeypatch.setattr(gpr3d, "read_all", slow)
    assert fz.run_case(p, 0.2) == ("escape", "no answer within 0.2 s")


def test_a_reader_that_leaves_a_child_running_escapes(fz, tmp_path, monkeypatch):
    import os
    import signal
    import time

    kids = []

    def read_and_leave(path):  # a reader that forks a walker and returns without ending it
        pid = os.fork()
        if pid == 0:
            time.sleep(30)
            os._exit(0)
        kids.append(pid)

    monkeypatch.setattr(fz.gpr3d, "read_all", read_and_leave)
    f = tmp_path / "x.bin"
    f.write_bytes(b"x")
    try:
        assert fz.run_case(f, 5.0) == ("escape", "a child process left running after the read")
    finally:
        for pid in kids:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
    monkeypatch.setattr(fz.gpr3d, "read_all", lambda path: None)
    assert fz.run_case(f, 5.0) == ("read", "")  # and none left: a clean read
