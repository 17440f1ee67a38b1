"""Processing: pure array functions ``(n_traces, n_samples) -> same``, SI units.

Each is wrapped by a :class:`~gpr3d.core.survey.Survey` method (see
:mod:`gpr3d.processing.steps`) that records the call in the survey's history.
"""

from gpr3d.processing.background import remove_background, remove_dc
from gpr3d.processing.dewow import dewow
from gpr3d.processing.envelope import envelope
from gpr3d.processing.filters import bandpass
from gpr3d.processing.picking import pick_peak
from gpr3d.processing.gain import gain_agc, gain_curve_sec, gain_sec, gain_tpow
from gpr3d.processing.resample import path_distance, resample_traces
from gpr3d.processing.timezero import direct_wave_peak, estimate_time_zero, first_break, shift_traces

__all__ = [
    "remove_background", "remove_dc", "dewow", "envelope", "bandpass", "gain_agc", "gain_curve_sec",
    "gain_sec", "gain_tpow", "path_distance", "resample_traces", "direct_wave_peak", "estimate_time_zero",
    "first_break", "shift_traces", "pick_peak", "STEPS",
]


def __getattr__(name):
    if name == "STEPS":
        from gpr3d.processing.steps import STEPS

        return STEPS
    raise AttributeError(name)
