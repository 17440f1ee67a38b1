"""From a survey with antenna poses to a 3D image and targets: what ``gpr3d reconstruct`` runs.

Steps: time zero (direct-wave peak) and mean-trace removal; a voxel grid over the
antenna positions; back projection with the survey's (or the given) eps_r; with
boxes, detection-masked migration and the noise map; the image envelope; target
extraction. Outputs: ``volume.h5`` (image, envelope, noise map, grid), ``volume.vti``
(ParaView), ``top.png``, ``front.png``, ``view3d.png``, ``targets.json``, ``config.json``.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import h5py
import numpy as np

from gpr3d import __version__
from gpr3d.core.errors import InvalidDataError
from gpr3d.core.units import velocity_from_eps_r
from gpr3d.io.atomic import atomic_path, atomic_write_text
from gpr3d.migration.grid import Grid3D
from gpr3d.migration.masking import box_mask, check_boxes, image_envelope
from gpr3d.migration.operator import BackProjection, antenna_positions
from gpr3d.migration.targets import extract_targets, targets_to_json

__all__ = ["ReconstructConfig", "check_site_settings", "reconstruct", "write_reconstruction"]


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
    taper_traces: float = 3.0
    engine: str = "numba"
    #: site scale (see :mod:`.sitetiles`): all unset, the whole grid in one pass; otherwise tiles of ``tile_m``
    #: (m; ``sitetiles.DEFAULT_TILE_M`` where unset), on ``workers`` local Dask processes (0: in this process) or
    #: on the Dask scheduler at ``scheduler``; ``checkpoint``: a folder keeping finished tiles (a rerun resumes)
    tile_m: float | None = None
    workers: int = 0
    scheduler: str | None = None
    checkpoint: str | None = None


def check_site_settings(cfg: ReconstructConfig) -> None:
    """One line naming a wrong tile size, worker count or scheduler address (before any work)."""
    from gpr3d.migration.sitetiles import check_settings

    check_settings(tile_m=cfg.tile_m, workers=cfg.workers, scheduler=cfg.scheduler)


def _prepare(survey, cfg):
    if survey.positions_xyz is None:
        raise InvalidDataError("the survey has no antenna positions: give --poses (a TUM file, one pose per trace)")
    s = survey
    if cfg.time_zero != "none":
        s = s.time_zero(method=cfg.time_zero, search_s=min(s.time_window_s / 4, 10e-9))
    if cfg.remove_background:
        s = s.remove_background()
    return s


def reconstruct(survey, cfg: ReconstructConfig | None = None, *, boxes=None, log=None) -> dict:
    """Migrate ``survey`` in 3D and extract targets; returns a dict of arrays, grid, targets and timings."""
    cfg = cfg or ReconstructConfig()
    log = log or (lambda msg: None)
    check_site_settings(cfg)
    eps = cfg.eps_r or survey.eps_r
    if eps is None:
        raise InvalidDataError("no eps_r: the survey has none; give --eps-r")
    if not (np.isfinite(eps) and eps >= 1.0):
        raise InvalidDataError(f"eps_r must be a relative permittivity >= 1, got {eps}")
    for name in ("spacing_m", "depth_spacing_m", "max_depth_m"):
        val = getattr(cfg, name)
        if val is not None and not (np.isfinite(val) and val > 0):
            raise InvalidDataError(f"{name} must be positive, got {val}")
    if boxes:
        boxes = check_boxes(boxes, survey.n_traces, survey.n_samples * survey.dt_s)
    t = time.perf_counter()
    s = _prepare(survey, cfg)
    t_prep = time.perf_counter() - t
    v = velocity_from_eps_r(eps)
    depth = cfg.max_depth_m or 0.5 * v * (s.n_samples * s.dt_s) * 0.95
    grid = Grid3D.covering(s.positions_xyz, depth_m=depth, spacing_m=cfg.spacing_m,
                           depth_spacing_m=cfg.depth_spacing_m, pad_m=cfg.pad_m)
    tx, rx = antenna_positions(s.positions_xyz, s.orientations_quat_wxyz, s.offset_m)
    op = BackProjection(grid, tx, rx, dt_s=s.dt_s, n_samples=s.n_samples, t0_s=s.t0_s, eps_r=eps,
                        aperture_deg=cfg.aperture_deg, obliquity=cfg.obliquity, spreading=cfg.spreading,
                        engine=cfg.engine)
    t = time.perf_counter()
    noise_map = None
    # the fold (how many traces see each voxel inside their aperture and record) comes with the image: in the same
    # pass where the kernel can
    want_fold = cfg.normalize != "none"
    site = cfg.tile_m is not None or cfg.workers or cfg.scheduler or cfg.checkpoint

    def migrate(data, with_fold, part=""):
        if not site:
            return op.adjoint(data, with_fold=with_fold)
        from gpr3d.migration.sitetiles import DEFAULT_TILE_M, migrate_site

        ck = None if cfg.checkpoint is None else str(Path(cfg.checkpoint) / (part or "image"))
        res = migrate_site(op, data, tile_m=cfg.tile_m or DEFAULT_TILE_M, with_fold=with_fold, workers=cfg.workers,
                           scheduler=cfg.scheduler, checkpoint=ck, log=log)
        return (res.image, res.fold) if with_fold else res.image

    if boxes:
        # boxes refer to the recording's samples; time zero cut some: shift them
        cut = survey.n_samples - s.n_samples
        shifted = [[b[0], b[1] - cut * s.dt_s, b[2], b[3] - cut * s.dt_s] for b in boxes]
        mask = box_mask(s.n_traces, s.n_samples, s.dt_s, shifted, taper_traces=cfg.taper_traces)
        out = migrate(s.data * mask, want_fold)
        noise_map = image_envelope(migrate(s.data * (1 - mask), False, "noise"))
    else:
        out = migrate(s.data, want_fold)
    image, fold = out if want_fold else (out, None)
    t_mig = time.perf_counter() - t
    if want_fold:
        floor = 0.05 * float(fold.max())
        norm = np.maximum(fold, floor)
        norm = np.sqrt(norm) if cfg.normalize == "sqrt_fold" else norm
        image = image / norm
        if noise_map is not None:
            noise_map = noise_map / norm
    env = image_envelope(image)
    targets = extract_targets(env, grid, threshold=cfg.threshold, min_line_m=cfg.min_line_m)
    return {"image": image, "envelope": env, "noise_map": noise_map, "fold": fold, "grid": grid, "targets": targets,
            "eps_r": eps, "config": asdict(cfg), "n_traces": s.n_traces,
            "timings_s": {"prepare": t_prep, "migrate": t_mig},
            "updates_per_s": s.n_traces * grid.size / t_mig if t_mig > 0 else None}


def _figures(result, out: Path):
    from gpr3d.viz._figures import pyplot, save_figure

    plt = pyplot()
    g, env = result["grid"], result["envelope"]
    ext_xy = (g.x[0], g.x[-1], g.y[0], g.y[-1])
    figs = {}
    fig, axes = plt.subplots(1, 2 if result["noise_map"] is not None else 1, figsize=(12 if result["noise_map"]
                                                                                      is not None else 6.5, 6))
    axes = np.atleast_1d(axes)
    axes[0].imshow(env.max(axis=2).T, origin="lower", extent=ext_xy, cmap="hot", aspect="equal")
    for t in result["targets"]:
        p = np.array(t.points_xyz)
        axes[0].plot(p[:, 0], p[:, 1], "c-" if t.kind == "line" else "co", lw=2, ms=5)
    axes[0].set_title("top view: max envelope over depth; cyan: extracted targets", fontsize=9)
    axes[0].set_xlabel("x (m)")
    axes[0].set_ylabel("y (m)")
    if result["noise_map"] is not None:
        axes[1].imshow(result["noise_map"].max(axis=2).T, origin="lower", extent=ext_xy, cmap="hot", aspect="equal")
        axes[1].set_title("noise map: the removed data, migrated", fontsize=9)
        axes[1].set_xlabel("x (m)")
    figs["top.png"] = fig
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.imshow(env.max(axis=1).T, extent=(g.x[0], g.x[-1], g.depth[-1], g.depth[0]), cmap="hot", aspect="auto")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("depth (m)")
    ax.set_title("front view: max envelope over y", fontsize=9)
    figs["front.png"] = fig
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    thr = result["config"]["threshold"] * float(np.percentile(env.max(axis=2), 99.5))
    idx = np.argwhere(env >= thr)
    if len(idx) > 20000:
        idx = idx[np.random.default_rng(0).choice(len(idx), 20000, replace=False)]
    pts = g.points(idx)
    ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], c=env[tuple(idx.T)], cmap="hot", s=2, alpha=0.5)
    for t in result["targets"]:
        p = np.array(t.points_xyz)
        ax.plot(p[:, 0], p[:, 1], -p[:, 2], "b-" if t.kind == "line" else "bo", lw=3)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.set_title("3D: voxels above the threshold, extracted targets (blue)", fontsize=9)
    figs["view3d.png"] = fig
    for name, f in figs.items():
        save_figure(f, out / name, dpi=110)


def write_reconstruction(result: dict, out_dir, *, source: str = "") -> list[str]:
    """Write the outputs of :func:`reconstruct` into ``out_dir`` (atomically, file by file)."""
    from gpr3d.core.deps import require

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    g = result["grid"]
    with atomic_path(out / "volume.h5", suffix=".h5.part") as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs.update({"schema": "gpr3d.volume", "schema_version": 1, "gpr3d_version": __version__,
                            "grid_json": json.dumps(g.to_dict()), "eps_r": result["eps_r"], "source": source,
                            "axes": "x, y, depth (positive down), metres"})
            for k in ("image", "envelope", "noise_map"):
                if result[k] is not None:
                    f.create_dataset(k, data=result[k], compression="gzip", compression_opts=4, shuffle=True)
    evtk = require("pyevtk").hl
    point_data = {"envelope": np.ascontiguousarray(result["envelope"][:, :, ::-1])}
    if result["noise_map"] is not None:
        point_data["noise_map"] = np.ascontiguousarray(result["noise_map"][:, :, ::-1])
    # ParaView: z up, so depth runs downwards from the top of the block
    z_bottom = -(g.d0 + (g.nd - 1) * g.dd)
    with atomic_path(out / "volume.vti", suffix=".part.vti") as tmp:
        written = evtk.imageToVTK(str(tmp)[:-4], origin=(g.x0, g.y0, z_bottom), spacing=(g.dx, g.dy, g.dd),
                                  pointData=point_data)
        Path(written).replace(tmp)
    atomic_write_text(out / "targets.json", json.dumps(targets_to_json(result["targets"]), indent=1))
    atomic_write_text(out / "config.json", json.dumps({"gpr3d": __version__, "source": source,
                                                       "eps_r": result["eps_r"],
                                                       "eps_r_source": result.get("eps_r_source", "given"),
                                                       "config": result["config"], "grid": g.to_dict(), "timings_s": result["timings_s"]},
                                                      indent=1))
    _figures(result, out)
    return sorted(p.name for p in out.iterdir())
