"""The last stages: the permittivity settled, the record migrated in 3D from its poses (inside the detected boxes
only, when asked), the targets extracted, and the result folder written as a whole."""

from __future__ import annotations

from dataclasses import dataclass, replace

from gpr3d.core.errors import GPR3DError

__all__ = ["ReconstructionRun", "reconstruct_recording", "write_result", "write_reconstruction_folder"]


@dataclass
class ReconstructionRun:
    """What :func:`reconstruct_recording` gives back.

    Attributes
    ----------
    result : Reconstruction
        The :class:`~gpr3d.migration.reconstruct.Reconstruction` (volume, targets, timings).
    found : dict or None
        The detections (with depths where eps_r was estimated), or None.
    mask : str
        ``"none"`` (the whole record, or the boxes of a file) or ``"detect"``.
    """

    result: object  #: the :class:`~gpr3d.migration.reconstruct.Reconstruction` (volume, targets, timings)
    found: dict | None  #: the detections (with depths where eps_r was estimated), or None
    mask: str  #: ``"none"`` (the whole record, or the boxes of a file) or ``"detect"``


def reconstruct_recording(survey, cfg, *, eps_r=None, boxes_file=None, mask: str = "none", detector=None,
                          depthnet=None, depth: str = "hybrid", trace_spacing_m: float | None = None,
                          radius_m: float | None = None, score: float = 0.5, input_name: str = "the survey",
                          eps_r_source: str | None = None, log=print) -> ReconstructionRun:
    """Migrate a survey that has antenna positions and extract its targets.

    Parameters
    ----------
    survey : Survey
        With ``positions_xyz`` (one pose per trace: :func:`~gpr3d.pipeline.recording.attach_trajectory`).
    cfg : ReconstructConfig
        The migration's settings; its ``eps_r`` is replaced as ``eps_r`` says.
    eps_r : float, "file" or None
        The host's relative permittivity, the file header's, or None: estimated from the data (``depth``).
    boxes_file : str or Path, optional
        Migrate only inside the boxes of this detections file.
    mask : {"none", "detect"}
        ``detect``: run ``detector`` and migrate only inside its boxes.
    detector, depthnet
        As :func:`~gpr3d.pipeline.targets.load_models` gives them (the detector: for ``mask="detect"`` or to estimate eps_r
        without ``boxes_file``; DepthNet for ``depth`` hybrid or net).
    depth : {"hybrid", "net", "fit"}
        How eps_r is estimated when ``eps_r`` is None.
    trace_spacing_m, radius_m
        As :func:`~gpr3d.pipeline.targets.add_depths`.
    score : float
        The detector's score threshold.
    input_name : str
        The recording's name in messages and outputs.
    eps_r_source : str, optional
        Where a given ``eps_r`` came from (e.g. ``"estimated (hybrid)"`` by an earlier stage; default ``"given"``).
    log : callable
        Progress lines (``print``).

    Returns
    -------
    ReconstructionRun

    Raises
    ------
    GPR3DError
        No positions, no eps_r to be had, an empty boxes file, boxes outside the record, no detections.
    """
    from gpr3d.core.timing import stage
    from gpr3d.io.detections import read_boxes
    from gpr3d.migration.reconstruct import reconstruct
    from gpr3d.pipeline.targets import add_depths, targets_from_file

    if mask == "detect" and boxes_file:
        raise GPR3DError("give --boxes or --mask detect, not both")
    if survey.positions_xyz is None:
        raise GPR3DError("the survey has no antenna positions: give --poses (a TUM file, one pose per trace)")
    if eps_r == "file" and survey.eps_r is None:
        raise GPR3DError(f"--eps-r file: {input_name} gives no eps_r; give a number or leave --eps-r out to estimate it")
    estimate = eps_r is None
    cfg = replace(cfg, eps_r=survey.eps_r if eps_r == "file" else eps_r)
    boxes = read_boxes(boxes_file) if boxes_file else None
    if boxes_file and not boxes:
        raise GPR3DError(f"{boxes_file} lists no boxes: nothing to migrate inside them (leave --boxes out to "
                         "migrate the whole record)")
    found = None
    if boxes_file:
        from gpr3d.io.detections import read_detections
        from gpr3d.migration.masking import check_boxes

        check_boxes(boxes, survey.n_traces, survey.n_samples * survey.dt_s)  # one line, before any estimate
        found = {"input": str(input_name),
                 "targets": targets_from_file(boxes_file, read_detections(boxes_file)[0]["targets"], survey)}
    if detector is not None and (mask == "detect" or found is None):
        with stage("detect"):
            found = detector.detect(survey, score_threshold=score, input_name=str(input_name))
    if estimate:
        with stage("depths"):
            add_depths(survey, found, depth, depthnet, trace_spacing_m, radius_m)
        if "permittivity" not in found:
            raise GPR3DError(f"{input_name}: eps_r cannot be estimated without trace positions; give --eps-r "
                             "or --trace-spacing")
        p = found["permittivity"]
        cfg = replace(cfg, eps_r=float(p["eps_r"]))
        parts = "; ".join(f"{k} {p[k]['eps_r']:.2f}" for k in ("net", "fit") if k in p and p[k]["eps_r"] == p[k]["eps_r"])
        header = f"; the file's header says {survey.eps_r:g}" if survey.eps_r else ""
        log(f"eps_r {p['eps_r']:.2f} +- {p['sigma_eps_r']:.2f} estimated from the data ({depth}"
            f"{': ' + parts if parts else ''}){header}")
    else:
        log(f"eps_r {cfg.eps_r:g} ({'the file header' if eps_r == 'file' else eps_r_source or 'given'})")
    if mask == "detect":
        boxes = [t["box"] for t in found["targets"]]
        log(f"detector: {len(boxes)} boxes in {survey.n_traces} traces ({found['wall_s']:.1f} s)")
        if not boxes:
            raise GPR3DError("the detector found no hyperbolas: nothing to migrate (try a lower --score)")
    result = reconstruct(survey, cfg, boxes=boxes, log=log)
    result.eps_r_source = (f"estimated ({depth})" if estimate else "file header" if eps_r == "file"
                           else eps_r_source or "given")
    return ReconstructionRun(result=result, found=found, mask=mask)


