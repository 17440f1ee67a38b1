"""From a survey with antenna poses to a 3D image and targets: what ``gpr3d reconstruct`` runs.

Steps: time zero (direct-wave peak) and mean-trace removal; a voxel grid over the
antenna positions; back projection with the survey's (or the given) eps_r; with
boxes, detection-masked migration and the noise map; the image envelope; target
extraction. Outputs: ``volume.h5`` (image, envelope, noise map, grid), ``volume.vti``
(ParaView), ``top.png``, ``front.png``, ``view3d.png``, ``targets.json``, ``config.json``.
"""

from __future__ import annotations

import json
import math
import os
import time
import warnings
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from gpr3d import __version__
from gpr3d.core.atomic import atomic_write_text
from gpr3d.core.errors import GeometryWarning, InvalidDataError
from gpr3d.core.grid import Grid3D
from gpr3d.core.timing import stage
from gpr3d.core.units import C0, velocity_from_eps_r
from gpr3d.migration.config import ReconstructConfig
from gpr3d.migration.masking import box_mask, check_boxes, image_envelope
from gpr3d.migration.operator import BackProjection, antenna_positions
from gpr3d.processing.timezero import shift_traces
from gpr3d.migration.targets import (
    extract_profile_targets,
    extract_targets,
    targets_to_json,
)

__all__ = ["ProfileFrame", "Reconstruction", "ReconstructConfig", "check_site_settings", "grid_depth_m",
           "normalise_by_fold",
           "reconstruct", "record_depth_m", "time_zero_search_s", "volume_targets", "write_reconstruction"]


@dataclass
class Reconstruction:
    """What :func:`reconstruct` returns: float32 volumes of ``grid.shape`` (x, y, depth), the targets, and how
    they were made."""

    image: np.ndarray  #: the migrated image, normalised by the fold as the config says
    envelope: np.ndarray  #: its envelope along depth (what the targets are extracted from)
    noise_map: np.ndarray | None  #: with boxes: the envelope of the data outside them, migrated; else None
    fold: np.ndarray | None  #: how many traces see each voxel (weighted); None with ``normalize="none"``
    grid: Grid3D
    targets: list  #: :class:`gpr3d.migration.targets.Target3D`
    eps_r: float
    config: dict  #: the :class:`ReconstructConfig` as a dict
    n_traces: int
    timings_s: dict
    updates_per_s: float | None  #: traces x voxels / migration seconds
    eps_r_source: str = "given"  #: where eps_r came from (``config.json`` records it)
    #: what coarse-to-fine imaging did (:func:`gpr3d.migration.refine.refined_adjoint`'s info; ``config.json``
    #: records it), or why it did not run; None where it was not asked for
    refine: dict | None = None
    #: None: a 3D image on a world grid; a :class:`ProfileFrame`: one straight profile migrated in 2D, the grid's
    #: x running along the line from ``frame.origin_xy`` (ny = 1, y = 0), targets mapped back to the world
    frame: "ProfileFrame | None" = None
    #: how deep the grid goes and why (:func:`grid_depth_m`; ``config.json``'s ``"depth"``)
    depth: dict | None = None
    #: the voxel size and why (``{"spacing_m", "how"}``: given, or those of ``voxel_spacing_m``; ``config.json``'s
    #: ``"spacing"``)
    spacing: dict | None = None

    def world_points(self, idx) -> np.ndarray:
        """World coordinates ``(n, 3)`` (z = -depth) of voxel indices ``(n, 3)`` (either kind of grid)."""
        pts = self.grid.points(idx)
        if self.frame is None:
            return pts
        return np.column_stack([self.frame.to_world(pts[:, 0], pts[:, 1]), pts[:, 2]])


