"""The commands' shared parts: the parser class, argument groups, and the checks every command makes before its work
(a wrong value: one line naming it)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from gpr3d.core.errors import GPR3DError


class _Parser(argparse.ArgumentParser):
    """An epilog given as a function is made when the help is shown (the steps' list imports all of processing)."""

    def format_help(self):
        if callable(self.epilog):
            self.epilog = self.epilog()
        return super().format_help()

    def error(self, message):
        """One line: what is wrong, and where the usage is (argparse would print the whole usage first)."""
        self.exit(2, f"{self.prog}: error: {message} (usage: {self.prog} --help)\n")


def _steps_help() -> str:
    from gpr3d.processing.steps import describe_steps

    return "processing steps, each NAME[:key=value[:key=value]] (SI units); known steps:\n" + describe_steps()


def _check_marks_args(args) -> None:
    """One line for a wrong --marks-every / --marks (before any file is read)."""
    every, marks = getattr(args, "marks_every", None), getattr(args, "marks", None)
    if marks is not None and every is None:
        raise GPR3DError("--marks needs --marks-every (the distance between two marks)")
    if every is not None and not (math.isfinite(every) and every > 0):
        raise GPR3DError(f"--marks-every must be a positive distance in metres, got {every:g}")
    if every is not None and getattr(args, "track", None):
        raise GPR3DError("give --track or --marks-every, not both (each places the traces)")
    if isinstance(marks, str):
        args.marks = _number_list(marks, "--marks", int)


def _read_channel(args):
    """The recording an ``add_input`` command names, its traces placed as ``add_track``'s options say."""
    from gpr3d.pipeline import read_recording

    return read_recording(args.input, format=args.format, channel=args.channel, track=getattr(args, "track", None),
                          marks_every_m=getattr(args, "marks_every", None), marks=getattr(args, "marks", None))


def _writable(path, what: str) -> None:
    """Refuse (before any work, leaving nothing behind) an output whose folder cannot be made or written: a trial
    folder is made and removed in the nearest folder that exists (permissions alone do not tell, e.g. for root)."""
    import tempfile

    target = Path(path).absolute()
    base = target if target.is_dir() else target.parent
    while not base.exists():
        base = base.parent
    if not base.is_dir():
        raise GPR3DError(f"{what} {path}: {base} is a file, not a folder")
    try:
        Path(tempfile.mkdtemp(prefix=".gpr3d-write-test-", dir=base)).rmdir()
    except OSError as exc:
        raise GPR3DError(f"{what} {path}: cannot write in {base} ({exc.strerror or exc})") from None


def _out_folder(path, command) -> Path:
    """``--out`` of a command that writes a folder: refused (before any work) where it names a file or cannot be
    written."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise GPR3DError(f"--out {out} is a file; {command} writes a folder (give a new or existing folder)")
    _writable(out, "--out")
    return out


def _number_list(text, what, kind=float):
    if not text:
        return None
    try:
        return [kind(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise GPR3DError(f"{what} must be a comma-separated list of {'whole numbers' if kind is int else 'numbers'}, "
                         f"got {text!r}") from None


def _eps_argument(value):
    """``--eps-r``: None (estimate from the data), ``"file"`` (the header's) or a number >= 1."""
    if value is None or value == "file":
        return value
    try:
        eps = float(value)
    except ValueError:
        raise GPR3DError(f"--eps-r must be a relative permittivity >= 1 or 'file', got {value!r}") from None
    if not (eps >= 1.0 and eps < 1e4):
        raise GPR3DError(f"--eps-r must be a relative permittivity >= 1 or 'file', got {value!r}")
    return eps


def _check_suffix(path, suffixes, what):
    """An output file's name: its suffix, and a folder it can be written in (before any work)."""
    if path and Path(path).suffix.lower() not in suffixes:
        raise GPR3DError(f"{what} {path}: expected a {' or '.join(suffixes)} file")
    if path:
        _writable(path, what)


def _detector(args):
    from gpr3d.detection.infer import load_detector

    if not 0.0 <= args.score <= 1.0:
        raise GPR3DError(f"--score must lie in 0..1, got {args.score}")
    scales = _trace_scales(getattr(args, "trace_scales", None))
    passes, mirror_off = getattr(args, "refine_passes", None), bool(getattr(args, "no_refine_mirror", False))
    rule, weight = getattr(args, "box_rule", "auto"), getattr(args, "quality_weight", None)
    dup = _duplicate_iou(getattr(args, "duplicate_iou", None))
    fine = getattr(args, "fine_refiner", "auto")
    if passes is not None and not 1 <= passes <= 5:
        raise GPR3DError(f"--refine-passes must be a whole number in 1..5, got {passes}")
    if weight is not None and not 0.0 <= weight <= 8.0:
        raise GPR3DError(f"--quality-weight must be a number in 0..8, got {weight}")
    how = passes is not None or mirror_off or rule != "auto" or weight is not None or dup != "default" \
        or fine != "auto"
    flags = "--refine-passes, --no-refine-mirror, --box-rule, --quality-weight, --duplicate-iou and --fine-refiner"
    if fine not in ("auto", "none") and not Path(fine).is_file():
        raise GPR3DError(f"--fine-refiner {fine}: no such file")
    if how and args.refiner == "none":
        raise GPR3DError(f"{flags} say how the box refiner is applied: not with --refiner none")
    det = load_detector(args.weights, device=args.device, engine=args.runtime, refiner=args.refiner,
                        refine_passes=passes, refine_mirror=False if mirror_off else None, box_rule=rule,
                        quality_weight=weight, fine_refiner=fine)
    if how and det.refiner is None:
        raise GPR3DError(f"{flags} say how the box refiner is applied: these weights come without one (give "
                         "--refiner default or a refiner's file)")
    if dup != "default":
        det.duplicate_iou = dup
    if "auto" in scales and not det.reference_width:
        raise GPR3DError("--trace-scales auto needs a detector that knows how wide its training records' features "
                         "were (weights fine-tuned by references/detection/finetune_pgpr.py); these weights do not")
    det.trace_scales, det.mirror = scales, bool(getattr(args, "mirror", False))
    return det


def _duplicate_iou(text):
    """``--duplicate-iou``: ``"default"`` when not given, None for ``none``, else the overlap in (0, 1]."""
    if text is None:
        return "default"
    if text.strip().lower() == "none":
        return None
    try:
        v = float(text)
    except ValueError:
        v = float("nan")
    if not 0.0 < v <= 1.0:  # (NaN fails too)
        raise GPR3DError(f"--duplicate-iou must be an overlap in (0, 1] or none, got {text!r}")
    return v


def _trace_scales(text) -> tuple:
    """``--trace-scales``: factors in 0.25..4 separated by commas (None: ``(1.0,)``, the record as it is)."""
    if text is None:
        return (1.0,)
    try:
        scales = tuple(v if v == "auto" else float(v) for v in str(text).split(","))
    except ValueError:
        scales = ()
    if not scales or not all(v == "auto" or (math.isfinite(v) and 0.25 <= v <= 4.0) for v in scales) \
            or len(set(scales)) < len(scales):
        raise GPR3DError(f"--trace-scales must be different factors in 0.25..4 or auto, separated by commas (e.g. "
                         f"1,2 or 1,auto), got {text!r}")
    return scales


def _check_radius(args, method: str) -> None:
    """``--radius``: a number of metres in 0..50, for a method that fits hyperbolas."""
    import math

    r = args.radius
    if r is None:
        return
    if not (math.isfinite(r) and 0.0 <= r <= 50.0):
        raise GPR3DError(f"--radius must be a radius in metres in 0..50, got {r}")
    if method not in ("fit", "hybrid"):
        raise GPR3DError(f"--radius is used by the hyperbola fit: give it with fit or hybrid, not {method}")


def _in_range(value, flag: str, lo, hi, what: str) -> None:
    """One line for a numeric option outside its plausible range (None: not given, nothing to check)."""
    if value is None:
        return
    if not (math.isfinite(value) and lo <= value <= hi):
        raise GPR3DError(f"{flag} must be {what} ({lo:g}..{hi:g}), got {value:g}")


def _names_list(text):
    """``"a,b"`` -> ``["a", "b"]`` (``None`` stays ``None``); an empty name is refused."""
    if text is None:
        return None
    names = [n.strip() for n in str(text).split(",")]
    if not all(names):
        raise GPR3DError(f"a list of names must be comma-separated words, got {text!r}")
    return names


def _read_labels(args, path, split: str = "train"):
    from gpr3d.io.labelled import read_labelled

    return read_labelled(path, pixel_map=args.pixel_map, split=split, names=_names_list(args.class_names),
                         kinds=args.class_kinds, frequency_hz=args.labels_frequency)


def _reconstruct_defaults():
    """The library's reconstruction defaults (the CLI's defaults come from them, so the two cannot drift apart)."""
    from gpr3d.migration.config import ReconstructConfig

    return ReconstructConfig()


def add_detector_args(sp):
    sp.add_argument("--weights", default=None, help="detector weights (default: the shipped model)")
    sp.add_argument("--score", type=float, default=0.5, help="keep detections scoring at least this (0..1)")
    sp.add_argument("--device", default="cpu", help="cpu (default), cuda, cuda:N")
    sp.add_argument("--refiner", default="auto", help="box refiner that places the boxes by a label rule: auto "
                    "(default: the shipped one with the shipped detector, none with --weights), none, or a "
                    "refiner's .pt/.onnx file")
    sp.add_argument("--runtime", default="auto", choices=("auto", "torch", "onnx", "int8"),
                    help="auto (default: ONNX Runtime for the shipped model on the CPU, else PyTorch), "
                         "torch, onnx (an .onnx export; no PyTorch import, faster start), or int8 (the shipped "
                         "model's 8-bit graph: about 0.7x the time a window)")


def add_view_args(sp):
    sp.add_argument("--mirror", action="store_true",
                    help="also detect each record with its traces reversed and fuse the boxes (twice the network's "
                         "time; on P-GPR's real B-scans +0.015 mAP@0.5)")
    sp.add_argument("--trace-scales", default=None, metavar="F,F",
                    help="also detect each record stretched along its traces by these factors (e.g. 0.5,1,2: "
                         "hyperbolas narrower or wider than the training data's, another radar's trace interval) "
                         "and fuse the boxes; auto: as wide as the training pictures' features (weights that "
                         "record it)")
    sp.add_argument("--refine-passes", type=int, default=None, metavar="N",
                    help="apply the box refiner N times (1..5; default 2), each time from the box it moved")
    sp.add_argument("--no-refine-mirror", action="store_true",
                    help="the box refiner sees each box once, not also mirrored (by default the two edge moves "
                         "are averaged)")
    sp.add_argument("--box-rule", default="auto", choices=("auto", "gpr3d", "pgpr"),
                    help="where a refiner of several label rules ends the boxes: gpr3d's rule (docs/labels.md), "
                         "P-GPR's labellers' (boxes higher up the legs), or auto (default: P-GPR's for pictures, "
                         "gpr3d's for recordings)")
    sp.add_argument("--duplicate-iou", default=None, metavar="O",
                    help="a refined box that overlaps a surer one by IoU O or more has its score multiplied by one "
                         "minus that overlap (0 < O <= 1; default 0.5, the merge's own overlap; none: the refined "
                         "boxes keep their scores)")
    sp.add_argument("--fine-refiner", default="auto", metavar="auto|none|FILE",
                    help="the box refiner's fine stage, which moves each box once more after its passes (trained on "
                         "boxes drawn closer to the labels): auto (default: the shipped one with the shipped refiner, "
                         "none with another), none, or a fine stage's .pt/.onnx file")
    sp.add_argument("--quality-weight", type=float, default=None, metavar="W",
                    help="a refiner with a quality head multiplies each refined box's score by its predicted IoU "
                         "to the power W (0..8; default: the refiner's own for simulated records, 0 for real radar "
                         "files and pictures; 0: scores as the network gives them)")


def add_depth_args(sp, flag):
    sp.add_argument(flag, default="hybrid", choices=("hybrid", "net", "fit") + (("none",) if flag == "--depth" else ()),
                    help="host eps_r and depths: hybrid (default: DepthNet refined by the hyperbola fit "
                         "where they agree), "
                         "net (DepthNet), fit (classical hyperbola fit)" + (", none" if flag == "--depth" else ""))
    sp.add_argument("--depthnet", default=None, help="DepthNet weights (default: the shipped ones)")
    sp.add_argument("--trace-spacing", type=float, default=None,
                    help="trace spacing in metres (default: the file's positions)")
    sp.add_argument("--radius", type=float, default=None, metavar="M",
                    help="the targets' radius in metres when known (e.g. 0.008 for 16 mm rebar): the hyperbola "
                         "fit then takes that cylinder instead of a point, which reads eps_r low by about "
                         "radius / (depth + radius)")


def add_label_args(sp):
    sp.add_argument("--pixel-map", default=None,
                    help="time axis of labelled pictures: s_per_px=SECONDS[,t0_s=..,traces_per_px=..,trace0=..] "
                         "(P-GPR: s_per_px=3.125e-11, 8 ns over 256 rows)")
    sp.add_argument("--class-names", default=None, metavar="A,B",
                    help="YOLO class names in id order when the dataset has no data.yaml (P-GPR: steel,pipe)")
    sp.add_argument("--class-kinds", default=None, metavar="NAME=KIND,..",
                    help="map class names onto target kinds (P-GPR: pipe=pvc_pipe; steel is rebar already)")
    sp.add_argument("--labels-frequency", type=float, default=None, metavar="HZ",
                    help="antenna frequency of labelled pictures (P-GPR: 1.6e9)")


def add_marks(sp):
    sp.add_argument("--marks-every", type=float, default=None, metavar="M",
                    help="place the traces by their marks, one every M metres along x (the file's marks: GSSI "
                         "DZT; or --marks)")
    sp.add_argument("--marks", default=None, metavar="TRACES",
                    help="the marked traces, e.g. 0,210,415 (with --marks-every; default the file's marks)")


def add_track(sp):
    sp.add_argument("--track", default=None,
                    help="place the traces on a surveyed track: x y z text, CSV (x,y,z columns) or GSSI .DZG "
                         "(GPS fixes by trace)")
    add_marks(sp)


def add_input(sp):
    sp.add_argument("input", help="radar file (DZT, DT1/HD, RD3/RAD, gprMax .h5/.out, gpr3d .h5)")
    sp.add_argument("--channel", type=int, default=0, help="channel of a multi-channel file (default 0)")
    sp.add_argument("--format", default=None, help="force a reader: dzt, dt1, rd3, gprmax, gpr3d")


def _migration_engine(engine, device: str) -> str:
    """The back projection's engine from ``--engine`` and ``--device``: on a GPU (``--device cuda``) the torch
    engine there, checked now (one line where there is no such device)."""
    if device in (None, "cpu"):
        return engine or "numba"
    if engine not in (None, "torch"):
        raise GPR3DError(f"--device {device} migrates with the torch engine: leave out --engine {engine}")
    from gpr3d.migration.operator import check_engine

    check_engine(f"torch:{device}")
    return f"torch:{device}"
