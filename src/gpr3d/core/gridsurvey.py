"""Grid surveys: parallel (or any straight) lines recorded one by one, put together into one :class:`~gpr3d.core.survey.Survey`.

A line file knows how far along its own line each trace was taken (survey wheel or
trace counter); where the lines lie is a fact of the field, given by the user:

* ``line_spacing_m``: line ``k`` runs along x at ``y = k * spacing`` (``direction="y"``: along y at
  ``x = k * spacing``), from ``start_offsets_m[k]`` (default 0) onwards; with ``serpentine`` every
  second line was walked back (its first trace at the far end, ``start + length``);
  ``reversed_lines`` names single lines walked back;
* a second, perpendicular set (``cross_lines``: the last lines given): cross line ``j`` runs along the other
  axis at ``cross_spacing_m * j`` (default the same spacing) plus ``cross_origin_m``; start offsets, reversals
  and ``serpentine`` apply to it as to the first set (offsets and reversals indexed over all lines, the
  first set's then the cross set's; the zig-zag counted within each set);
* or a layout (:func:`read_layout`): per line, its start and end points ``x0 y0 x1 y1``; the traces
  lie along that segment by their along-line distance.

The traces keep their order (line by line); the antenna heading follows the line
(for the tx-rx offset); ``metadata["grid"]`` records the files, their first trace
and placement.
"""

from __future__ import annotations

import csv
import io as _io
from pathlib import Path

import numpy as np

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.poses import quat_from_yaw

__all__ = ["GridLine", "assemble_grid", "read_layout", "along_line_distance", "marks_distance", "place_by_marks"]


class GridLine:
    """Where one line lies: ``start`` and ``end`` points (x, y, m), and whether it was walked from ``end``."""

    def __init__(self, start, end):
        self.start = np.asarray(start, dtype=float).reshape(2)
        self.end = np.asarray(end, dtype=float).reshape(2)
        if not (np.all(np.isfinite(self.start)) and np.all(np.isfinite(self.end))):
            raise InvalidDataError(f"a line's start and end must be finite, got {start} and {end}")
        if np.hypot(*(self.end - self.start)) <= 0:
            raise InvalidDataError(f"a line's start and end must differ, got {start} twice")

    @property
    def direction(self) -> np.ndarray:
        d = self.end - self.start
        return d / np.hypot(*d)

    def __repr__(self):
        return f"GridLine(start={self.start.tolist()}, end={self.end.tolist()})"


def along_line_distance(survey) -> np.ndarray:
    """Each trace's distance along its line (m) from the first: from the file's positions (path length) where it
    has them, else an error (give the files' trace spacing with ``trace_spacing_m``)."""
    p = survey.positions_xyz
    if p is None:
        raise InvalidDataError(f"{survey.metadata.get('path', 'a line')}: no trace positions (survey wheel); give "
                               "the trace spacing")
    step = np.hypot(*np.diff(p[:, :2], axis=0).T)
    return np.concatenate([[0.0], np.cumsum(step)])


def marks_distance(n_traces: int, marks, spacing_m: float, *, start_m: float = 0.0) -> np.ndarray:
    """Each trace's distance along its line (m) from marks: trace ``marks[k]`` lies at ``start_m + k *
    spacing_m``; traces between marks are spread evenly (piecewise linear), those before the first and after the
    last mark at the rate of the nearest interval. ``marks``: increasing trace indices, at least two."""
    m = np.asarray(marks)
    if m.ndim != 1 or m.size < 2 or not np.issubdtype(m.dtype, np.integer):
        raise InvalidDataError(f"marks: at least two trace indices are needed, got {list(np.ravel(marks))[:6]}")
    if m[0] < 0 or m[-1] >= n_traces or np.any(np.diff(m) <= 0):
        raise InvalidDataError(f"marks must be increasing trace indices in 0..{n_traces - 1}, got "
                               f"{m[:6].tolist()}{' ...' if m.size > 6 else ''}")
    if not (isinstance(spacing_m, (int, float)) and np.isfinite(spacing_m) and spacing_m > 0):
        raise InvalidDataError(f"the distance between marks must be a positive number of metres, got {spacing_m!r}")
    at = start_m + spacing_m * np.arange(m.size)
    i = np.arange(n_traces, dtype=float)
    d = np.interp(i, m, at)
    first, last = spacing_m / (m[1] - m[0]), spacing_m / (m[-1] - m[-2])
    d = np.where(i < m[0], at[0] - (m[0] - i) * first, d)
    return np.where(i > m[-1], at[-1] + (i - m[-1]) * last, d)


