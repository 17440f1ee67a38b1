"""Processing: pure array functions ``(n_traces, n_samples) -> same``, SI units.

Each is wrapped by a :class:`~gpr3d.core.survey.Survey` method (see
:mod:`gpr3d.processing.steps`) that records the call in the survey's history.

The names below are imported on first use, so that a module of this package that
needs none of SciPy (``gpr3d.processing.image``, on the detector's path) does not
pay for SciPy's signal and image packages when it is imported.
"""

#: where each public name lives
_HOME = {
    "remove_background": "background", "remove_dc": "background", "dewow": "dewow", "envelope": "envelope",
    "bandpass": "filters", "pick_peak": "picking", "gain_agc": "gain", "gain_curve_sec": "gain", "gain_sec": "gain",
    "gain_tpow": "gain", "path_distance": "resample", "resample_traces": "resample", "direct_wave_peak": "timezero",
    "estimate_time_zero": "timezero", "first_break": "timezero", "shift_traces": "timezero", "STEPS": "steps",
}

__all__ = list(_HOME)


def __getattr__(name):
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module 'gpr3d.processing' has no attribute {name!r}")
    from importlib import import_module

    value = getattr(import_module(f"gpr3d.processing.{home}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_HOME))
