"""Fuzz every radar reader with mutated recordings and count what escapes (issue 31).

    python tools/fuzz_readers.py                          # 10,000 cases per reader, the table to stdout
    python tools/fuzz_readers.py --cases 300 --seed 7     # a quick pass
    python tools/fuzz_readers.py --out benchmarks/results/fuzz_readers.md

Each case starts from a real recording (the embedded GSSI DZT; ``../shared/data/real`` where present) or a
small file made here, changes it the way damage and hostile files do (bits flipped, the file cut short, bytes
inserted or removed, binary header fields set to extremes, text header numbers replaced by nan, inf, 0, -1,
1e308 ..., lines dropped or repeated; for HDF5 files also attributes and data sets replaced), and reads it with
``gpr3d.read_all``. A case ends one of three ways:

- **read**: a survey comes back (warnings allowed: a truncated recording reads what it holds);
- **refused**: a :class:`gpr3d.GPR3DError` (one line naming the file);
- **escape**: anything else (another exception, a hang past ``--timeout-s``, a process killed, a child process a
  reader leaves running), a defect.

Every case is made from ``(seed, reader, index)`` alone, so an escape is reproduced with ``--reader R --only I``.
Memory is capped (``--memory-gb``, the address space of this process) so that a header's claim of a huge array
is an escape unless the reader refuses it first.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import platform
import re
import resource
import shutil
import signal
import struct
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "src"), str(ROOT)]
REAL = ROOT.parent / "shared" / "data" / "real"

import gpr3d  # noqa: E402
from gpr3d.core.errors import GPR3DError  # noqa: E402

# ----------------------------------------------------------------------------------------------- the starting files


def _bytes_of(path: Path) -> bytes:
    return path.read_bytes()


def _made(make) -> dict[str, bytes]:
    """Files a maker writes into a fresh folder, as {name: bytes}."""
    with tempfile.TemporaryDirectory() as d:
        make(Path(d))
        return {p.name: p.read_bytes() for p in sorted(Path(d).iterdir())}


def _real(*rels) -> list[dict[str, bytes]]:
    out = []
    for rel in rels:
        files = {}
        for p in sorted((REAL / rel[0]).glob(rel[1])):
            files[p.name] = p.read_bytes()
        if files:
            out.append(files)
    return out


def bases() -> dict[str, list[tuple[dict[str, bytes], str]]]:
    """Per reader: (files {name: bytes}, the name to read) pairs to mutate."""
    from tests.io.makers import write_dt1, write_dzt, write_gprmax3_out, write_rd3

    def survey(d):
        rng = np.random.default_rng(0)
        s = gpr3d.Survey(data=rng.standard_normal((12, 64)).astype(np.float32), dt_s=1e-10, frequency_hz=1e9,
                         positions_xyz=np.c_[np.arange(12) * 0.02, np.zeros(12), np.zeros(12)])
        s.save(d / "s.h5")

    def segy(d):
        from gpr3d.io.segy import write_segy

        rng = np.random.default_rng(1)
        write_segy(gpr3d.Survey(data=rng.standard_normal((10, 48)).astype(np.float32), dt_s=1e-10,
                                frequency_hz=5e8, positions_xyz=np.c_[np.arange(10) * 0.05, np.zeros((10, 2))]),
                   d / "s.sgy")

    def gprmax4(d):
        import h5py

        with h5py.File(d / "g.h5", "w") as f:
            f.attrs.update({"gprMax": "4.0.1", "Iterations": 40, "dt": 2e-12, "Title": "fuzz", "nrx": 1,
                            "dx_dy_dz": (0.002, 0.002, 0.002), "rxsteps": (1, 0, 0), "srcsteps": (1, 0, 0)})
            g = f.create_group("rxs/rx1")
            g.attrs["Position"] = (0.1, 0.1, 0.0)
            g["Ez"] = np.sin(np.arange(40 * 6).reshape(40, 6) / 7.0)
            f.create_group("srcs/src1").attrs["Position"] = (0.08, 0.1, 0.0)

    dzt = [({"FILE____032.DZT": (Path(gpr3d.__file__).parent / "data" / "FILE____032.DZT").read_bytes()},
            "FILE____032.DZT")]
    for kw in ({}, {"n_channels": 2, "bits": 8}, {"bits": 32, "rh_data": 2}):
        files = _made(lambda d, kw=kw: write_dzt(d / "m.DZT", **kw))
        dzt.append((files, "m.DZT"))
    dt1 = [(_made(lambda d: write_dt1(d / "m")), "m.DT1"), (_made(lambda d: write_dt1(d / "w", bits=32)), "w.DT1")]
    rd3 = [(_made(lambda d: write_rd3(d / "m")), "m.rd3")]
    for files in _real(("impdar_mala_500MHz", "ten_col_nogps.*")):
        rd3.append((files, "ten_col_nogps.rd3"))
    for files in _real(("gprpy_sns_50MHz", "XLINE00.*")):
        dt1.append((files, "XLINE00.DT1"))
    for files in _real(("impdar_gssi_sir4000", "test_gssi.DZ?")):
        dzt.append((files, "test_gssi.DZT"))
    return {
        "dzt": dzt,
        "dt1": dt1,
        "rd3": rd3,
        "segy": [(_made(segy), "s.sgy")],
        "gprmax": [(_made(gprmax4), "g.h5"), (_made(lambda d: write_gprmax3_out(d / "o.out")), "o.out")],
        "gpr3d": [(_made(survey), "s.h5")],
    }


# ----------------------------------------------------------------------------------------------- the mutations

TEXT_VALUES = ["nan", "inf", "-inf", "0", "-1", "1e308", "-1e308", "1e-308", "1e-40", "99999999999999", "0.5",
               "4294967296", "abc", "", "1,5", "0x10", "+", "."]
BIN_VALUES = [b"\x00\x00", b"\xff\xff", b"\xff\x7f", b"\x00\x80", b"\x01\x00", struct.pack("<f", float("nan")),
              struct.pack("<f", float("inf")), struct.pack("<f", -1.0), struct.pack("<f", 3e38),
              struct.pack("<f", 1e-42), struct.pack("<I", 0xFFFFFFFF), struct.pack("<i", -1),
              struct.pack("<d", float("nan")), struct.pack(">f", 1e30), struct.pack(">H", 65535), b"\x00" * 8]


def _is_text(name: str, data: bytes) -> bool:
    return name.lower().endswith((".hd", ".rad", ".dzx", ".gps", ".cor")) or (b"\x00" not in data[:512] and
                                                                             name.lower().endswith(".txt"))


def mutate_bytes(rng, data: bytes, text: bool) -> tuple[bytes, str]:
    b = bytearray(data)
    kinds = ["flip", "cut", "insert", "delete", "field", "append"] + (["number", "line", "number", "number"]
                                                                     if text else ["field", "field"])
    kind = kinds[rng.integers(len(kinds))]
    if kind == "flip" and b:
        head = rng.random() < 0.6  # most flips in the headers, where a bit decides the layout
        for _ in range(int(rng.integers(1, 9))):
            i = int(rng.integers(min(len(b), 4096) if head else len(b)))
            b[i] ^= 1 << int(rng.integers(8))
    elif kind == "cut":
        b = b[: int(rng.integers(len(b) + 1))]
    elif kind == "insert":
        i = int(rng.integers(len(b) + 1))
        b[i:i] = rng.integers(0, 256, int(rng.integers(1, 65)), dtype=np.uint8).tobytes()
    elif kind == "delete" and b:
        i = int(rng.integers(len(b)))
        del b[i : i + int(rng.integers(1, 257))]
    elif kind == "field" and b:
        v = BIN_VALUES[rng.integers(len(BIN_VALUES))]
        lim = min(len(b), 4096 if rng.random() < 0.8 else len(b))
        i = int(rng.integers(max(lim - len(v), 0) // 2 + 1)) * 2
        b[i : i + len(v)] = v
    elif kind == "append":
        b += rng.integers(0, 256, int(rng.integers(1, 5000)), dtype=np.uint8).tobytes()
    elif kind == "number":
        s = b.decode("latin-1")
        nums = list(re.finditer(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?", s))
        if nums:
            m = nums[rng.integers(len(nums))]
            s = s[: m.start()] + TEXT_VALUES[rng.integers(len(TEXT_VALUES))] + s[m.end() :]
        b = bytearray(s.encode("latin-1"))
    elif kind == "line":
        lines = b.split(b"\n")
        j = int(rng.integers(len(lines)))
        if rng.random() < 0.5:
            del lines[j]
        else:
            lines.insert(j, lines[j])
        b = bytearray(b"\n".join(lines))
    return bytes(b), kind


H5_VALUES = [float("nan"), float("inf"), -1.0, 0.0, 1e-40, 1e40, 2**31, -(2**31), "text", np.zeros(3), np.ones((2, 2))]


def mutate_h5(rng, path: Path) -> str:
    """Semantic damage through h5py: an attribute set to an extreme, a data set replaced or removed."""
    import h5py

    with h5py.File(path, "r+") as f:
        objs = []
        f.visititems(lambda n, o: objs.append(n))
        roll = rng.random()
        if roll < 0.5:
            holders = [f] + [f[n] for n in objs]
            h = holders[rng.integers(len(holders))]
            keys = list(h.attrs)
            if keys:
                k = keys[rng.integers(len(keys))]
                v = H5_VALUES[rng.integers(len(H5_VALUES))]
                if rng.random() < 0.15:
                    del h.attrs[k]
                    return f"attr {h.name}@{k} removed"
                h.attrs[k] = v
                return f"attr {h.name}@{k} = {v!r}"[:80]
        sets = [n for n in objs if isinstance(f[n], h5py.Dataset)]
        if sets:
            n = sets[rng.integers(len(sets))]
            shape = f[n].shape
            del f[n]
            r = rng.random()
            if r < 0.2:
                return f"dataset {n} removed"
            if r < 0.4:
                f.create_dataset(n, shape=(10**6, 10**5) if len(shape) == 2 else (10**9,), dtype="f4",
                                 chunks=True)
                return f"dataset {n} declared huge"
            if r < 0.6:
                f[n] = np.full(shape, np.nan)
                return f"dataset {n} all nan"
            if r < 0.8:
                f[n] = np.zeros(tuple(int(v) for v in rng.integers(0, 4, int(rng.integers(0, 4)))))
                return f"dataset {n} another shape"
            f[n] = np.array([b"x"] * 3)
            return f"dataset {n} strings"
    return "unchanged"


# ----------------------------------------------------------------------------------------------- one case


class _Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise _Timeout


def make_case(rng, base: tuple[dict[str, bytes], str], folder: Path) -> tuple[Path, str]:
    files, main = base
    for p in folder.iterdir():
        p.unlink()
    for name, data in files.items():
        (folder / name).write_bytes(data)
    target = main if len(files) == 1 or rng.random() < 0.5 else list(files)[rng.integers(len(files))]
    path = folder / target
    data = files[target]
    if data[:8] == b"\x89HDF\r\n\x1a\n" and rng.random() < 0.6:
        how = mutate_h5(rng, path)
    else:
        new, how = mutate_bytes(rng, data, _is_text(target, data))
        path.write_bytes(new)
    return folder / main, f"{target}: {how}"


def _children() -> set:
    """This process's living children (Linux: from /proc; elsewhere none are seen)."""
    me, kids = os.getpid(), set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if fields[0] != "Z" and int(fields[1]) == me:  # (state, ppid) after the command's name
            kids.add(int(stat.parent.name))
    return kids


