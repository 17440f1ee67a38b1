"""Scene descriptions for simulation: host medium, buried targets, antenna and survey line.

Frames follow CONVENTIONS.md: world x along the survey line, y to the left, z up,
the surface at z = 0; a target's ``depth_m`` is the depth of its **top**. A scene
is saved as JSON beside every output (:meth:`Scene.to_json`, :meth:`Scene.from_json`).

The same scene drives both engines: gprMax (2D, so targets must cross the line,
i.e. lie along world y) and the fast ray-based forward model (any 3D geometry).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from gpr3d.core.units import C0, velocity_from_eps_r

__all__ = ["Medium", "Target", "Stone", "Antenna", "Layer", "Scene", "TARGET_KINDS", "MATERIALS"]

TARGET_KINDS = ("rebar", "steel_pipe", "pvc_pipe", "void", "tank")

#: electrical properties used for target and fill materials: (eps_r, conductivity S/m); "pec" = perfect conductor
MATERIALS = {
    "pec": None,
    "pvc": (3.0, 0.0),
    "air": (1.0, 0.0),
    "water": (80.0, 0.05),
}


@dataclass
class Medium:
    """Host medium: concrete or soil, homogeneous or (soil) heterogeneous."""

    kind: str = "concrete"  #: "concrete" or "soil"
    eps_r: float = 6.0
    conductivity_s_m: float = 0.005
    #: heterogeneous soil: gprMax Peplinski mixing model inside a fractal box
    #: {"sand": 0.5, "clay": 0.5, "bulk_density": 2.0, "sand_density": 2.66, "water": [0.01, 0.15], "fractal_dim": 1.5}
    peplinski: dict | None = None

    @property
    def velocity_m_s(self) -> float:
        return velocity_from_eps_r(self.eps_r)


@dataclass
class Target:
    """A buried object. Cylinders (rebar, pipes, voids, tanks) run along ``axis_xyz``."""

    kind: str  #: one of TARGET_KINDS
    x_m: float  #: position along the line of the axis point nearest the line (m)
    depth_m: float  #: depth of the top below the surface (m)
    radius_m: float
    y_m: float = 0.0
    axis_xyz: tuple = (0.0, 1.0, 0.0)  #: direction of the cylinder axis (unit vector, world frame)
    length_m: float | None = None  #: None = longer than the scene
    material: str = "pec"  #: outer material (key of MATERIALS)
    fill: str | None = None  #: inner material of hollow pipes
    wall_m: float = 0.0  #: wall thickness of hollow pipes

    @property
    def centre_depth_m(self) -> float:
        return self.depth_m + self.radius_m

    def crosses_line(self) -> bool:
        ax = np.asarray(self.axis_xyz, float)
        return abs(abs(ax[1]) - 1.0) < 1e-9


@dataclass
class Stone:
    """A clutter stone (a small dielectric cylinder crossing the line)."""

    x_m: float
    depth_m: float
    radius_m: float
    eps_r: float


@dataclass
class Antenna:
    """Transmitter and receiver: Hertzian dipoles with a Ricker pulse, broadside (along y)."""

    frequency_hz: float = 2.0e9
    offset_m: float = 0.04  #: tx-rx separation along x
    kind: str = "hertzian_ricker"


@dataclass
class Layer:
    """A horizontal layer of the host: from ``top_m`` below the surface down to the next layer's top (or the
    bottom of the scene)."""

    top_m: float
    eps_r: float
    conductivity_s_m: float = 0.005


@dataclass
class Scene:
    """A 2D/3D GPR scene and the straight survey line over it."""

    medium: Medium = field(default_factory=Medium)
    targets: list = field(default_factory=list)
    antenna: Antenna = field(default_factory=Antenna)
    width_m: float = 0.6  #: extent along x
    depth_m: float = 0.3  #: extent below the surface
    air_m: float = 0.05  #: air above the surface
    n_traces: int = 48
    trace_step_m: float = 0.01
    x_start_m: float = 0.05  #: antenna midpoint of the first trace
    time_window_s: float | None = None  #: None: from the rule in :meth:`default_time_window`
    dx_m: float | None = None  #: None: from the rule in :meth:`default_dx`
    stones: list = field(default_factory=list)
    rough_surface_m: float = 0.0  #: RMS height of a rough surface (0 = flat)
    layers: list = field(default_factory=list)  #: :class:`Layer` below the host's top one, tops increasing
    seed: int = 0
    name: str = "scene"

    # ---- derived grid and time rules -------------------------------------------------
    def max_eps_r(self) -> float:
        eps = [self.medium.eps_r] + [s.eps_r for s in self.stones] + [lay.eps_r for lay in self.layers]
        for t in self.targets:
            for m in (t.material, t.fill):
                if m and MATERIALS.get(m):
                    eps.append(MATERIALS[m][0])
        if self.medium.peplinski:
            eps.append(self.medium.eps_r * 1.5)
        return max(eps)

    def default_dx(self) -> float:
        """Grid step: 10 cells per shortest wavelength.

        The shortest wavelength is taken at twice the Ricker pulse's peak frequency
        (the spectrum there is 20% of its peak; gprMax's own dispersion check passes),
        in the slowest material present (water fills are thin, so the host and
        ordinary targets set it: the step is capped at the host rule but not driven
        by water).
        """
        host = max([self.medium.eps_r] + [lay.eps_r for lay in self.layers])
        eps = min(self.max_eps_r(), max(host * 1.5, 20.0))
        lam_min = C0 / (2.0 * self.antenna.frequency_hz * math.sqrt(eps))
        step = lam_min / 10.0
        return float(np.floor(step * 1e4) / 1e4)  # whole 0.1 mm

    def default_time_window(self) -> float:
        """Time window: the two-way time to the bottom of the scene (through its layers) plus two pulse lengths."""
        return 2.0 * self.vertical_time_s(self.depth_m) + 2.0 * math.sqrt(2) / self.antenna.frequency_hz

    def eps_profile(self) -> list:
        """``[(top_m, eps_r), ...]`` of the host from the surface down: the medium, then the layers."""
        return [(0.0, self.medium.eps_r)] + [(lay.top_m, lay.eps_r) for lay in self.layers]

    def vertical_time_s(self, depth_m: float) -> float:
        """One-way vertical travel time from the surface down to ``depth_m`` through the host's layers."""
        prof = self.eps_profile()
        t = 0.0
        for k, (top, eps) in enumerate(prof):
            bottom = prof[k + 1][0] if k + 1 < len(prof) else math.inf
            t += max(0.0, min(bottom, depth_m) - top) * math.sqrt(eps) / C0
        return t

    @property
    def dx(self) -> float:
        return self.dx_m if self.dx_m is not None else self.default_dx()

    @property
    def time_window(self) -> float:
        return self.time_window_s if self.time_window_s is not None else self.default_time_window()

    def trace_midpoints_x(self) -> np.ndarray:
        return self.x_start_m + self.trace_step_m * np.arange(self.n_traces)

    # ---- JSON ---------------------------------------------------------------------
    def to_dict(self) -> dict:
        d = asdict(self)
        d["derived"] = {"dx_m": self.dx, "time_window_s": self.time_window}
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1)

    @classmethod
    def from_dict(cls, d: dict) -> "Scene":
        d = dict(d)
        d.pop("derived", None)
        d["medium"] = Medium(**d["medium"])
        d["antenna"] = Antenna(**d["antenna"])
        d["targets"] = [Target(**{**t, "axis_xyz": tuple(t["axis_xyz"])}) for t in d["targets"]]
        d["stones"] = [Stone(**s) for s in d.get("stones", [])]
        d["layers"] = [Layer(**lay) for lay in d.get("layers", [])]
        return cls(**d)

    @classmethod
    def from_json(cls, text: str) -> "Scene":
        return cls.from_dict(json.loads(text))
