"""Migration velocity analysis: the host's eps_r as the one whose 3D image is the most focused.

A hyperbola fit (or a network) reads eps_r from the shape of one B-scan's hyperbola, which assumes the path
crosses the target at right angles; on a random-motion survey the crossings are oblique, the hyperbolas
stretched, and eps_r comes out low. Back projection from the antenna's true 3D poses has no such assumption:
with the right wave speed every trace's echo lands on the target and the image is sharp, with a wrong one the
echoes smear. The sharpness is measured by the entropy of the image's energy (lower: more focused), over a grid
of eps_r, refined by a parabola through the best three.

The images compared hold the same samples on the same cells of migrated time (``window="time"``): a slower wave
puts a record's time window at a shallower depth, so the depth range and the depth cell follow the wave speed.
On a fixed depth grid (``window="depth"``) a slower wave reads more of the record into the same cells, and the
entropy drifts down at high eps_r: on the demo's survey, 5 cm cells put the best value at the grid's top end
(``benchmarks/results/intel/focus_window.md``).

>>> r = focus_eps(survey, boxes=boxes)                                  # doctest: +SKIP
>>> r["eps_r"]                                                          # doctest: +SKIP
"""

from __future__ import annotations

import numpy as np

from gpr3d.core.errors import InvalidDataError

__all__ = ["focus_eps", "image_entropy"]


def image_entropy(image) -> float:
    """Shannon entropy of an image's normalised energy (lower: more of it in fewer voxels)."""
    e = np.asarray(image, dtype=float).ravel() ** 2
    total = e.sum()
    if not total > 0:
        return float("nan")
    p = e[e > 0] / total
    return float(-(p * np.log(p)).sum())


def focus_eps(survey, *, boxes=None, eps_grid=None, spacing_m: float = 0.04, max_depth_m: float | None = None,
              aperture_deg: float = 50.0, window: str = "time") -> dict:
    """eps_r that focuses the migrated image of ``survey`` best (inside ``boxes`` only, when given).

    ``eps_grid``: the values tried (default 3 to 25, 12 steps even in sqrt(eps_r), i.e. in slowness).
    ``window``: ``"time"`` (every image on the same cells of migrated time: ``spacing_m`` and ``max_depth_m`` are
    the depth cell and depth at the grid's middle eps_r, the geometric mean of its ends, and scale with the wave
    speed, sqrt(middle / eps_r); with no ``max_depth_m`` the record's or its signal's depth scales by itself) or
    ``"depth"`` (one depth grid for all). Returns ``eps_r``, the grid and its entropies, and ``at_edge`` (the best
    lies at an end of the grid: widen it)."""
    from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct

    if window not in ("time", "depth"):
        raise InvalidDataError(f"window must be 'time' or 'depth', got {window!r}")
    grid = (np.linspace(np.sqrt(3.0), np.sqrt(25.0), 12) ** 2 if eps_grid is None
            else np.asarray(eps_grid, dtype=float).reshape(-1))
    if grid.size < 3 or not np.all(np.isfinite(grid)) or np.any(grid < 1.0) or np.any(np.diff(grid) <= 0):
        raise InvalidDataError("eps_grid must hold at least three increasing values >= 1")
    middle = float(np.sqrt(grid[0] * grid[-1]))
    ent = []
    for eps in grid:
        k = float(np.sqrt(middle / eps)) if window == "time" else 1.0
        cfg = ReconstructConfig(eps_r=float(eps), spacing_m=spacing_m, aperture_deg=aperture_deg,
                                depth_spacing_m=None if window == "depth" or spacing_m is None else spacing_m * k,
                                max_depth_m=None if max_depth_m is None else max_depth_m * k,
                                coarse_to_fine=False)  # (the entropy reads every voxel: each one migrated)
        # the envelope is all the entropy reads: no noise map (a second migration) and no targets
        r = reconstruct(survey, cfg, boxes=boxes, with_noise_map=False, with_targets=False)
        ent.append(image_entropy(r.envelope))
    ent = np.array(ent)
    if not np.any(np.isfinite(ent)):
        raise InvalidDataError("the migrated image is empty for every eps_r: no data to focus")
    i = int(np.nanargmin(ent))
    best = float(grid[i])
    if 0 < i < grid.size - 1:  # parabola in sqrt(eps_r) through the best three
        x = np.sqrt(grid[i - 1 : i + 2])
        a, b, _ = np.polyfit(x, ent[i - 1 : i + 2], 2)
        # the middle value is the least (nanargmin takes the first of equals), so the parabola opens upwards and
        # its vertex lies between the neighbours; a neighbour whose image was empty (NaN) leaves the grid value
        if np.isfinite(a):
            best = float((-b / (2 * a)) ** 2)
    return {"eps_r": best, "eps_grid": grid.tolist(), "entropy": ent.tolist(),
            "at_edge": bool(i in (0, grid.size - 1))}