@dataclass(frozen=True)
class ProfileFrame:
    """A straight profile's own horizontal frame: ``along`` from ``origin_xy`` in ``direction_xy`` (a unit
    vector), ``across`` to its left."""

    origin_xy: tuple
    direction_xy: tuple

    @classmethod
    def fit(cls, positions_xyz) -> "ProfileFrame":
        """The main horizontal direction of ``positions_xyz`` (pointing from the first trace towards the last),
        its origin at the rearmost position's projection onto it (every position has ``along >= 0``)."""
        xy = np.asarray(positions_xyz, dtype=float)[:, :2]
        c = xy.mean(axis=0)
        _, _, vt = np.linalg.svd(xy - c, full_matrices=False)
        d = vt[0]
        if (xy[-1] - xy[0]) @ d < 0:
            d = -d
        o = c + float(((xy - c) @ d).min()) * d
        return cls((float(o[0]), float(o[1])), (float(d[0]), float(d[1])))

    def to_line(self, xyz) -> np.ndarray:
        """``(n, 3)`` world points as ``[along, across, z]``."""
        p = np.asarray(xyz, dtype=float).reshape(-1, 3)
        rel = p[:, :2] - np.asarray(self.origin_xy)
        d = np.asarray(self.direction_xy)
        n = np.array([-d[1], d[0]])
        return np.ascontiguousarray(np.column_stack([rel @ d, rel @ n, p[:, 2]]))

    def to_world(self, along, across=0.0) -> np.ndarray:
        """``(n, 2)`` world x, y of profile coordinates."""
        a = np.asarray(along, dtype=float).reshape(-1)
        c = np.broadcast_to(np.asarray(across, dtype=float), a.shape)
        d = np.asarray(self.direction_xy)
        n = np.array([-d[1], d[0]])
        return np.asarray(self.origin_xy) + a[:, None] * d + c[:, None] * n

    def to_dict(self) -> dict:
        return {"kind": "profile", "origin_xy": list(self.origin_xy), "direction_xy": list(self.direction_xy)}


def check_config(cfg: ReconstructConfig, names: dict | None = None) -> None:
    """One line naming the first setting of ``cfg`` out of its range (before any work); ``names`` maps a setting
    to what the caller calls it (the CLI: ``{"spacing_m": "--spacing", ...}``)."""
    names = names or {}

    def bad(name, must):
        raise InvalidDataError(f"{names.get(name, name)} must be {must}, got {getattr(cfg, name)!r}")

    def number(name, *, positive=False, none_ok=False, lo=None, hi=None, lo_open=False, hi_open=False):
        v = getattr(cfg, name)
        if v is None and none_ok:
            return
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
            bad(name, "a finite number")
        if positive and not v > 0:
            bad(name, "positive")
        if lo is not None and (v < lo or (lo_open and v == lo)):
            bad(name, f"{'>' if lo_open else '>='} {lo}")
        if hi is not None and (v > hi or (hi_open and v == hi)):
            bad(name, f"{'<' if hi_open else '<='} {hi}")

    number("eps_r", none_ok=True, lo=1.0)
    number("time_zero_s", none_ok=True, lo=0.0)
    if cfg.background_window is not None and (isinstance(cfg.background_window, bool)
                                              or not isinstance(cfg.background_window, int)
                                              or cfg.background_window < 2):
        bad("background_window", "a whole number of traces >= 2 (or None: the whole survey)")
    for name in ("spacing_m", "depth_spacing_m", "max_depth_m"):
        number(name, positive=True, none_ok=True)
    number("pad_m", lo=0.0)
    number("aperture_deg", none_ok=True, lo=0.0, hi=90.0, lo_open=True, hi_open=True)
    number("aperture_m", positive=True, none_ok=True)
    number("threshold", lo=0.0, hi=1.0, lo_open=True)  # relative to the image's reference level
    number("min_line_m", lo=0.0)
    number("min_target_depth_m", none_ok=True, lo=0.0)
    number("taper_traces", lo=0.0)
    number("air_gap_m", lo=0.0)
    number("refine_level", lo=0.0, hi=1.0, lo_open=True)
    for name in ("obliquity", "spreading", "remove_background", "lattice", "background_trailing", "coarse_to_fine",
                 "signal_depth"):
        if not isinstance(getattr(cfg, name), bool):
            bad(name, "true or false")
    if cfg.time_zero not in ("peak", "first_break", "none"):
        bad("time_zero", "'peak', 'first_break' or 'none'")
    if cfg.normalize not in ("sqrt_fold", "fold", "none"):
        bad("normalize", "'sqrt_fold', 'fold' or 'none'")
    if cfg.method not in ("backprojection", "pseudo3d"):
        bad("method", "'backprojection' or 'pseudo3d'")
    check_site_settings(cfg)
    if cfg.method == "pseudo3d" and (cfg.tile_m is not None or cfg.workers or cfg.scheduler or cfg.checkpoint):
        bad("method", "'backprojection' for site tiles (pseudo-3D migrates line by line)")
    if cfg.method == "pseudo3d" and cfg.aperture_m is not None:
        bad("method", f"'backprojection' for an aperture radius ({names.get('aperture_m', 'aperture_m')}; "
                      "pseudo-3D's lines take the cone alone)")