def _left_behind(before: set) -> str:
    """A process the read started and left running (a pre-check's child once walked a looping file for 25 min)."""
    return "; and a child process left running" if _children() - before else ""


def run_case(path: Path, timeout_s: float, names=()) -> tuple[str, str]:
    """("read" | "refused" | "escape", detail)."""
    before = _children()
    outcome = _run_case(path, timeout_s, names)
    left = _left_behind(before)
    if left and outcome[0] != "escape":
        return "escape", "a child process left running after the read"
    return outcome[0], outcome[1] + (left if outcome[0] == "escape" else "")


def _run_case(path: Path, timeout_s: float, names=()) -> tuple[str, str]:
    signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with contextlib.redirect_stderr(io.StringIO()):
                gpr3d.read_all(path)
        return "read", ""
    except GPR3DError as exc:
        msg = str(exc)
        if "\n" in msg or not msg.startswith(tuple(f"{n}: " for n in (path.name, *names))):
            return "escape", f"a refusal that is not one line naming the file: {msg[:200]!r}"
        return "refused", msg
    except _Timeout:
        return "escape", f"no answer within {timeout_s:g} s"
    except BaseException as exc:  # noqa: BLE001 - every other outcome is what this counts
        tb = traceback.extract_tb(exc.__traceback__)
        where = next((f"{Path(fr.filename).name}:{fr.lineno}" for fr in reversed(tb) if "gpr3d" in fr.filename), "?")
        return "escape", f"{type(exc).__name__} at {where}: {str(exc)[:160]}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)


