"""The settings of :func:`gpr3d.migration.reconstruct.reconstruct` (light to import: the command line's defaults)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ReconstructConfig"]


@dataclass
class ReconstructConfig:
    eps_r: float | None = None  #: None: the survey's hint
    spacing_m: float = 0.02
    depth_spacing_m: float | None = None
    max_depth_m: float | None = None  #: None: what the time window reaches
    pad_m: float = 0.1
    aperture_deg: float | None = 50.0
    obliquity: bool = True
    spreading: bool = True
    time_zero: str = "peak"  #: "peak", "first_break" or "none" (data already start at time zero)
    remove_background: bool = True
    normalize: str = "sqrt_fold"  #: divide the image by sqrt(fold) ("sqrt_fold"), by the fold ("fold") or not ("none")
    threshold: float = 0.3
    min_line_m: float = 0.3
    min_target_depth_m: float | None = None  #: no targets shallower (e.g. where the direct wave rings)
    taper_traces: float = 3.0
    #: the antennas' height above the ground (m; an air-launched antenna): the rays refract at the surface
    air_gap_m: float = 0.0
    engine: str = "numba"
    #: "backprojection": every trace migrated into the 3D grid from its pose; "pseudo3d": each straight line (along
    #: x or y) migrated in its vertical plane (2D Kirchhoff), the planes interpolated between lines
    #: (:func:`gpr3d.migration.traditional.pseudo3d`; grid surveys only)
    method: str = "backprojection"
    #: site scale (see :mod:`.sitetiles`): all unset, the whole grid in one pass; otherwise tiles of ``tile_m``
    #: (m; ``sitetiles.DEFAULT_TILE_M`` where unset), on ``workers`` local Dask processes (0: in this process) or
    #: on the Dask scheduler at ``scheduler``; ``checkpoint``: a folder keeping finished tiles (a rerun resumes)
    tile_m: float | None = None
    workers: int = 0
    scheduler: str | None = None
    checkpoint: str | None = None