def cross_line_extent(positions_xyz) -> float:
    """The spread of the antenna positions across their main horizontal direction (m): the extent along the
    second principal axis (one straight profile: about 0)."""
    xy = np.asarray(positions_xyz, dtype=float)[:, :2]
    if len(xy) < 3:
        return 0.0
    xy = xy - xy.mean(axis=0)
    _, _, vt = np.linalg.svd(xy, full_matrices=False)
    across = xy @ vt[-1]
    return float(across.max() - across.min())


#: bytes per voxel that a reconstruction holds at once (image, fold, envelope, the normalised image, and the
#: accumulators and temporaries of the migration and the envelope)
BYTES_PER_VOXEL = 4 * 8


def check_grid_fits(grid: Grid3D, *, available_bytes: int | None = None) -> None:
    """Refuse a grid whose reconstruction would not fit in this machine's memory, saying how big it would be."""
    need = grid.size * BYTES_PER_VOXEL
    if available_bytes is None:
        try:
            available_bytes = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
        except (ValueError, OSError, AttributeError):  # not a POSIX system: no estimate
            return
    if need > 0.8 * available_bytes:
        raise InvalidDataError(
            f"the grid of {grid.nx} x {grid.ny} x {grid.nd} voxels ({grid.size / 1e6:,.0f} M) would need about "
            f"{need / 2**30:,.1f} GiB, more than this machine's {available_bytes / 2**30:,.1f} GiB can hold: "
            "use a larger --spacing or a smaller --max-depth")


def check_site_settings(cfg: ReconstructConfig) -> None:
    """One line naming a wrong tile size, worker count or scheduler address (before any work)."""
    from gpr3d.migration.sitetiles import check_settings

    check_settings(tile_m=cfg.tile_m, workers=cfg.workers, scheduler=cfg.scheduler)


def _prepare(survey, cfg):
    """Time zero and background removal as ``cfg`` says; returns the survey and how much recording time time zero
    cut from the front (s): a time ``t`` after the recording's first sample is ``t - cut`` after the new first."""
    if survey.positions_xyz is None:
        raise InvalidDataError("the survey has no antenna positions: give --poses (a TUM file, one pose per trace)")
    s = survey
    cut_s = 0.0
    if cfg.time_zero_s is not None:
        if cfg.time_zero_s >= s.time_window_s:
            raise InvalidDataError(f"time_zero_s {cfg.time_zero_s:g} s lies beyond the record "
                                   f"({s.time_window_s:g} s)")
        s = s.replace(data=shift_traces(s.data, cfg.time_zero_s / s.dt_s), t0_s=0.0)
        cut_s = float(cfg.time_zero_s) - survey.t0_s
    elif cfg.time_zero != "none":
        s = s.time_zero(method=cfg.time_zero, search_s=time_zero_search_s(s))
        # the estimate, to a fraction of a sample: the traces were shifted by it, not by whole samples
        cut_s = float(s.history[-1]["result"]["t0_s"]) - s.t0_s
    if cfg.remove_background:
        s = s.remove_background(window_traces=cfg.background_window,
                                trailing=bool(cfg.background_window and cfg.background_trailing))
    return s, cut_s


#: the voxel size where the record names no frequency (m)
FALLBACK_SPACING_M = 0.02
#: the voxel sizes a data-sized grid keeps to (m): never finer than the 2 cm of the fixed grid it replaced (a
#: high-frequency antenna's finer image is asked with ``spacing_m``), never coarser than half a metre
SPACING_RANGE_M = (0.02, 0.5)