def place_by_marks(survey, spacing_m: float, *, marks=None, start_m: float = 0.0):
    """``survey`` with its traces placed along world x by its marks (``marks``, else the file's own:
    ``metadata["marks"]``, which the DZT reader fills), one every ``spacing_m`` metres (:func:`marks_distance`);
    headings along +x. The survey's own positions, if any, are replaced."""
    own = survey.metadata.get("marks")
    if marks is None:
        if not own or len(own) < 2:
            raise InvalidDataError(f"{survey.metadata.get('path', 'the survey')}: the file holds "
                                   f"{len(own or [])} mark(s); give the marked traces")
        marks = own
    d = marks_distance(survey.n_traces, np.asarray(marks, dtype=np.int64) if len(marks) else marks, spacing_m,
                       start_m=start_m)
    pos = np.zeros((survey.n_traces, 3))
    pos[:, 0] = d
    meta = dict(survey.metadata, positions_source=f"marks every {spacing_m:g} m", marks=[int(k) for k in marks])
    return survey.replace(positions_xyz=pos, orientations_quat_wxyz=None, metadata=meta)


def read_layout(path) -> dict:
    """A layout file: one line per radar file, ``name x0 y0 x1 y1`` (spaces or commas; ``#`` comments); returns
    ``{file name: GridLine}``. The name is matched against the line files' names."""
    p = Path(path)
    if not p.is_file():
        raise InvalidDataError(f"layout {path}: no such file")
    out = {}
    text = p.read_text(encoding="utf-8", errors="replace")
    for k, row in enumerate(csv.reader(_io.StringIO(text.replace(",", " ")), delimiter=" ", skipinitialspace=True)):
        row = [c for c in row if c]
        if not row or row[0].startswith("#"):
            continue
        if len(row) != 5:
            raise InvalidDataError(f"layout {p.name} line {k + 1}: expected 'name x0 y0 x1 y1', got {' '.join(row)!r}")
        try:
            x0, y0, x1, y1 = (float(v) for v in row[1:])
        except ValueError:
            raise InvalidDataError(f"layout {p.name} line {k + 1}: coordinates must be numbers, got {row[1:]}") from None
        out[row[0]] = GridLine((x0, y0), (x1, y1))
    if not out:
        raise InvalidDataError(f"layout {p.name} lists no lines")
    return out


def _lines_from_spacing(lengths, *, line_spacing_m, direction, start_offsets_m, serpentine, reversed_lines):
    n = len(lengths)
    if not (isinstance(line_spacing_m, (int, float)) and np.isfinite(line_spacing_m) and line_spacing_m > 0):
        raise InvalidDataError(f"line spacing must be a positive number of metres, got {line_spacing_m!r}")
    if direction not in ("x", "y"):
        raise InvalidDataError(f"direction must be 'x' or 'y', got {direction!r}")
    offs = np.zeros(n) if start_offsets_m is None else np.asarray(start_offsets_m, dtype=float).reshape(-1)
    if offs.size != n or not np.all(np.isfinite(offs)):
        raise InvalidDataError(f"start offsets: one finite number per line ({n}), got {start_offsets_m!r}")
    back = set(reversed_lines or [])
    if any(not isinstance(k, (int, np.integer)) or not 0 <= k < n for k in back):
        raise InvalidDataError(f"reversed lines must be line indices 0..{n - 1}, got {sorted(back)}")
    lines = []
    for k, length in enumerate(lengths):
        across = k * line_spacing_m
        a, b = offs[k], offs[k] + max(length, 1e-6)
        if (serpentine and k % 2 == 1) ^ (k in back):
            a, b = b, a
        start, end = ((a, across), (b, across)) if direction == "x" else ((across, a), (across, b))
        lines.append(GridLine(start, end))
    return lines


