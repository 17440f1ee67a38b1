"""Labelled B-scan datasets at scale: ``gpr3d simulate``.

Each sample ``i`` is the scene :func:`~gpr3d.simulation.sampler.sample_scene` ``(seed, i)``
run through an engine, written to ``OUT/samples/{i:06d}/``:

* ``scene.json`` - the scene (with the derived grid step and time window),
* ``bscan.h5`` - the B-scan as a gpr3d Survey (engine, version and inputs in its metadata),
* ``labels.json`` - apexes, boxes, depths (:func:`~gpr3d.simulation.labels.label_scene`),
* ``image.png`` - the detector's input image ('hot' colour map of the absolute background-removed data,
  ``image_height`` rows x one column per trace).

A sample is built in ``OUT/samples/{i:06d}.part-*`` and renamed into place when
complete, so a sample folder either holds everything or does not exist. Re-running
the same command skips finished samples and removes half-built ones: a killed run
loses at most the samples in flight. At the end ``manifest.json`` lists every
sample with the SHA-256 of its files, and ``coco.json`` holds the COCO labels.

Work runs on Dask: a local cluster of ``workers`` processes by default, or the
cluster behind a ``tcp://`` scheduler address.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import time
import uuid
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from gpr3d import __version__
from gpr3d.core.atomic import atomic_write_text, file_sha256
from gpr3d.core.deps import require
from gpr3d.core.errors import GPR3DError
from gpr3d.processing.image import bscan_image  # re-exported: the image.png rendering

__all__ = ["SimulateConfig", "simulate_sample", "build_dataset", "write_manifest", "bscan_image", "PRESETS"]

SAMPLE_FILES = ("scene.json", "bscan.h5", "labels.json", "image.png")

#: scene presets: "standard" = the sampler's ranges (short scenes); "tiny" = small, fast scenes for
#: smoke tests; "survey" = survey-scale scenes of the held-out gprMax set
#: (:func:`~gpr3d.simulation.surveys.sample_gprmax_survey_scene`), run in antenna-following models
#: (:func:`~gpr3d.simulation.gprmax_runner.run_gprmax_following`) that resume trace by trace
PRESETS = ("standard", "tiny", "survey")


@dataclass
class SimulateConfig:
    """What ``gpr3d simulate`` builds."""

    out: str
    n: int = 10
    seed: int = 0
    engine: str = "gprmax"  #: "gprmax" (2D FDTD) or "forward" (fast ray model)
    workers: int = 2
    scheduler: str | None = None  #: tcp://host:port of a running Dask scheduler
    image_height: int = 256
    preset: str = "standard"
    host: str | None = None  #: force "concrete" or "soil"
    start: int = 0  #: first scene index: indices start..n-1 are built
    max_seconds: float | None = None  #: stop waiting after this long; finished samples stay, the rest resume later


def _scene_for(cfg_dict: dict, index: int):
    from gpr3d.simulation.sampler import sample_scene

    if cfg_dict.get("preset") == "survey":
        from gpr3d.simulation.surveys import sample_gprmax_survey_scene

        return sample_gprmax_survey_scene(cfg_dict["seed"], index, host=cfg_dict.get("host"))
    scene = sample_scene(cfg_dict["seed"], index, host=cfg_dict.get("host"))
    if cfg_dict.get("preset") == "tiny":
        # a quarter of the width and depth, 10 traces: seconds in gprMax
        scene.width_m, scene.depth_m = scene.width_m / 2.5, scene.depth_m / 2
        scene.n_traces = 10
        scene.x_start_m = scene.width_m * 0.25
        scene.trace_step_m = scene.width_m * 0.5 / 9
        scene.targets = [t for t in scene.targets[:1]]
        for t in scene.targets:
            t.x_m, t.depth_m = scene.width_m / 2, min(t.depth_m, scene.depth_m / 3)
            t.radius_m = min(t.radius_m, scene.depth_m / 8)
        scene.stones, scene.rough_surface_m = [], 0.0
    return scene


def simulate_sample(cfg_dict: dict, index: int) -> dict:
    """Build sample ``index`` into its folder (atomically); returns ``{"index", "wall_s"}``."""
    from PIL import Image

    from gpr3d.simulation.labels import label_scene

    out = Path(cfg_dict["out"]) / "samples"
    final = out / f"{index:06d}"
    if final.exists():
        return {"index": index, "wall_s": 0.0, "skipped": True}
    part = out / f"{index:06d}.part-{uuid.uuid4().hex[:8]}"
    part.mkdir(parents=True)
    t0 = time.perf_counter()
    try:
        scene = _scene_for(cfg_dict, index)
        if cfg_dict["engine"] == "gprmax" and cfg_dict.get("preset") == "survey":
            from gpr3d.simulation.gprmax_runner import run_gprmax_following

            # traces finished before a kill stay in work/ and are not run again
            work = Path(cfg_dict["out"]) / "work" / f"{index:06d}"
            survey, info = run_gprmax_following(scene, work)
            scene = type(scene).from_dict(survey.metadata["scene"])
        elif cfg_dict["engine"] == "gprmax":
            from gpr3d.simulation.gprmax_runner import run_gprmax

            survey, info = run_gprmax(scene, workdir=part / "gprmax")
            shutil.rmtree(part / "gprmax", ignore_errors=True)
            scene = type(scene).from_dict(survey.metadata["scene"])  # as simulated: steps snapped to the grid
        elif cfg_dict["engine"] == "forward":
            from gpr3d.simulation.forward import simulate_scene_bscan

            survey, info = simulate_scene_bscan(scene)
        else:
            raise GPR3DError(f"unknown engine {cfg_dict['engine']!r} (use 'gprmax' or 'forward')")
        labels = label_scene(scene, survey.n_samples, survey.dt_s)
        (part / "scene.json").write_text(scene.to_json())
        survey.save(part / "bscan.h5")
        (part / "labels.json").write_text(json.dumps({"index": index, "eps_r": scene.medium.eps_r,
                                                      "n_traces": survey.n_traces, "n_samples": survey.n_samples,
                                                      "dt_s": survey.dt_s, "simulation": info,
                                                      "labels": labels}, indent=1))
        Image.fromarray(bscan_image(survey, cfg_dict.get("image_height", 256))).save(part / "image.png")
        os.replace(part, final)  # the sample appears complete, or not at all
        shutil.rmtree(Path(cfg_dict["out"]) / "work" / f"{index:06d}", ignore_errors=True)
    except BaseException:
        shutil.rmtree(part, ignore_errors=True)
        raise
    return {"index": index, "wall_s": time.perf_counter() - t0, "skipped": False}


def _finished(out: Path) -> set[int]:
    d = out / "samples"
    if not d.exists():
        return set()
    return {int(p.name) for p in d.iterdir() if p.is_dir() and p.name.isdigit()}


def _clean_partial(out: Path) -> int:
    d = out / "samples"
    n = 0
    if d.exists():
        for p in d.iterdir():
            if ".part-" in p.name:
                shutil.rmtree(p, ignore_errors=True)
                n += 1
    return n


def write_manifest(out, cfg: SimulateConfig | None = None) -> dict:
    """(Re)write ``manifest.json`` and ``coco.json`` from the sample folders on disk."""
    from gpr3d.io.coco import coco_dataset

    out = Path(out)
    entries, coco_in = [], []
    for index in sorted(_finished(out)):
        d = out / "samples" / f"{index:06d}"
        missing = [f for f in SAMPLE_FILES if not (d / f).exists()]
        if missing:
            raise GPR3DError(f"{d}: sample folder lacks {missing}; delete it and run again")
        lab = json.loads((d / "labels.json").read_text())
        entries.append({"index": index, "files": {f: file_sha256(d / f) for f in SAMPLE_FILES},
                        "n_targets": len(lab["labels"]), "eps_r": lab["eps_r"]})
        coco_in.append({"id": index + 1, "file_name": f"samples/{index:06d}/image.png",
                        "n_traces": lab["n_traces"], "n_samples": lab["n_samples"], "dt_s": lab["dt_s"],
                        "eps_r": lab["eps_r"], "labels": lab["labels"]})
    height = cfg.image_height if cfg else 256
    manifest = {"gpr3d": __version__, "config": asdict(cfg) if cfg else None, "n_samples": len(entries),
                "samples": entries}
    atomic_write_text(out / "manifest.json", json.dumps(manifest, indent=1))
    atomic_write_text(out / "coco.json", json.dumps(coco_dataset(coco_in, height), indent=1))
    return manifest


def _client(cfg: SimulateConfig):
    distributed = require("distributed")
    if cfg.scheduler:
        return distributed.Client(cfg.scheduler), None
    cluster = distributed.LocalCluster(n_workers=cfg.workers, threads_per_worker=1, processes=True,
                                       dashboard_address=":0", silence_logs=40)
    return distributed.Client(cluster), cluster


def build_dataset(cfg: SimulateConfig, *, progress: bool = True, log=print) -> dict:
    """Build (or finish) the dataset described by ``cfg``; returns a summary with throughput."""
    if cfg.n < 1:
        raise GPR3DError(f"--n must be >= 1, got {cfg.n}")
    if not 0 <= cfg.start < cfg.n:
        raise GPR3DError(f"--start must lie in 0..{cfg.n - 1} (below --n), got {cfg.start}")
    if cfg.max_seconds is not None and not cfg.max_seconds > 0:
        raise GPR3DError(f"--max-seconds must be > 0, got {cfg.max_seconds}")
    if cfg.preset not in PRESETS:
        raise GPR3DError(f"unknown preset {cfg.preset!r} (use {', '.join(PRESETS)})")
    if cfg.engine not in ("gprmax", "forward"):
        raise GPR3DError(f"--engine must be gprmax or forward, got {cfg.engine!r}")
    if isinstance(cfg.workers, bool) or not isinstance(cfg.workers, int) or cfg.workers < 1:
        raise GPR3DError(f"--workers must be a whole number >= 1, got {cfg.workers!r}")
    if cfg.scheduler is not None and not re.fullmatch(r"(tcp|tls|ucx)://[^\s:/]+:\d{1,5}", str(cfg.scheduler)):
        raise GPR3DError(f"--scheduler must be an address such as tcp://host:8786, got {cfg.scheduler!r}")
    if not isinstance(cfg.image_height, int) or not 16 <= cfg.image_height <= 4096:
        raise GPR3DError(f"--image-height must be a whole number of pixels from 16 to 4096, got {cfg.image_height!r}")
    if cfg.engine == "gprmax":
        require("gprMax")
    out = Path(cfg.out)
    (out / "samples").mkdir(parents=True, exist_ok=True)
    cfg_path = out / "config.json"
    keys = ("seed", "engine", "preset", "host", "image_height")
    if cfg_path.exists():
        old = json.loads(cfg_path.read_text()).get("config", {})
        clash = [k for k in keys if old.get(k) != getattr(cfg, k)]
        if clash:
            raise GPR3DError(f"{out} holds a dataset made with other settings ({', '.join(clash)}); "
                             "use another --out or the same settings")
    atomic_write_text(cfg_path, json.dumps({"gpr3d": __version__, "config": asdict(cfg)}, indent=1))
    removed = _clean_partial(out)
    if removed:
        log(f"removed {removed} half-built sample(s) from an interrupted run")
    done = _finished(out)
    wanted = range(cfg.start, cfg.n)
    todo = [i for i in wanted if i not in done]
    log(f"{len(wanted)} samples: {len(done & set(wanted))} already built, {len(todo)} to build "
        f"({cfg.engine}, {'scheduler ' + cfg.scheduler if cfg.scheduler else f'{cfg.workers} local worker(s)'})")
    t0 = time.perf_counter()
    walls: list[float] = []
    failures: list[dict] = []
    stopped = 0
    if todo:
        distributed = require("distributed")
        client, cluster = _client(cfg)
        try:
            cfg_dict = asdict(cfg)
            cfg_dict["out"] = str(out.resolve())
            futures = client.map(simulate_sample, [cfg_dict] * len(todo), todo, pure=False)
            bar = None
            if progress:
                from tqdm import tqdm

                bar = tqdm(total=len(todo), unit="sample", desc="simulate")
            try:
                for fut in distributed.as_completed(futures, timeout=cfg.max_seconds):
                    try:
                        res = fut.result()
                        walls.append(res["wall_s"])
                    except Exception as exc:  # noqa: BLE001 - one bad scene must not stop the others
                        idx = todo[futures.index(fut)]
                        failures.append({"index": idx, "error": f"{type(exc).__name__}: {exc}"[:500]})
                        log(f"sample {idx} failed: {failures[-1]['error']}")
                    if bar:
                        bar.update(1)
            except distributed.TimeoutError:  # --max-seconds: the unfinished samples resume on the next run
                stopped = sum(not f.done() for f in futures)
                client.cancel(futures)
                log(f"--max-seconds {cfg.max_seconds:g} reached: {stopped} sample(s) left for the next run")
            if bar:
                bar.close()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    elapsed = time.perf_counter() - t0
    manifest = write_manifest(out, cfg)
    built = len(walls)
    if failures:
        atomic_write_text(out / "failures.json", json.dumps(failures, indent=1))
    elif (out / "failures.json").exists():
        (out / "failures.json").unlink()
    summary = {"n": cfg.n, "built": built, "failed": failures, "left": stopped, "elapsed_s": elapsed,
               "samples_per_s": built / elapsed if built and elapsed > 0 else None,
               "mean_sample_wall_s": float(np.mean(walls)) if walls else None,
               "in_manifest": manifest["n_samples"]}
    log(f"built {built} sample(s) in {elapsed:.1f} s; manifest lists {manifest['n_samples']}")
    if failures:
        raise GPR3DError(f"{len(failures)} sample(s) failed (see {out / 'failures.json'}); run again to retry them")
    return summary
