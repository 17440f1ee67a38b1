"""``gpr3d run``: the whole road in one call, resumable stage by stage.

    OUT/survey.h5          the recording, its traces placed (poses, a fused IMU/odometry recording, a track or a spacing)
    OUT/detections.json    the hyperbolas found, the host eps_r and each target's depth
    OUT/reconstruction/    the migration inside the detected boxes and the targets (a result folder, one whole)
    OUT/summary.json       what was found
    OUT/report.html        the page to open in a browser (pipeline.report)
    OUT/run.json           the stages done: each with the key of its inputs and settings and the SHA-256 of its files

A re-run with the same inputs and settings keeps every stage whose key and files still match and runs the rest; a
stage whose inputs changed is run again, and the stages after it too.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from gpr3d.core.errors import GPR3DError
from gpr3d.core.timing import stage

__all__ = ["RunConfig", "run_pipeline", "STAGES"]

#: the stages in order, each with the files it leaves in OUT
STAGES = {"survey": ["survey.h5"], "detections": ["detections.json"], "reconstruction": ["reconstruction"]}
JOURNAL = "run.json"


@dataclass(frozen=True)
class RunConfig:
    """The settings of :func:`run_pipeline` (every field a plain value: the journal keys them)."""

    input: str  #: the radar file
    out: str  #: the run folder
    format: str | None = None  #: force a reader
    channel: int = 0  #: channel of a multi-channel file
    poses: str | None = None  #: a trajectory file, one antenna pose per trace (TUM, EuRoC or CSV)
    imu: str | None = None  #: an IMU recording (CSV) to fuse (with ``odometry``, ``wheel``, ``rig``), by time
    odometry: str | None = None  #: camera poses beside ``imu``
    wheel: str | None = None  #: survey-wheel distances beside ``imu``
    rig: str | None = None  #: the rig file beside ``imu``
    track: str | None = None  #: a surveyed track the traces are placed on
    trace_spacing_m: float | None = None  #: a straight line of this trace spacing, where the file has no positions
    eps_r: float | str | None = None  #: the host's eps_r, ``"file"`` (the header's) or None (estimated)
    depth: str = "hybrid"  #: how eps_r and the depths are estimated: hybrid, net or fit
    score: float = 0.5  #: the detector's score threshold
    weights: str | None = None  #: detector weights (default: the shipped ones)
    depthnet: str | None = None  #: DepthNet weights (default: the shipped ones)
    refiner: str | None = "auto"  #: the box refiner: auto (the shipped one with the shipped detector), none, or a file
    device: str = "cpu"  #: cpu, cuda, cuda:N
    runtime: str = "auto"  #: the detector's runtime
    reconstruct: dict = field(default_factory=dict)  #: ReconstructConfig settings (spacing_m, max_depth_m, ...)


def _sha(path) -> str | None:
    from gpr3d.core.atomic import file_sha256

    return None if path is None else file_sha256(path)


def _models_key(cfg) -> dict:
    """The detection stage's models as file hashes: the files named, and where the shipped ones are used (no
    --weights, --refiner auto, no --depthnet) the shipped files themselves, so that a gpr3d that ships other
    models makes the detections again rather than keeping those of the old ones."""
    from gpr3d.detection.ort import DEFAULT_ONNX
    from gpr3d.detection.refine import (DEFAULT_FINE_REFINER, DEFAULT_FINE_REFINER_ONNX, DEFAULT_REFINER,
                                        DEFAULT_REFINER_ONNX)
    from gpr3d.detection.weights import DEFAULT_WEIGHTS
    from gpr3d.inversion.depthnet import DEFAULT_DEPTHNET

    def shipped(*paths):
        return [_sha(x) if Path(x).is_file() else None for x in paths]

    shipped_net = cfg.weights is None
    refiner = cfg.refiner
    if refiner == "auto" and shipped_net:
        refiner = shipped(DEFAULT_REFINER, DEFAULT_REFINER_ONNX, DEFAULT_FINE_REFINER, DEFAULT_FINE_REFINER_ONNX)
    elif refiner not in (None, "auto", "none"):
        refiner = _sha(refiner)
    return {"weights": shipped(DEFAULT_WEIGHTS, DEFAULT_ONNX) if shipped_net else _sha(cfg.weights),
            "refiner": refiner,
            "depthnet": shipped(DEFAULT_DEPTHNET) if cfg.depthnet is None else _sha(cfg.depthnet)}


def _key(*parts) -> str:
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _files_sha(out: Path, names) -> dict:
    from gpr3d.core.atomic import file_sha256

    got = {}
    for n in names:
        p = out / n
        for f in sorted(p.rglob("*")) if p.is_dir() else [p]:
            if f.is_file():
                got[str(f.relative_to(out))] = file_sha256(f)
    return got


class _Journal:
    def __init__(self, out: Path):
        self.out, self.path = out, out / JOURNAL
        self.stages = {}
        if self.path.exists():
            try:
                self.stages = json.loads(self.path.read_text())["stages"]
            except (ValueError, KeyError, TypeError):
                self.stages = {}  # a journal that cannot be read: every stage is run again

    def done(self, stage: str, key: str) -> bool:
        s = self.stages.get(stage)
        if not s or s.get("key") != key or not s.get("files"):
            return False
        try:
            return _files_sha(self.out, STAGES[stage]) == s["files"]
        except OSError:
            return False

    def begin(self, stage: str) -> None:
        """Forget ``stage`` and those after it on disk before its files are written again: a run killed while
        it writes them leaves a journal that names only stages whose files are whole."""
        later = list(STAGES)[list(STAGES).index(stage):]
        if any(n in self.stages for n in later):
            for n in later:
                self.stages.pop(n, None)
            self._write()

    def record(self, stage: str, key: str, wall_s: float, line: str) -> None:
        self.stages[stage] = {"key": key, "files": _files_sha(self.out, STAGES[stage]), "wall_s": round(wall_s, 3),
                              "line": line}
        for later in list(STAGES)[list(STAGES).index(stage) + 1:]:
            self.stages.pop(later, None)  # what came after was made from the old result
        self._write()

    def _write(self) -> None:
        from gpr3d.core.atomic import atomic_write_text

        atomic_write_text(self.path, json.dumps({"version": 1, "stages": self.stages}, indent=1))


def check_run_config(cfg: RunConfig) -> None:
    """One line for a wrong setting, before any work."""
    import math

    sources = [n for n in ("poses", "imu", "track") if getattr(cfg, n)]
    if len(sources) > 1:
        raise GPR3DError(f"give one of --poses, --imu, --track (each places the traces), not {' and '.join(sources)}")
    if cfg.trace_spacing_m is not None and (cfg.poses or cfg.imu):
        raise GPR3DError(f"--trace-spacing places the traces on a straight line: leave it out with "
                         f"--{'poses' if cfg.poses else 'imu'} (or give --track with it)")
    if (cfg.odometry or cfg.wheel or cfg.rig) and not cfg.imu:
        raise GPR3DError("--odometry, --wheel and --rig are fused with an IMU recording: give --imu")
    if cfg.trace_spacing_m is not None and not (math.isfinite(cfg.trace_spacing_m) and 0 < cfg.trace_spacing_m <= 10):
        raise GPR3DError(f"--trace-spacing must be a distance in metres (0..10], got {cfg.trace_spacing_m:g}")
    if cfg.depth not in ("hybrid", "net", "fit"):
        raise GPR3DError(f"--depth must be hybrid, net or fit, got {cfg.depth!r}")
    if not 0.0 <= cfg.score <= 1.0:
        raise GPR3DError(f"--score must lie in 0..1, got {cfg.score}")
    for n in ("input", "poses", "imu", "odometry", "wheel", "rig", "track", "weights", "depthnet"):
        v = getattr(cfg, n)
        if v is not None and not Path(v).exists():
            raise GPR3DError(f"--{n.replace('_', '-')} {v}: no such file" if n != "input" else f"{v}: no such file")
    if cfg.refiner not in (None, "auto", "none") and not Path(cfg.refiner).is_file():
        raise GPR3DError(f"--refiner {cfg.refiner}: no such file (or auto, none)")


def _survey_stage(cfg: RunConfig, out: Path, log):
    from gpr3d.pipeline.recording import attach_trajectory, place_traces, read_recording

    s = read_recording(cfg.input, format=cfg.format, channel=cfg.channel)
    how = s.metadata.get("positions_source") or "the file's positions"
    if cfg.trace_spacing_m is not None:  # (a straight line; a --track then bends it along the surveyed points)
        x = cfg.trace_spacing_m * np.arange(s.n_traces)
        s = s.replace(positions_xyz=np.c_[x, np.zeros_like(x), np.zeros_like(x)])
        s.metadata["positions_source"] = f"a straight line, {cfg.trace_spacing_m:g} m between traces"
        how = f"a straight line of {cfg.trace_spacing_m:g} m trace spacing"
    if cfg.track:
        s = place_traces(s, track=cfg.track)
        how = f"the track {Path(cfg.track).name}" + (f" at {cfg.trace_spacing_m:g} m spacing"
                                                     if cfg.trace_spacing_m is not None else "")
    elif cfg.poses:
        s = attach_trajectory(s, cfg.poses, source=str(cfg.input))
        how = f"poses from {Path(cfg.poses).name}"
    elif cfg.imu:
        from gpr3d.io.trajectory import attach_poses
        from gpr3d.pipeline.poses import fuse_recordings, poses_at_traces

        if s.timestamps_s is None:
            raise GPR3DError(f"{cfg.input} has no trace times: the fused poses cannot be given to its traces "
                             "(give --poses, one per trace)")
        with stage("poses"):  # (the fusion: the whole IMU recording through the filter and its smoother)
            fused = fuse_recordings(imu=cfg.imu, odometry=cfg.odometry, wheel=cfg.wheel, rig=cfg.rig, log=log)
            s = attach_poses(s, poses_at_traces(fused.trajectory, s, source=str(cfg.input)), by="index")
        how = f"poses fused from {Path(cfg.imu).name}" + (f" and {Path(cfg.odometry).name}" if cfg.odometry else "")
    if s.positions_xyz is None:
        raise GPR3DError(f"{cfg.input} holds no trace positions: give --poses, --imu, --track or --trace-spacing")
    with stage("write survey"):
        s.save(out / "survey.h5")
    return f"{s.n_traces} traces x {s.n_samples} samples, placed by {how}"


def _detections_stage(cfg: RunConfig, out: Path, log):
    import gpr3d
    from gpr3d.io.detections import write_detections
    from gpr3d.pipeline.targets import add_depths, load_models

    estimate = cfg.eps_r is None  # (a given eps_r: the depths come from the migration)
    det, net = load_models(detector=True, depth=cfg.depth if estimate else "none", weights=cfg.weights,
                           depthnet=cfg.depthnet, device=cfg.device, runtime=cfg.runtime, refiner=cfg.refiner)
    s = gpr3d.read(out / "survey.h5")
    found = det.detect(s, score_threshold=cfg.score, input_name=str(cfg.input))
    if estimate and (found["targets"] or cfg.depth != "fit"):
        with stage("depths"):
            add_depths(s, found, cfg.depth, net, None)
    write_detections([found], out / "detections.json")
    p = found.get("permittivity")
    eps = f"; host eps_r {p['eps_r']:.2f} +- {p['sigma_eps_r']:.2f} ({cfg.depth})" if p else ""
    return f"{len(found['targets'])} hyperbolas{eps}"


def _reconstruction_stage(cfg: RunConfig, out: Path, log, figures=None):
    import gpr3d
    from gpr3d.io.detections import read_detections
    from gpr3d.migration.reconstruct import ReconstructConfig
    from gpr3d.pipeline.reconstruction import (
        reconstruct_recording,
        write_reconstruction_folder,
    )

    s = gpr3d.read(out / "survey.h5")
    found = read_detections(out / "detections.json")[0]
    eps, source = cfg.eps_r, None
    if eps is None:
        p = found.get("permittivity")
        if not p or not np.isfinite(p["eps_r"]):
            raise GPR3DError(f"{cfg.input}: no eps_r could be estimated (no hyperbolas): give --eps-r")
        eps, source = float(p["eps_r"]), f"estimated ({cfg.depth}, detections.json)"
    if not found["targets"]:
        raise GPR3DError("the detector found no hyperbolas: nothing to migrate (try a lower --score)")
    run = reconstruct_recording(s, ReconstructConfig(**cfg.reconstruct), eps_r=eps,
                                boxes_file=out / "detections.json", input_name=str(cfg.input), eps_r_source=source,
                                log=log)
    write_reconstruction_folder(run, out / "reconstruction", source=str(cfg.input), command="run", figures=figures)
    return f"{len(run.result.targets)} targets, eps_r {run.result.eps_r:.2f} ({run.result.eps_r_source})"


def run_pipeline(cfg: RunConfig, *, log=print, progress: bool | None = None, figures=None) -> dict:
    """Run (or finish) the whole road for one recording; see the module's text for the folder it fills.

    Parameters
    ----------
    cfg : RunConfig
    log : callable
        Progress lines, one per stage.
    progress : bool, optional
        A progress bar over the stages on stderr, named after the one running (None: where stderr is a
        terminal). The lines of ``log`` come either way.
    figures : FigureWorker, optional
        Draws the reconstruction's figures while its data files are written (:class:`~gpr3d.viz.worker.FigureWorker`,
        started before anything else; None: drawn here).

    Returns
    -------
    dict
        The summary (also in ``OUT/summary.json``): each stage's line and whether it was kept, the targets.

    Raises
    ------
    GPR3DError
        A wrong setting (before any work), or a stage that cannot go on (one line).
    """
    from gpr3d.core.atomic import atomic_write_text

    check_run_config(cfg)
    out = Path(cfg.out)
    if out.exists() and not out.is_dir():
        raise GPR3DError(f"--out {out} is a file; run writes a folder")
    out.mkdir(parents=True, exist_ok=True)
    journal = _Journal(out)
    files = {n: _sha(getattr(cfg, n)) for n in ("input", "poses", "imu", "odometry", "wheel", "rig", "track")}
    settings = asdict(cfg)
    settings.pop("out")
    keys = {}
    keys["survey"] = _key("survey", files, {k: settings[k] for k in ("format", "channel", "trace_spacing_m")})
    keys["detections"] = _key("detections", keys["survey"], _models_key(cfg),
                              {k: settings[k] for k in ("eps_r", "depth", "score")})
    keys["reconstruction"] = _key("reconstruction", keys["detections"], {k: settings[k] for k in ("eps_r", "reconstruct")})
    work = {"survey": _survey_stage, "detections": _detections_stage,
            "reconstruction": lambda *a: _reconstruction_stage(*a, figures=figures)}
    lines = {}
    from tqdm import tqdm

    bar = tqdm(total=len(work), unit="stage", disable=None if progress is None else not progress, leave=False,
               mininterval=0)  # (three updates: each one drawn, a stage kept in a millisecond too)
    try:
        for k, (stage, fn) in enumerate(work.items(), 1):
            bar.set_description(f"gpr3d run: {stage}")
            if journal.done(stage, keys[stage]):
                lines[stage] = {"kept": True, "line": journal.stages[stage].get("line", "")}
                log(f"[{k}/{len(work)}] {stage}: kept from an earlier run ({lines[stage]['line']})")
                bar.update(1)
                continue
            journal.begin(stage)  # (before its files change: a kill from here on leaves it unnamed)
            t0 = time.perf_counter()
            line = fn(cfg, out, log)
            wall = time.perf_counter() - t0
            journal.record(stage, keys[stage], wall, line)
            lines[stage] = {"kept": False, "line": line, "wall_s": wall}
            log(f"[{k}/{len(work)}] {stage}: {line} ({wall:.1f} s)")
            bar.update(1)
    finally:
        bar.close()
    targets = json.loads((out / "reconstruction" / "targets.json").read_text())
    summary = {"input": str(cfg.input), "stages": lines, "targets": targets.get("targets", [])}
    from gpr3d.pipeline.report import write_report

    t0 = time.perf_counter()
    page = write_report(out)
    log(f"report: {page} ({time.perf_counter() - t0:.1f} s; opens offline in a browser)")
    summary["report"] = str(page)
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1))
    return summary
