"""Format detection and the ``read`` entry points.

Each format registers ``is_format(path) -> bool`` and ``read(path, **kw) ->
list[Survey]`` (one Survey per channel). :func:`read_all` asks the detectors in
order (content first: HDF5 files by their attributes, DZT by a valid header;
then header/data pairs by their sidecars) and reads with the first that answers.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from gpr3d.core.errors import FormatError, GPR3DError, InvalidDataError, UnknownFormatError
from gpr3d.io import dt1, dzt, gprmax, hdf5, rd3, segy
from gpr3d.io._common import check_file

__all__ = ["FORMATS", "register", "detect_format", "read", "read_all"]


@dataclass(frozen=True)
class Format:
    name: str
    description: str
    extensions: tuple[str, ...]
    is_format: Callable[[Path], bool]
    read: Callable[..., list]


FORMATS: dict[str, Format] = {}


def register(fmt: Format) -> None:
    """Add (or replace) a format plug-in.

    Parameters
    ----------
    fmt : Format
        Its name, description, extensions, ``is_format(path) -> bool`` and ``read(path, **kw) -> list[Survey]``.
    """
    FORMATS[fmt.name] = fmt


register(Format("gpr3d", "gpr3d HDF5 survey", (".h5", ".hdf5"), hdf5.is_gpr3d_h5, hdf5.read_surveys))
register(Format("gprmax", "gprMax output (v3 .out, v4 .h5)", (".h5", ".out"), gprmax.is_gprmax, gprmax.read_gprmax))
register(Format("dzt", "GSSI DZT", (".dzt",), dzt.is_dzt, dzt.read_dzt))
register(Format("dt1", "Sensors & Software DT1/HD", (".dt1", ".hd"), dt1.is_dt1, dt1.read_dt1))
register(Format("rd3", "MALA RD3/RD7 + RAD", (".rd3", ".rd7", ".rad"), rd3.is_rd3, rd3.read_rd3))
register(Format("segy", "SEG-Y rev 1/2 (as GPR software writes it)", (".sgy", ".segy"), segy.is_segy,
                segy.read_segy))


def detect_format(path) -> str:
    """Name of the registered format that recognises ``path`` (content first, then extension and partner files).

    Parameters
    ----------
    path : str or Path
        The file to look at.

    Returns
    -------
    str
        A key of ``FORMATS``.

    Raises
    ------
    UnknownFormatError
        No reader recognises the file; the message says why (a sidecar, a missing partner file, a corrupt file of a
        known extension, or an unknown extension with the ones that are read).
    FormatError
        The file is missing, empty or unreadable.
    """
    p = check_file(path)
    for name, fmt in FORMATS.items():
        if fmt.is_format(p):
            return name
    ext = p.suffix.lower()
    sidecars = {".dzg": ".DZT", ".dzx": ".DZT", ".cor": ".rd3", ".gps": ".DT1"}
    if ext in sidecars:
        raise UnknownFormatError(p, f"is a sidecar (GPS/metadata) file: read the {sidecars[ext]} data file beside it")
    # data files whose header lives in a file of its own beside them: name the missing one
    pairs = {".dt1": ((".HD",), "pulseEKKO"), ".hd": ((".DT1",), "pulseEKKO"), ".rd3": ((".RAD",), "MALA"),
             ".rd7": ((".RAD",), "MALA"), ".rad": ((".RD3", ".RD7"), "MALA")}
    if ext in pairs:  # (with its partner beside it, the format's detector would have answered already)
        need, vendor = pairs[ext]
        wanted = " or ".join(p.with_suffix(s).name for s in need)
        raise UnknownFormatError(p, f"its partner file {wanted} is missing ({vendor} keeps data and header in "
                                    "two files with one name): copy it beside this one")
    claimed = [f.name for f in FORMATS.values() if ext in f.extensions]
    if len(claimed) == 1:
        # one reader owns the extension: its own words say what is wrong (a DZT with 7 bits per sample says so,
        # not "not a valid file")
        try:
            FORMATS[claimed[0]].read(p)
        except FormatError as exc:
            raise UnknownFormatError(p, f"is not a valid {claimed[0]} file: {exc.problem}") from None
        except GPR3DError as exc:
            raise UnknownFormatError(p, f"is not a valid {claimed[0]} file: {exc}") from None
        return claimed[0]  # (its detector declined what its reader takes: read it so)
    if claimed:
        raise UnknownFormatError(p, f"has a {ext} extension but is not a valid {'/'.join(claimed)} file "
                                    "(corrupt or truncated)")
    known = ", ".join(sorted({e for f in FORMATS.values() for e in f.extensions}))
    raise UnknownFormatError(p, f"unrecognised file format (readers exist for {known})")


def read_all(path, *, format: str | None = None, **kwargs) -> list:
    """Read every channel of a radar file as a list of :class:`~gpr3d.core.survey.Survey`.

    Parameters
    ----------
    path : str or Path
        The recording (DZT, DT1/HD, RD3/RD7 + RAD, SEG-Y, gprMax output or gpr3d HDF5).
    format : str, optional
        Force a reader (``dzt``, ``dt1``, ``rd3``, ``segy``, ``gprmax``, ``gpr3d``) instead of detecting it.
    **kwargs
        Options of that reader (e.g. ``component="Ey"`` for gprMax).

    Returns
    -------
    list of Survey
        One survey per channel, in the file's order.

    Raises
    ------
    FormatError
        The file is missing, truncated, corrupt or not of a known format, or a reader option is unknown; the
        message names the file and the problem in one line.
    """
    from gpr3d.io._common import check_hdf5_survives

    check_file(path)
    check_hdf5_survives(path)  # before any reader or detector opens an HDF5 file that could crash libhdf5
    name = format or detect_format(path)
    if name not in FORMATS:
        raise FormatError(path, f"unknown format {name!r}; known: {', '.join(FORMATS)}")
    try:
        return FORMATS[name].read(Path(path), **kwargs)
    except TypeError as exc:
        if "unexpected keyword" in str(exc):
            option = str(exc).split()[-1]  # "read_dzt() got an unexpected keyword argument 'component'"
            raise FormatError(path, f"the {name} reader takes no option {option}") from None
        raise
    except FormatError:
        raise
    except InvalidDataError as exc:  # what the file holds makes no survey (Survey's checks): name the file
        raise FormatError(path, str(exc)) from None
    except MemoryError:
        size = Path(path).stat().st_size
        raise FormatError(path, f"reading it needs more memory than this machine has (the file is {size:,} bytes; "
                                "its header may claim far more data than it holds)") from None


def read(path, *, format: str | None = None, channel: int = 0, **kwargs):
    """Read one channel (default the first) of a radar file as a :class:`~gpr3d.core.survey.Survey`.

    Parameters
    ----------
    path : str or Path
        The recording; see :func:`read_all`.
    format : str, optional
        Force a reader instead of detecting it.
    channel : int
        Which channel of a multi-channel file.
    **kwargs
        Options of the reader.

    Returns
    -------
    Survey
        The channel, with the file's header values and provenance.

    Raises
    ------
    FormatError
        As :func:`read_all`, and for a channel the file does not have.
    """
    surveys = read_all(path, format=format, **kwargs)
    if not 0 <= channel < len(surveys):
        raise FormatError(path, f"has {len(surveys)} channel(s); channel {channel} does not exist")
    return surveys[channel]
