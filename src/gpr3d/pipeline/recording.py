"""The first stages: a recording read, its traces placed on the ground, processed, and written back out."""

from __future__ import annotations

from pathlib import Path

from gpr3d.core.errors import GPR3DError

__all__ = ["SURVEY_SUFFIXES", "apply_steps", "attach_trajectory", "place_traces", "read_recording", "write_survey"]

#: what :func:`write_survey` writes, by suffix
SURVEY_SUFFIXES = (".h5", ".hdf5", ".sgy", ".segy", ".png")


def place_traces(survey, *, track=None, marks_every_m: float | None = None, marks=None):
    """The survey with its traces placed on the ground.

    Parameters
    ----------
    survey : Survey
        The recording as read.
    track : str or Path, optional
        A surveyed track (x y z text, CSV with x, y, z columns, or a GSSI ``.DZG``): each trace takes its place on it.
    marks_every_m : float, optional
        The traces placed by their marks, one mark every this many metres along x (the file's marks, or ``marks``).
    marks : list of int, optional
        The marked traces (with ``marks_every_m``; default: the marks the file holds).

    Returns
    -------
    Survey
        ``survey`` itself when neither is given.
    """
    if marks_every_m is not None:
        from gpr3d.core.gridsurvey import place_by_marks

        survey = place_by_marks(survey, marks_every_m, marks=marks)
    if track:
        from gpr3d.io.trajectory import apply_track, read_track

        survey = apply_track(survey, read_track(track))
    return survey


def apply_steps(survey, specs):
    """The survey after the processing steps ``specs``, each ``NAME[:key=value[:key=value]]`` (SI units), in order.

    Parameters
    ----------
    survey : Survey
    specs : list of str
        e.g. ``["time_zero", "dewow", "gain_tpow:power=1.5"]``; the known steps: ``gpr3d process --help``.

    Returns
    -------
    Survey

    Raises
    ------
    GPR3DError
        For an unknown step or argument (one line naming it).
    """
    from gpr3d.processing.steps import parse_step

    for spec in specs or []:
        name, kwargs = parse_step(spec)
        survey = survey.apply(name, **kwargs)
    return survey


def read_recording(path, *, format: str | None = None, channel: int = 0, track=None,
                   marks_every_m: float | None = None, marks=None, steps=()):
    """Read one channel of a radar file, place its traces (see :func:`place_traces`) and process it.

    Parameters
    ----------
    path : str or Path
        DZT, DT1/HD, RD3/RAD, SEG-Y, gprMax output or gpr3d ``.h5``.
    format : str, optional
        Force a reader (``dzt``, ``dt1``, ``rd3``, ``segy``, ``gprmax``, ``gpr3d``).
    channel : int
        Channel of a multi-channel file.
    track, marks_every_m, marks
        As :func:`place_traces`.
    steps : list of str
        As :func:`apply_steps`.

    Returns
    -------
    Survey

    Raises
    ------
    GPR3DError
        A file that cannot be read, in one line naming it.
    """
    from gpr3d.core.timing import stage
    from gpr3d.io.registry import read

    with stage("read"):
        survey = read(path, format=format, channel=channel)
        survey = place_traces(survey, track=track, marks_every_m=marks_every_m, marks=marks)
    with stage("processing"):
        return apply_steps(survey, steps)


def write_survey(survey, out) -> None:
    """Write a survey by the suffix of ``out``: ``.h5`` (gpr3d HDF5), ``.sgy``/``.segy`` (SEG-Y) or ``.png``.

    Parameters
    ----------
    survey : Survey
        What is written (atomically).
    out : str or Path
        The file; its suffix chooses the writer.

    Raises
    ------
    GPR3DError
        For another suffix.
    """
    suffix = Path(out).suffix.lower()
    if suffix in (".h5", ".hdf5"):
        survey.save(out)
    elif suffix in (".sgy", ".segy"):
        from gpr3d.io.segy import write_segy

        write_segy(survey, out)
    elif suffix == ".png":
        from gpr3d.viz.bscan import save_bscan_png

        save_bscan_png(survey, out)
    else:
        raise GPR3DError(f"{out}: unknown output type {suffix!r} (use .h5, .sgy/.segy or .png)")


def attach_trajectory(survey, poses, *, source: str = "the survey"):
    """The survey with one antenna pose per trace from a trajectory file (TUM, EuRoC or CSV), in trace order.

    Parameters
    ----------
    survey : Survey
        The recording.
    poses : str or Path
        The trajectory file: one pose per trace, matched by index.
    source : str
        The survey's name in a message.

    Returns
    -------
    Survey
        A copy with ``positions_xyz`` and ``orientations_quat_wxyz`` set.

    Raises
    ------
    GPR3DError
        When the file holds another number of poses than the survey has traces.
    """
    from gpr3d.core.timing import stage
    from gpr3d.io.trajectory import attach_poses, read_trajectory

    with stage("poses"):
        traj = read_trajectory(poses)
        if len(traj) != survey.n_traces:
            raise GPR3DError(f"{poses} holds {len(traj)} poses but {source} has {survey.n_traces} "
                             "traces (one pose per trace)")
        return attach_poses(survey, traj, by="index")
