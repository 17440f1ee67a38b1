"""The settings of :func:`gpr3d.migration.reconstruct.reconstruct` (light to import: the command line's defaults)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ReconstructConfig"]


@dataclass
class ReconstructConfig:
    eps_r: float | None = None  #: None: the survey's hint
    #: the voxel size (m); None: the data's, a tenth of the antenna's centre wavelength in the host (to the
    #: millimetre, 2 cm or more; 2 cm at 500 MHz in eps_r 9; 2 cm where the record names no frequency):
    #: ``gpr3d.migration.reconstruct.voxel_spacing_m``
    spacing_m: float | None = None
    depth_spacing_m: float | None = None
    max_depth_m: float | None = None  #: None: what the time window reaches (or its signal: ``signal_depth``)
    #: with no ``max_depth_m``: the grid ends where the traces' signal does (neighbouring traces no longer alike:
    #: :func:`gpr3d.processing.signal.signal_end`), not at the record's end. Off by default: on 13 simulated
    #: scenes and a real grid it saved no time overall and changed the targets of 2 scenes
    #: (``benchmarks/results/signal_depth.md``); worth it on records much deeper than their signal
    signal_depth: bool = False
    pad_m: float = 0.1
    #: voxel centres on whole multiples of the spacing (the grid's corner rounded down to them): the lattice live
    #: mode's tiles share, so that a batch image lands on the same voxels
    lattice: bool = False
    aperture_deg: float | None = 50.0
    #: the aperture's horizontal radius (m): a trace adds only to the columns within it of its tx-rx midpoint, the
    #: cone of ``aperture_deg`` still applying above the depth where it is the narrower (None: the cone alone)
    aperture_m: float | None = None
    obliquity: bool = True
    spreading: bool = True
    time_zero: str = "peak"  #: "peak", "first_break" or "none" (data already start at time zero)
    #: time zero given (s after the first sample): the traces are cut there instead of at an estimate (what live
    #: mode fixes from its first traces, so that a batch run can repeat it)
    time_zero_s: float | None = None
    remove_background: bool = True
    #: None: the mean trace of the whole survey is removed; a number of traces: the mean over a centred moving
    #: window of that many (live mode's background: a trace is final once half a window has followed it)
    background_window: int | None = None
    #: with ``background_window``: the window ends at each trace instead of being centred on it (no trace waits
    #: for later ones: live mode's default)
    background_trailing: bool = False
    normalize: str = "sqrt_fold"  #: divide the image by sqrt(fold) ("sqrt_fold"), by the fold ("fold") or not ("none")
    threshold: float = 0.3
    #: coarse-to-fine imaging (:mod:`gpr3d.migration.refine`): a coarse pass over every few columns, then every
    #: voxel of the depths where its envelope reaches ``refine_level`` x ``threshold`` of the reference level (the
    #: other voxels interpolated from the coarse pass); False: every voxel migrated. On by default: on 13
    #: simulated scenes the same targets to millimetres for 0.67 of the migration's time
    #: (``benchmarks/results/coarse_to_fine.md``)
    coarse_to_fine: bool = True
    refine_level: float = 0.5
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