def voxel_spacing_m(frequency_hz, eps_r: float) -> tuple[float, str]:
    """The voxel size that follows the data: a tenth of the antenna's centre wavelength in the host, ``c /
    (f sqrt(eps_r)) / 10``, to the millimetre, within ``SPACING_RANGE_M`` (a focused point still spans a few
    voxels; a low-frequency survey is not imaged on voxels far finer than it can resolve), and why;
    ``FALLBACK_SPACING_M`` where ``frequency_hz`` is unknown. 500 MHz in eps_r 9 gives 2 cm, 400 MHz in eps_r 6
    3.1 cm, a 100 MHz survey 8-10 cm."""
    if not (frequency_hz and math.isfinite(frequency_hz) and frequency_hz > 0):
        return FALLBACK_SPACING_M, f"{FALLBACK_SPACING_M:g} m: the record names no antenna frequency"
    wavelength = velocity_from_eps_r(eps_r) / frequency_hz
    tenth = round(wavelength / 10, 3)
    spacing = min(max(tenth, SPACING_RANGE_M[0]), SPACING_RANGE_M[1])
    why = (f"a tenth of the {frequency_hz / 1e6:g} MHz wavelength in the host (eps_r {eps_r:.3g}: {wavelength:.3g} m), "
           "to the millimetre")
    if spacing != tenth:
        why += f", kept to {SPACING_RANGE_M[0]:g}..{SPACING_RANGE_M[1]:g} m"
    return spacing, why


def time_zero_search_s(survey) -> float:
    """How far into the record time zero's direct-wave peak is looked for (s)."""
    return min(survey.time_window_s / 4, 10e-9)