# ----------------------------------------------------------------------------------------------- the run


def fuzz(readers, cases: int, seed: int, timeout_s: float, only=None, log=print) -> list[dict]:
    all_bases = bases()
    rows = []
    work = Path(tempfile.mkdtemp(prefix="gpr3d-fuzz-"))
    try:
        for reader in readers:
            folder = work / reader
            folder.mkdir()
            counts = {"read": 0, "refused": 0, "escape": 0}
            escapes = []
            t0 = time.perf_counter()
            indices = [only] if only is not None else range(cases)
            for i in indices:
                rng = np.random.default_rng([seed, list(all_bases).index(reader), i])
                base = all_bases[reader][rng.integers(len(all_bases[reader]))]
                path, how = make_case(rng, base, folder)
                outcome, detail = run_case(path, timeout_s, names=tuple(base[0]))
                counts[outcome] += 1
                if outcome == "escape":
                    escapes.append({"index": i, "mutation": how, "detail": detail})
                    if len(escapes) <= 5:
                        log(f"  {reader} case {i} ({how}): {detail}")
            wall = time.perf_counter() - t0
            rows.append({"reader": reader, "cases": len(indices), **counts, "wall_s": wall,
                         "bases": len(all_bases[reader]), "escapes": escapes})
            log(f"{reader}: {len(indices)} cases, {counts['read']} read, {counts['refused']} refused, "
                f"{counts['escape']} escapes, {wall:.0f} s")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return rows