def assemble_grid(surveys, *, names=None, line_spacing_m: float | None = None, direction: str = "x",
                  start_offsets_m=None, serpentine: bool = False, reversed_lines=None, layout: dict | None = None,
                  cross_lines: int = 0, cross_spacing_m: float | None = None, cross_origin_m: float = 0.0):
    """One :class:`~gpr3d.core.survey.Survey` from line surveys (see the module's docstring); ``names`` (default the files' names)
    match ``layout`` entries; the last ``cross_lines`` surveys form the perpendicular set."""
    surveys = list(surveys)
    if len(surveys) < 2:
        raise InvalidDataError(f"a grid needs two lines at least, got {len(surveys)}")
    names = [str(Path(s.metadata.get("path", f"line{k}")).name) for k, s in enumerate(surveys)] if names is None \
        else list(names)
    first = surveys[0]
    for name, s in zip(names, surveys):
        if not np.isclose(s.dt_s, first.dt_s, rtol=1e-9, atol=0.0):
            raise InvalidDataError(f"{name}: samples every {s.dt_s * 1e9:g} ns, but {names[0]} every "
                                   f"{first.dt_s * 1e9:g} ns: lines of one grid must match")
        if abs(s.t0_s - first.t0_s) > 0.5 * first.dt_s:
            raise InvalidDataError(f"{name}: time zero {s.t0_s * 1e9:g} ns, but {names[0]}'s is "
                                   f"{first.t0_s * 1e9:g} ns: correct time zero line by line first (time_zero)")
    ns = min(s.n_samples for s in surveys)  # time zero cut each line a little differently: the common length
    dist = [along_line_distance(s) for s in surveys]
    if (layout is None) == (line_spacing_m is None):
        raise InvalidDataError("give the line spacing or a layout (one of them)")
    if layout is not None:
        missing = [n for n in names if n not in layout]
        if missing:
            raise InvalidDataError(f"the layout has no entry for {', '.join(missing[:3])}"
                                   f"{' ...' if len(missing) > 3 else ''} (its names: {', '.join(list(layout)[:3])})")
        lines = [layout[n] for n in names]
    else:
        n = len(surveys)
        if isinstance(cross_lines, bool) or not isinstance(cross_lines, (int, np.integer)) \
                or not 0 <= cross_lines <= n - 1:
            raise InvalidDataError(f"cross lines must be a count in 0..{n - 1} (the first set keeps one line at "
                                   f"least), got {cross_lines!r}")
        if cross_spacing_m is not None and not (isinstance(cross_spacing_m, (int, float))
                                                and np.isfinite(cross_spacing_m) and cross_spacing_m > 0):
            raise InvalidDataError(f"the cross lines' spacing must be a positive number of metres, got "
                                   f"{cross_spacing_m!r}")
        if not (isinstance(cross_origin_m, (int, float)) and np.isfinite(cross_origin_m)):
            raise InvalidDataError(f"the cross lines' origin must be a finite number of metres, got {cross_origin_m!r}")
        offs = np.zeros(n) if start_offsets_m is None else np.asarray(start_offsets_m, dtype=float).reshape(-1)
        if offs.size != n:
            raise InvalidDataError(f"start offsets: one finite number per line ({n}), got {start_offsets_m!r}")
        back = sorted(reversed_lines or [])
        if any(not isinstance(k, (int, np.integer)) or not 0 <= k < n for k in back):
            raise InvalidDataError(f"reversed lines must be line indices 0..{n - 1}, got {back}")
        m = n - cross_lines
        lengths = [d[-1] for d in dist]
        lines = _lines_from_spacing(lengths[:m], line_spacing_m=line_spacing_m, direction=direction,
                                    start_offsets_m=offs[:m], serpentine=serpentine,
                                    reversed_lines=[k for k in back if k < m])
        if cross_lines:
            other = "y" if direction == "x" else "x"
            cross = _lines_from_spacing(lengths[m:], line_spacing_m=line_spacing_m if cross_spacing_m is None
                                        else cross_spacing_m, direction=other, start_offsets_m=offs[m:],
                                        serpentine=serpentine, reversed_lines=[k - m for k in back if k >= m])
            shift = np.array([cross_origin_m, 0.0]) if direction == "x" else np.array([0.0, cross_origin_m])
            lines += [GridLine(c.start + shift, c.end + shift) for c in cross]
    pos, yaw, first_trace = [], [], []
    for line, d, s in zip(lines, dist, surveys):
        first_trace.append(sum(len(p) for p in pos))
        xy = line.start[None, :] + d[:, None] * line.direction[None, :]
        pos.append(np.hstack([xy, np.zeros((len(d), 1))]))  # on flat ground (elevations: --track, topo_correct)
        yaw.append(np.full(len(d), np.arctan2(line.direction[1], line.direction[0])))
    t0 = [s.t0_s for s in surveys]
    data = np.concatenate([s.data[:, :ns] for s in surveys], axis=0)
    meta = {"format": "grid", "grid": {"files": names, "first_trace": first_trace, "samples_kept": ns,
                                       "lines": [[*ln.start.tolist(), *ln.end.tolist()] for ln in lines],
                                       "t0_s": t0}}
    meta.update({k: v for k, v in first.metadata.items() if k not in ("path", "format")})
    return first.replace(data=data, positions_xyz=np.concatenate(pos), orientations_quat_wxyz=quat_from_yaw(
        np.concatenate(yaw)), timestamps_s=None, t0_s=float(np.median(t0)), metadata=meta, history=[])