def reconstruct(survey, cfg: ReconstructConfig | None = None, *, boxes=None, log=None, with_noise_map: bool = True,
                with_targets: bool = True) -> "Reconstruction":
    """Migrate ``survey`` in 3D and extract targets (see :class:`Reconstruction`). ``with_noise_map=False``: with
    boxes, the data outside them are not migrated (``noise_map`` None; it costs as much as the image);
    ``with_targets=False``: no targets extracted (an empty list). What a caller that reads only the image needs
    (:func:`gpr3d.migration.velocity.focus_eps`, one image per eps_r tried)."""
    cfg = cfg or ReconstructConfig()
    log = log or (lambda msg: None)
    check_config(cfg)
    eps = cfg.eps_r or survey.eps_r
    if eps is None:
        raise InvalidDataError("no eps_r: the survey has none; give --eps-r")
    if not (np.isfinite(eps) and eps >= 1.0):
        raise InvalidDataError(f"eps_r must be a relative permittivity >= 1, got {eps}")
    if boxes is not None:
        if len(boxes) == 0:
            raise InvalidDataError("no boxes: nothing to migrate inside them (give boxes=None for the whole record)")
        boxes = check_boxes(boxes, survey.n_traces, survey.n_samples * survey.dt_s)
    if cfg.spacing_m is None:  # the grid follows the data: its voxel from the antenna's wavelength
        spacing, how = voxel_spacing_m(survey.frequency_hz, eps)
        cfg = replace(cfg, spacing_m=spacing)
        spacing_info = {"spacing_m": spacing, "how": how}
        log(f"voxels of {spacing * 100:.3g} cm: {how}")
        if cfg.tile_m is not None and cfg.tile_m < 10 * spacing:  # (its margins would cost more than its voxels)
            raise InvalidDataError(f"tile_m must be at least 10 of this record's voxels ({spacing:g} m: {how}), "
                                   f"so {10 * spacing:g} m or more; got {cfg.tile_m:g}")
    else:
        spacing_info = {"spacing_m": float(cfg.spacing_m), "how": "given"}
    t = time.perf_counter()
    with stage("prepare"):
        s, cut_s = _prepare(survey, cfg)
    t_prep = time.perf_counter() - t
    frame = None
    positions = s.positions_xyz
    tx, rx = antenna_positions(s.positions_xyz, s.orientations_quat_wxyz, s.offset_m)
    width = cross_line_extent(s.positions_xyz)
    if cfg.method == "pseudo3d":
        result = _reconstruct_pseudo3d(s, cfg, eps, boxes, t_prep, cut_s, log, with_noise_map, with_targets)
        result.spacing = spacing_info
        return result
    if width < max(2 * cfg.spacing_m, 0.05):
        # one straight profile: a 3D image would mirror every target to both sides of the line; image the
        # vertical plane under the line instead (the same back projection on a grid one cell wide)
        frame = ProfileFrame.fit(s.positions_xyz)
        positions = frame.to_line(s.positions_xyz)
        length = float(np.ptp(positions[:, 0]))
        if length < 2 * cfg.spacing_m:
            raise InvalidDataError(f"the antenna positions all lie within {max(length, width) * 100:.1f} cm: no "
                                   "profile and no area to image")
        tx, rx = frame.to_line(tx), frame.to_line(rx)
        warnings.warn(f"the antenna positions span only {width * 100:.1f} cm across their main direction (one "
                      f"straight profile, {length:.2f} m long): a 3D image cannot tell one side of the line from the "
                      "other, so the profile is migrated in 2D (the vertical plane under it) and targets crossing it "
                      "come out as points on it", GeometryWarning, stacklevel=2)
    v = velocity_from_eps_r(eps)
    depth, depth_info = grid_depth_m(s, cfg, v, positions, log)
    with stage("grid"):
        grid = Grid3D.covering(positions, depth_m=depth, spacing_m=cfg.spacing_m,
                               depth_spacing_m=cfg.depth_spacing_m, pad_m=cfg.pad_m, lattice=cfg.lattice)
        if frame is not None:
            grid = replace(grid, y0=0.0, ny=1)
        check_grid_fits(grid)  # (site tiles too: the whole volume is put together in memory)
        op = BackProjection(grid, tx, rx, dt_s=s.dt_s, n_samples=s.n_samples, t0_s=s.t0_s, eps_r=eps,
                            aperture_deg=cfg.aperture_deg, aperture_m=cfg.aperture_m, obliquity=cfg.obliquity,
                            spreading=cfg.spreading, air_gap_m=cfg.air_gap_m, engine=cfg.engine)
    t = time.perf_counter()
    noise_map = None
    # the fold (how many traces see each voxel inside their aperture and record) comes with the image: in the same
    # pass where the kernel can
    want_fold = cfg.normalize != "none"
    site = cfg.tile_m is not None or cfg.workers or cfg.scheduler or cfg.checkpoint

    refine = _refine_plan(cfg, s, v, frame, site, op) if cfg.coarse_to_fine else None

    def migrate(data, with_fold, part=""):
        if refine is not None and "skipped" not in refine and not part:
            from gpr3d.migration.refine import refined_adjoint

            img, fold, info = refined_adjoint(op, data, with_fold=with_fold, wavelength_m=refine["wavelength_m"],
                                              level=cfg.refine_level * cfg.threshold, normalize=cfg.normalize)
            refine.update(info)
            return (img, fold) if with_fold else img
        if not site:
            return op.adjoint(data, with_fold=with_fold)
        from gpr3d.migration.sitetiles import DEFAULT_TILE_M, migrate_site

        ck = None if cfg.checkpoint is None else str(Path(cfg.checkpoint) / (part or "image"))
        res = migrate_site(op, data, tile_m=cfg.tile_m or DEFAULT_TILE_M, with_fold=with_fold, workers=cfg.workers,
                           scheduler=cfg.scheduler, checkpoint=ck, log=log)
        return (res.image, res.fold) if with_fold else res.image

    if boxes:
        # boxes refer to the recording's samples; time zero cut some: shift them
        shifted = [[b[0], b[1] - cut_s, b[2], b[3] - cut_s] for b in boxes]
        mask = box_mask(s.n_traces, s.n_samples, s.dt_s, shifted, taper_traces=cfg.taper_traces)
        with stage("migrate"):
            out = migrate(s.data * mask, want_fold)
        if with_noise_map:
            with stage("noise map"):
                noise_map = image_envelope(migrate(s.data * (1 - mask), False, "noise"))
    else:
        with stage("migrate"):
            out = migrate(s.data, want_fold)
    image, fold = out if want_fold else (out, None)
    t_mig = time.perf_counter() - t
    if want_fold:
        fold_max = None
        if depth_info["how"] == "signal":
            # the fold's floor is a share of its largest, which the deeper voxels cut away would have held: taken
            # from a coarse fold over the whole record's depth, so that the image above stays what it was
            with stage("fold max"):
                fold_max = max(float(fold.max()), whole_record_fold_max(op, eps, positions, cfg,
                                                                        depth_info["record_m"], frame is not None))
            depth_info["fold_max"] = fold_max
        with stage("fold"):
            image, noise_map = normalise_by_fold(image, fold, cfg.normalize, noise_map, fold_max=fold_max)
    with stage("envelope"):
        env = image_envelope(image)
    with stage("targets"):
        if not with_targets:
            targets = []
        elif frame is None:
            targets = volume_targets(env, grid, cfg, v, survey.frequency_hz)
        else:
            targets = extract_profile_targets(env[:, 0, :], grid.x, grid.depth, threshold=cfg.threshold,
                                              min_line_m=cfg.min_line_m, min_depth_m=cfg.min_target_depth_m)
            for t in targets:  # [along, 0, depth] -> [x, y, depth]
                along = [p[0] for p in t.points_xyz]
                xy = frame.to_world(along)
                t.extra["along_m"] = along
                t.points_xyz = [[float(q[0]), float(q[1]), float(p[2])] for q, p in zip(xy, t.points_xyz)]
    return Reconstruction(image=image, envelope=env, noise_map=noise_map, fold=fold, grid=grid, targets=targets,
                          eps_r=float(eps), config=asdict(cfg), n_traces=s.n_traces,
                          timings_s={"prepare": t_prep, "migrate": t_mig},
                          updates_per_s=s.n_traces * grid.size / t_mig if t_mig > 0 else None, frame=frame,
                          refine=refine, depth=depth_info, spacing=spacing_info)