def host() -> str:
    try:
        from numba.core import config

        cpu = config.NUMBA_DEFAULT_TARGET if hasattr(config, "NUMBA_DEFAULT_TARGET") else None
        import llvmlite.binding as llvm

        cpu = llvm.get_host_cpu_name()
    except Exception:  # noqa: BLE001 - the table still says something
        cpu = platform.processor() or platform.machine()
    return f"{cpu}, {os.cpu_count()} cores"


def table(rows, seed: int, command: str) -> str:
    lines = [f"Reader fuzzing (issue 31): `{command}`; seed {seed}; host {host()}.", "",
             "| reader | starting files | cases | read | refused (one line) | escapes | time (s) | cases/s |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['reader']} | {r['bases']} | {r['cases']} | {r['read']} | {r['refused']} | "
                     f"{r['escape']} | {r['wall_s']:.0f} | {r['cases'] / max(r['wall_s'], 1e-9):.0f} |")
    for r in rows:
        for e in r["escapes"][:20]:
            lines.append(f"\n- {r['reader']} case {e['index']} ({e['mutation']}): {e['detail']}")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", type=int, default=10_000, help="cases per reader (10,000)")
    ap.add_argument("--seed", type=int, default=31)
    ap.add_argument("--reader", nargs="*", default=None, help="readers (default all: dzt dt1 rd3 segy gprmax gpr3d)")
    ap.add_argument("--only", type=int, default=None, help="run this one case index (to reproduce an escape)")
    ap.add_argument("--timeout-s", type=float, default=20.0, help="a case without an answer by then escapes")
    ap.add_argument("--memory-gb", type=float, default=4.0, help="address-space cap of this process")
    ap.add_argument("--out", default=None, help="also write the table here (Markdown)")
    args = ap.parse_args(argv)
    readers = args.reader or ["dzt", "dt1", "rd3", "segy", "gprmax", "gpr3d"]
    if args.memory_gb > 0:
        cap = int(args.memory_gb * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    rows = fuzz(readers, args.cases, args.seed, args.timeout_s, only=args.only)
    command = "python tools/fuzz_readers.py " + " ".join(argv if argv is not None else sys.argv[1:])
    text = table(rows, args.seed, command.strip())
    print(text)
    if args.out:
        from gpr3d.core.atomic import atomic_write_text

        atomic_write_text(args.out, text)
    return 1 if any(r["escape"] for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
