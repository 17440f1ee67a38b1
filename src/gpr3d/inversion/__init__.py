"""Inversion: the host's wave speed (permittivity) and each target's depth from B-scans.

Depends on ``core``, ``io`` and ``processing`` only. :mod:`gpr3d.inversion.hyperbola`
holds the classical least-squares hyperbola fit.
"""

from gpr3d.inversion.hyperbola import HyperbolaFit, combine_permittivity, fit_boxes, fit_hyperbola

__all__ = ["HyperbolaFit", "fit_hyperbola", "fit_boxes", "combine_permittivity"]