def _refine_plan(cfg, s, v, frame, site, op) -> dict:
    """Whether coarse-to-fine imaging runs and with what wavelength: ``{"skipped": why}`` where it cannot gain
    anything (a profile, site tiles, no aperture, an engine without depth ranges)."""
    if frame is not None:
        return {"skipped": "one profile, migrated in 2D"}
    if site:
        return {"skipped": "site tiles migrate every voxel"}
    if op.tan_ap <= 0 and op.aperture_m is None:
        return {"skipped": "no aperture: every trace reaches every voxel"}
    if cfg.engine != "numba":
        return {"skipped": f"engine {cfg.engine!r} migrates every voxel"}
    from gpr3d.migration.refine import dominant_frequency_hz

    f_data = dominant_frequency_hz(s.data, s.dt_s)
    f = max(f_data, s.frequency_hz or 0.0)  # the shorter wavelength of the two: the closer coarse columns
    if not f > 0:
        return {"skipped": "the traces carry no frequency to size the coarse pass by"}
    return {"frequency_hz": float(f), "data_frequency_hz": float(f_data), "wavelength_m": float(v / f)}


def normalise_by_fold(image, fold, how: str, noise_map=None, *, fold_max: float | None = None):
    """``image`` (and ``noise_map``) divided by the fold (``how="fold"``) or its square root (``"sqrt_fold"``), the
    fold held at least 5 % of its largest (``fold_max``, default ``fold.max()``) so that the grid's thinly covered
    edges are not blown up. Returns ``(image, noise_map)``."""
    floor = 0.05 * float(fold.max() if fold_max is None else fold_max)
    norm = np.maximum(fold, floor)
    norm = np.sqrt(norm) if how == "sqrt_fold" else norm
    return image / norm, None if noise_map is None else noise_map / norm


def volume_targets(envelope, grid, cfg: ReconstructConfig, v_m_s: float, frequency_hz: float | None,
                   **search) -> list:
    """The targets of a 3D image's envelope as :func:`reconstruct` extracts them (``cfg``'s threshold, shortest
    line and shallowest depth; the band cleared around each line found: half a wavelength, at least two cells);
    ``search``: other settings of :func:`~gpr3d.migration.targets.extract_targets` (live mode's previews take a
    coarser ``angle_step_deg``)."""
    tol = 2.0 * max(grid.dx, grid.dy)
    band = max(2 * tol, 0.5 * v_m_s / frequency_hz) if frequency_hz else None
    return extract_targets(envelope, grid, threshold=cfg.threshold, min_line_m=cfg.min_line_m, band_m=band,
                           min_depth_m=cfg.min_target_depth_m, **search)


def record_depth_m(v_m_s: float, record_s: float, air_gap_m: float = 0.0) -> float:
    """How deep a record of ``record_s`` after time zero reaches at ``v_m_s`` (m): 95 % of half the two-way
    time left once the air gap's is taken off (the grid's default depth)."""
    return 0.5 * v_m_s * (record_s - 2 * air_gap_m / C0) * 0.95