def write_reconstruction_folder(run: ReconstructionRun, out, *, source: str, command: str = "reconstruct",
                                figures=None) -> list:
    """Write a reconstruction into the folder ``out`` as one whole (:func:`~gpr3d.io.resultdir.result_folder`):
    the volume, targets, figures, VTI, and the detections where the detector made the mask.

    Parameters
    ----------
    run : ReconstructionRun
        What :func:`reconstruct_recording` gave back.
    out : str or Path
        The folder: replaced as a whole, or left as it was if the writing is interrupted.
    source : str
        The recording's name, kept in the files.
    command : str
        The command named in the folder's manifest.
    figures : FigureWorker, optional
        Draws the figures beside the writing (:class:`~gpr3d.viz.worker.FigureWorker`; None: drawn here).

    Returns
    -------
    list of str
        The files written.
    """
    from gpr3d.core.timing import stage
    from gpr3d.io.resultdir import result_folder

    with stage("write folder"), result_folder(out, command=command) as folder:  # the whole result, or the previous
        if run.mask == "detect":
            from gpr3d.io.detections import write_detections

            write_detections([run.found], folder / "detections.json")
        return write_result(run.result, folder, source=source, figures=figures)


def write_result(result, out, *, source: str = "", figures=None) -> list:
    """A reconstruction's data and its figures, written into the folder ``out`` file by file (each atomically).

    Parameters
    ----------
    result : Reconstruction
        What :func:`~gpr3d.migration.reconstruct.reconstruct` gave back.
    out : str or Path
        The folder (made with its parents where missing).
    source : str
        The recording's name, kept in ``volume.h5`` and ``config.json``.
    figures : FigureWorker, optional
        Draws the figures while the data files are written (:class:`~gpr3d.viz.worker.FigureWorker`; None, or a
        worker that has gone: drawn here, after them).

    Returns
    -------
    list of str
        The names of the files in ``out``: ``volume.h5``, ``volume.vti``, ``targets.json``, ``config.json``
        (:func:`~gpr3d.migration.reconstruct.write_reconstruction`) and the figures of
        :func:`~gpr3d.viz.volume.reconstruction_figures` (``top.png``, ``front.png``, ``view3d.png``).
    """
    from pathlib import Path

    from gpr3d.core.timing import stage
    from gpr3d.migration.reconstruct import write_reconstruction
    from gpr3d.viz.volume import draw_figures, figure_inputs
    from gpr3d.viz.worker import FigureWorker

    worker = figures if figures is not None else FigureWorker(enabled=False)  # (no worker: drawn here, when asked)
    with stage("figures"):  # (with a worker: the views taken and handed over; then the wait below)
        drawn = worker.submit(draw_figures, figure_inputs(result), Path(out))
    write_reconstruction(result, out, source=source)
    with stage("figures"):
        drawn()
    return sorted(p.name for p in Path(out).iterdir())