def grid_depth_m(s, cfg: ReconstructConfig, v_m_s: float, positions, log=None) -> tuple[float, dict]:
    """How deep the grid goes, and why: ``cfg.max_depth_m``; else where the signal of the prepared survey ``s``
    ends (``cfg.signal_depth``, :func:`gpr3d.processing.signal.signal_end`), half its two-way time at ``v_m_s``;
    else the record's depth (:func:`record_depth_m`). ``positions``: the traces' (their spacing tells whether
    neighbours can be compared). Returns the depth (m) and ``config.json``'s ``"depth"`` entry."""
    record = record_depth_m(v_m_s, s.n_samples * s.dt_s - s.t0_s, cfg.air_gap_m)
    if cfg.max_depth_m:
        return float(cfg.max_depth_m), {"depth_m": float(cfg.max_depth_m), "record_m": record, "how": "max_depth_m"}
    info = {"depth_m": record, "record_m": record, "how": "record"}
    if not cfg.signal_depth:
        return record, info
    from gpr3d.migration.refine import dominant_frequency_hz
    from gpr3d.processing.signal import signal_end

    with stage("signal depth"):
        f = dominant_frequency_hz(s.data, s.dt_s)
        step = np.linalg.norm(np.diff(np.asarray(positions, dtype=np.float64)[:, :2], axis=0), axis=1)
        median_step = float(np.median(step)) if step.size else 0.0
        if not f > 0:
            why = "the traces carry no frequency to compare them by"
        elif median_step > v_m_s / f / 4:
            why = (f"neighbouring traces lie {median_step * 100:.1f} cm apart, over a quarter wavelength "
                   f"({v_m_s / f / 4 * 100:.1f} cm): their likeness cannot tell signal from noise")
        else:
            end = signal_end(s.data, s.dt_s, f)
            why = end.reason
            info["signal"] = end.to_dict()
            if end.end_s is not None:
                depth = 0.5 * v_m_s * (end.end_s - s.t0_s - 2 * cfg.air_gap_m / C0)
                if 0 < depth < record:
                    info.update(depth_m=depth, how="signal", why=why)
                    if log:
                        log(f"depth range to {depth:.2f} m of the record's {record:.2f} m: {why} (--signal-depth)")
                    return depth, info
    info["why"] = why
    return record, info


def whole_record_fold_max(op: BackProjection, eps_r: float, positions, cfg: ReconstructConfig, record_m: float,
                          profile: bool) -> float:
    """The largest fold of the grid over the whole record's depth (``record_m``) that ``cfg`` would make, with
    ``op``'s geometry and weights: found on a grid three times coarser in every direction (about 1/27 of the
    whole pass's work), then at full resolution in the 7 x 7 x 7 voxels about each of its 16 largest."""
    def covering(k):
        g = Grid3D.covering(positions, depth_m=record_m, spacing_m=k * cfg.spacing_m,
                            depth_spacing_m=k * (cfg.depth_spacing_m or cfg.spacing_m), pad_m=cfg.pad_m,
                            lattice=cfg.lattice)
        return replace(g, y0=0.0, ny=1) if profile else g

    def fold_on(g):
        twin = BackProjection(g, op.tx, op.rx, dt_s=op.dt, n_samples=op.n_samples, t0_s=op.t0, eps_r=eps_r,
                              aperture_deg=cfg.aperture_deg, aperture_m=op.aperture_m, obliquity=op.obliquity,
                              spreading=op.spreading,
                              air_gap_m=op.air_gap, engine=cfg.engine)
        return twin.adjoint(np.zeros((op.n_traces, op.n_samples), np.float32), with_fold=True)[1]

    coarse, full = covering(3), covering(1)
    fold = fold_on(coarse)
    best = float(fold.max())
    # the fold is broad and flat near its largest (several near-equal summits): each of the coarse grid's 16
    # largest voxels is looked at again at full resolution, in the 7 x 7 x 7 voxels about it
    for flat in np.argsort(fold, axis=None)[::-1][:16]:
        i, j, k = np.unravel_index(int(flat), fold.shape)
        near = {}
        for axis, at, n in (("x", coarse.x0 + i * coarse.dx, full.nx), ("y", coarse.y0 + j * coarse.dy, full.ny),
                            ("d", coarse.d0 + k * coarse.dd, full.nd)):
            o, step = getattr(full, axis + "0"), getattr(full, "dd" if axis == "d" else "d" + axis)
            lo = min(max(int(round((at - o) / step)) - 3, 0), max(n - 7, 0))
            near.update({axis + "0": o + lo * step, "n" + axis: min(7, n)})
        best = max(best, float(fold_on(replace(full, **near)).max()))
    return best


def _reconstruct_pseudo3d(s, cfg, eps, boxes, t_prep, cut_s, log, with_noise_map, with_targets) -> "Reconstruction":
    """``reconstruct`` with ``method="pseudo3d"``: the lines of a grid survey migrated one by one (2D Kirchhoff),
    their envelopes interpolated between lines; the same target extraction."""
    from gpr3d.migration.traditional import pseudo3d, survey_lines

    lines = survey_lines(s)
    for k, idx in enumerate(lines):
        d = s.positions_xyz[idx[-1], :2] - s.positions_xyz[idx[0], :2]
        off_axis = np.degrees(np.arctan2(min(abs(d[0]), abs(d[1])), max(abs(d[0]), abs(d[1]), 1e-12)))
        if off_axis > 5.0:
            raise InvalidDataError(f"pseudo-3D needs lines along x or y; line {k} (traces {idx[0]}..{idx[-1]}) runs "
                                   f"{off_axis:.0f} deg off both: use method 'backprojection'")
    if len(lines) < 2:
        raise InvalidDataError(f"pseudo-3D needs two lines at least, the survey has {len(lines)}: migrate one "
                               "profile with 'gpr3d migrate', or use method 'backprojection'")
    v = velocity_from_eps_r(eps)
    depth, depth_info = grid_depth_m(s, cfg, v, s.positions_xyz, log)
    grid = Grid3D.covering(s.positions_xyz, depth_m=depth, spacing_m=cfg.spacing_m,
                           depth_spacing_m=cfg.depth_spacing_m, pad_m=cfg.pad_m, lattice=cfg.lattice)
    check_grid_fits(grid)
    aperture = cfg.aperture_deg if cfg.aperture_deg is not None else 89.0
    t = time.perf_counter()
    noise_map = None
    data = s.data
    if boxes:
        shifted = [[b[0], b[1] - cut_s, b[2], b[3] - cut_s] for b in boxes]
        mask = box_mask(s.n_traces, s.n_samples, s.dt_s, shifted, taper_traces=cfg.taper_traces)
        if with_noise_map:
            noise_map, _ = pseudo3d(s.replace(data=s.data * (1 - mask)), grid, eps_r=eps, aperture_deg=aperture,
                                    engine=cfg.engine, air_gap_m=cfg.air_gap_m)
        data = s.data * mask
    env, _ = pseudo3d(s.replace(data=data), grid, eps_r=eps, aperture_deg=aperture, engine=cfg.engine,
                      air_gap_m=cfg.air_gap_m)
    t_mig = time.perf_counter() - t
    targets = volume_targets(env, grid, cfg, v, s.frequency_hz) if with_targets else []
    # the envelopes of the line images are all there is (no signed 3D image): the image is the envelope
    return Reconstruction(image=env, envelope=env, noise_map=noise_map, fold=None, grid=grid, targets=targets,
                          eps_r=float(eps), config=asdict(cfg), n_traces=s.n_traces,
                          timings_s={"prepare": t_prep, "migrate": t_mig},
                          updates_per_s=None, depth=depth_info)


def write_reconstruction(result: "Reconstruction", out_dir, *, source: str = "") -> list[str]:
    """Write a :class:`Reconstruction`'s data into ``out_dir`` (atomically, file by file): ``volume.h5``
    (:func:`gpr3d.io.volume.write_volume`), ``volume.vti``, ``targets.json`` and ``config.json``. Its figures are
    drawn above the migration, by :func:`gpr3d.pipeline.reconstruction.write_result`."""
    from gpr3d.io.volume import write_volume, write_vti

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    g = result.grid
    frame = None if result.frame is None else json.dumps(result.frame.to_dict())
    with stage("write volume"):
        write_volume(out / "volume.h5", g, {"image": result.image, "envelope": result.envelope,
                                            "noise_map": result.noise_map}, eps_r=result.eps_r, source=source,
                     frame_json=frame)
    with stage("write vti"):
        write_vti(out / "volume.vti", g, {"envelope": result.envelope, "noise_map": result.noise_map})
    atomic_write_text(out / "targets.json", json.dumps(targets_to_json(result.targets), indent=1))
    atomic_write_text(out / "config.json", json.dumps({"gpr3d": __version__, "source": source,
                                                       "eps_r": result.eps_r, "eps_r_source": result.eps_r_source,
                                                       "config": result.config, "grid": g.to_dict(),
                                                       "frame": None if result.frame is None
                                                       else result.frame.to_dict(),
                                                       "spacing": result.spacing, "refine": result.refine,
                                                       "depth": result.depth,
                                                       "timings_s": result.timings_s}, indent=1))
    return sorted(p.name for p in out.iterdir())
