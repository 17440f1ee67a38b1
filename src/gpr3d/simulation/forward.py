"""A fast ray-based forward model: A-scans for any 3D scene and any antenna poses.

Where FDTD (gprMax) solves Maxwell's equations on a grid, this model places one
wavelet per reflector at the two-way time of its nearest surface point, and runs
at tens of thousands of A-scans per second (numba, parallel over traces). It
makes the surveys along arbitrary paths that 3D migration needs.

Physics, per trace and reflector (antenna midpoint ``m``, transmitter ``a``,
receiver ``b``, both rotating with the antenna heading; see CONVENTIONS.md):

* **time**: ``p`` = the point of the reflector's surface nearest ``m``; the path
  ``|a - p| + |p - b|`` runs through the host at ``v = c / sqrt(eps_r)``. The
  ground is flat (z = 0): an antenna at z > 0 (a cart's bounce: small next to a
  wavelength) adds its height twice at the speed of light. An antenna held
  ``air_gap_m`` above the ground (air-launched: a gap of a wavelength or more) sends
  each leg through the air first, refracted at the surface (the least time over
  the crossing point, :func:`gpr3d.core.raypath.air_ground_time`), as the migration
  does with its ``air_gap_m``. (For a gap much smaller than a wavelength the ground
  wave's straight ray dominates, and the refracted ray is the weaker head wave.)
* **reflection coefficient**: ``-1`` for metal, ``(sqrt(eps_h) - sqrt(eps_t)) /
  (sqrt(eps_h) + sqrt(eps_t))`` for dielectrics (normal incidence).
* **spreading** (geometric optics, ``R`` = half the path): 3D: a sphere of radius
  ``r`` returns ``r / (2 R^2)``, a cylinder ``sqrt(r / (2 R)) / (2 R)``, a plane
  ``1 / (2 R)``; 2D (``spreading="2d"``, to compare with 2D FDTD, where every
  target is a cylinder): a cylinder ``sqrt(r / 2) / R``, a plane ``1 / sqrt(2 R)``.
* **attenuation**: ``exp(-alpha * path)``, ``alpha = sigma / 2 * sqrt(mu0 / eps)``.
* **polarisation**: the dipoles lie along the antenna's y axis; a line target
  (rebar, pipe) returns ``max(cos^2(phi), floor)`` of its echo, ``phi`` the angle
  between dipole and target axis.
* **footprint**: a dipole lying on the ground radiates into it with the pattern of
  the TE transmission coefficient ``T(theta)`` (strongest near the critical angle
  ``asin(1 / sqrt(eps_r))``), normalised to 1 straight down, once per leg; an
  optional Gaussian taper ``exp(-(theta / theta0)^2 / 2)`` models a shielded antenna.
* **penetrable targets** (voids, plastic or water-filled pipes, stones) add the
  echo of their far side, and hollow pipes the echo of their wall's inner
  surface (see ``_echo_table``).
* **source strength**: a short dipole fed a given current radiates a far field
  that grows as ``f`` (3D) or ``sqrt(f)`` (2D): wavelets are scaled by ``(f / 1 GHz)``
  to that power.
* **direct waves**: the air wave at ``offset / c`` and the ground wave at
  ``offset / v``; **clutter**: small random point scatterers; **noise**: white
  Gaussian noise of a given standard deviation.

Every wavelet arrives ``source_delay_s`` after the trace's first sample (gprMax's
Ricker peaks ``sqrt(2)/f`` after its start; the same default is used here).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gpr3d.core.poses import quat_from_yaw, rotate_vectors
from gpr3d.core.units import C0
from gpr3d.simulation.synthetic import ricker

__all__ = ["Pipe", "Sphere", "Box", "Layer", "ForwardScene", "forward_model", "wavelet_table",
           "simulate_scene_bscan", "scene_to_forward"]

MU0 = 4e-7 * math.pi


@dataclass
class Pipe:
    """A cylinder of radius ``radius_m`` around the segment ``p0 -> p1`` (world frame, m; z up)."""

    p0: tuple
    p1: tuple
    radius_m: float
    material: str = "pec"  #: "pec" or "dielectric"
    eps_r: float = 1.0  #: for dielectric targets (an air void: 1; a water-filled pipe: 80)
    wall_m: float = 0.0  #: wall thickness of a hollow (e.g. PVC) pipe; its inside is ``material``/``eps_r``
    wall_eps_r: float = 3.0


@dataclass
class Sphere:
    centre: tuple
    radius_m: float
    material: str = "pec"
    eps_r: float = 1.0


@dataclass
class Box:
    """An axis-aligned box (a tank, a slab)."""

    lo: tuple
    hi: tuple
    material: str = "pec"
    eps_r: float = 1.0


@dataclass
class Layer:
    """A horizontal interface ``depth_m`` below the surface onto a medium of ``eps_r``."""

    depth_m: float
    eps_r: float


@dataclass
class ForwardScene:
    """Host medium and reflectors for :func:`forward_model`."""

    eps_r: float = 6.0
    conductivity_s_m: float = 0.0
    pipes: list = field(default_factory=list)
    spheres: list = field(default_factory=list)
    boxes: list = field(default_factory=list)
    layers: list = field(default_factory=list)


def _gamma(eps_host: float, material: str, eps_r: float) -> float:
    if material == "pec":
        return -1.0
    a, b = math.sqrt(eps_host), math.sqrt(eps_r)
    return (a - b) / (a + b)


def wavelet_table(frequency_hz: float, kind: str = "ricker", step_s: float | None = None):
    """Tabulated wavelet ``(t0_s, step_s, values)`` with its peak-time reference at ``t = 0``.

    ``kind``: ``"ricker"`` (peak 1 at t = 0), ``"ricker_d1"`` (its time derivative,
    the 3D far field of a Hertzian dipole driven by a Ricker current), or
    ``"ricker_half"`` (the half-derivative: the far field of a 2D line source, as in
    2D FDTD). All are normalised to a maximum absolute value of 1.
    """
    step = step_s or 1.0 / (frequency_hz * 400)
    half = 3.0 / frequency_hz
    n_pad = 1 << int(math.ceil(math.log2(8 * half / step)))
    t = (np.arange(n_pad) - n_pad // 2) * step
    w = ricker(t, frequency_hz)
    if kind != "ricker":
        power = {"ricker_d1": 1.0, "ricker_half": 0.5}.get(kind)
        if power is None:
            raise ValueError(f"unknown wavelet {kind!r} (ricker, ricker_d1, ricker_half)")
        spec = np.fft.rfft(np.fft.ifftshift(w))
        omega = 2 * math.pi * np.fft.rfftfreq(n_pad, step)
        w = np.fft.fftshift(np.fft.irfft(spec * (1j * omega) ** power, n_pad))
    keep = np.abs(t) <= half
    w = w[keep]
    w = w / np.max(np.abs(w))
    return float(t[keep][0]), step, w.astype(np.float64)


def _kernel():
    """The forward model's numba kernel (:mod:`gpr3d.simulation._forward_kernels`, imported on first use)."""
    from gpr3d.simulation._forward_kernels import kernel

    return kernel


def _echo_table(eps_host: float, material: str, eps_r: float, radius_m: float, wall_m: float = 0.0,
                wall_eps_r: float = 3.0):
    """Up to three echoes of a cylinder or sphere: ``[[delay_s, amplitude factor, extra host path m], ...]``.

    Solid metal: one echo, -1. Dielectric: the near side ``Gamma`` and the far side,
    ``4 r sqrt(eps_t) / c`` later with ``-(1 - Gamma^2) Gamma`` (and the extra
    spreading of a path ``2 r sqrt(eps_h / eps_t)`` in host units). A hollow pipe
    (``wall_m > 0``) adds its wall: the outer surface echoes first, the wall/fill
    surface ``2 wall sqrt(eps_wall) / c`` later.
    """
    n_h = math.sqrt(eps_host)
    table = []
    delay = 0.0
    through = 1.0
    r_in = radius_m
    if wall_m > 0.0:
        g_out = _gamma(eps_host, "dielectric", wall_eps_r)
        table.append([0.0, g_out, 0.0])
        through = 1.0 - g_out * g_out
        delay = 2.0 * wall_m * math.sqrt(wall_eps_r) / C0
        n_h = math.sqrt(wall_eps_r)
        r_in = radius_m - wall_m
    if material == "pec":
        table.append([delay, -through, 0.0])
    else:
        g = (n_h - math.sqrt(eps_r)) / (n_h + math.sqrt(eps_r))
        table.append([delay, through * g, 0.0])
        table.append([delay + 4.0 * r_in * math.sqrt(eps_r) / C0, -through * (1.0 - g * g) * g,
                      2.0 * r_in * math.sqrt(eps_host / eps_r)])
    while len(table) < 3:
        table.append([0.0, 0.0, 0.0])
    return table[:3]


def forward_model(
    scene: ForwardScene,
    positions_xyz,
    orientations_quat_wxyz=None,
    *,
    headings_rad=None,
    offset_m: float = 0.0,
    frequency_hz: float = 1e9,
    n_samples: int = 512,
    dt_s: float | None = None,
    time_window_s: float | None = None,
    source_delay_s: float | None = None,
    wavelet: str = "ricker",
    spreading: str = "3d",
    footprint: str = "interface",
    beam_half_angle_deg: float | None = None,
    polarisation_floor: float = 0.05,
    air_wave: float = 0.0,
    ground_wave: float = 0.0,
    clutter: int = 0,
    clutter_amplitude: float = 0.05,
    noise: float = 0.0,
    seed: int = 0,
    air_gap_m: float = 0.0,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """A-scans ``(n_traces, n_samples)`` float32 for antenna poses over ``scene``.

    Poses: ``positions_xyz (n, 3)`` antenna midpoints (world, m, surface z = 0) and
    ``orientations_quat_wxyz (n, 4)`` (or ``headings_rad (n,)`` yaw angles);
    transmitter and receiver sit at ``-/+ offset/2`` along the antenna x axis.
    Give ``dt_s`` or ``time_window_s`` (then ``dt = window / n_samples``).
    ``footprint="interface"`` applies the pattern of a dipole on the ground
    (``"none"`` switches it off); ``beam_half_angle_deg`` adds a Gaussian taper.
    ``air_gap_m``: the antennas held that high above the ground (refracted rays; see the module's notes).
    """
    if not (math.isfinite(air_gap_m) and air_gap_m >= 0):
        raise ValueError(f"air_gap_m must be a height >= 0 in metres, got {air_gap_m!r}")
    pos = np.ascontiguousarray(np.atleast_2d(np.asarray(positions_xyz, dtype=np.float64)))
    n = pos.shape[0]
    if orientations_quat_wxyz is None:
        yaw = np.zeros(n) if headings_rad is None else np.broadcast_to(np.asarray(headings_rad, float), (n,))
        q = quat_from_yaw(yaw)
    else:
        q = np.asarray(orientations_quat_wxyz, dtype=float).reshape(n, 4)
    if dt_s is None:
        if time_window_s is None:
            raise ValueError("give dt_s or time_window_s")
        dt_s = time_window_s / n_samples
    if footprint not in ("interface", "none"):
        raise ValueError(f"footprint must be 'interface' or 'none', got {footprint!r}")
    half = rotate_vectors(q, np.array([offset_m / 2, 0.0, 0.0]))
    tx = np.ascontiguousarray(pos - half)
    rx = np.ascontiguousarray(pos + half)
    dip = np.ascontiguousarray(rotate_vectors(q, np.array([0.0, 1.0, 0.0])))
    eps = scene.eps_r
    v = C0 / math.sqrt(eps)
    alpha = scene.conductivity_s_m / 2 * math.sqrt(MU0 / (eps * 8.8541878128e-12))
    caps, pol, echoes = [], [], []
    for p in scene.pipes:
        caps.append([*p.p0, *p.p1, p.radius_m])
        pol.append(polarisation_floor if p.material == "pec" and p.wall_m == 0 else 0.3)
        echoes.append(_echo_table(eps, p.material, p.eps_r, p.radius_m, p.wall_m, p.wall_eps_r))
    for s in scene.spheres:
        caps.append([*s.centre, *s.centre, s.radius_m])
        pol.append(1.0)
        echoes.append(_echo_table(eps, s.material, s.eps_r, s.radius_m))
    if clutter:
        rng = np.random.default_rng(seed + 7919)
        lo, hi = pos.min(axis=0), pos.max(axis=0)
        depth = (time_window_s or n_samples * dt_s) * v / 2
        for _ in range(clutter):
            c = [rng.uniform(lo[0] - 0.2, hi[0] + 0.2), rng.uniform(lo[1] - 0.2, hi[1] + 0.2),
                 -rng.uniform(0.02, 0.9) * depth]
            caps.append([*c, *c, 0.01])
            pol.append(1.0)
            echoes.append([[0.0, clutter_amplitude * rng.uniform(-1, 1) * 20, 0.0], [0, 0, 0], [0, 0, 0]])
    caps_a = np.asarray(caps, dtype=np.float64).reshape(-1, 7)
    pol_a = np.asarray(pol, dtype=np.float64).reshape(-1)
    echo_a = np.asarray(echoes, dtype=np.float64).reshape(-1, 3, 3)
    boxes = np.asarray([[*b.lo, *b.hi] for b in scene.boxes], dtype=np.float64).reshape(-1, 6)
    box_g = np.asarray([_gamma(eps, b.material, b.eps_r) for b in scene.boxes], dtype=np.float64).reshape(-1)
    layers = np.asarray([[ly.depth_m, _gamma(eps, "dielectric", ly.eps_r)] for ly in scene.layers],
                        dtype=np.float64).reshape(-1, 2)
    wt0, wstep, wvals = wavelet_table(frequency_hz, wavelet)
    # a short dipole fed a given current radiates a far field growing as f (3D) or sqrt(f) (2D line source)
    wvals = wvals * (frequency_hz / 1e9) ** (0.5 if spreading == "2d" else 1.0)
    t_src = math.sqrt(2) / frequency_hz if source_delay_s is None else source_delay_s
    if out is None:
        out = np.empty((n, n_samples), dtype=np.float32)
    kernel = _kernel()
    kernel(out, tx, rx, dip, caps_a, pol_a, echo_a, boxes, box_g, layers, v, math.sqrt(eps), alpha, float(dt_s),
           t_src, wt0, wstep, wvals, float(air_wave), float(ground_wave), spreading == "2d",
           1 if footprint == "interface" else 0,
           0.0 if beam_half_angle_deg is None else math.radians(beam_half_angle_deg), float(noise), int(seed),
           float(air_gap_m))
    return out


def scene_to_forward(scene) -> ForwardScene:
    """A :class:`~gpr3d.simulation.scene.Scene` (2D or 3D) as forward-model reflectors."""
    from gpr3d.simulation.scene import MATERIALS

    fs = ForwardScene(eps_r=scene.medium.eps_r, conductivity_s_m=scene.medium.conductivity_s_m)
    for t in scene.targets:
        ax = np.asarray(t.axis_xyz, float)
        ax = ax / np.linalg.norm(ax)
        half = (t.length_m / 2) if t.length_m else 50.0
        centre = np.array([t.x_m, t.y_m, -(t.depth_m + t.radius_m)])
        mat = t.fill or t.material
        eps_t = 1.0 if MATERIALS.get(mat) is None else MATERIALS[mat][0]
        kind = "pec" if mat == "pec" else "dielectric"
        wall, wall_eps = 0.0, 3.0
        if t.fill and t.wall_m > 0 and MATERIALS.get(t.material):
            wall, wall_eps = t.wall_m, MATERIALS[t.material][0]
        fs.pipes.append(Pipe(tuple(centre - half * ax), tuple(centre + half * ax), t.radius_m, kind, eps_t,
                             wall, wall_eps))
    for st in scene.stones:
        c = (st.x_m, 0.0, -(st.depth_m + st.radius_m))
        fs.pipes.append(Pipe((c[0], -50.0, c[2]), (c[0], 50.0, c[2]), st.radius_m, "dielectric", st.eps_r))
    return fs


def simulate_scene_bscan(scene, *, n_samples: int = 512, time_window_s: float | None = None,
                         wavelet: str = "ricker_half", spreading: str = "2d", noise: float = 0.0):
    """The straight-line B-scan of ``scene`` from the forward model, as a Survey (the ``forward`` engine).

    Defaults mimic a 2D FDTD B-scan (half-derivative Ricker, 2D spreading, no beam
    pattern), so forward-model datasets look like gprMax ones.
    """
    import time

    from gpr3d.core.survey import Survey

    t0 = time.perf_counter()
    x = scene.trace_midpoints_x()
    pos = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    window = scene.time_window if time_window_s is None else time_window_s
    data = forward_model(scene_to_forward(scene), pos, offset_m=scene.antenna.offset_m,
                         frequency_hz=scene.antenna.frequency_hz, n_samples=n_samples,
                         time_window_s=window, wavelet=wavelet, spreading=spreading,
                         air_wave=1.0, ground_wave=0.5, noise=noise, seed=scene.seed)
    info = {"engine": "forward", "wavelet": wavelet, "spreading": spreading, "time_window_s": window,
            "n_samples": n_samples, "wall_s": time.perf_counter() - t0}
    survey = Survey(data=data, dt_s=window / n_samples, positions_xyz=pos, offset_m=scene.antenna.offset_m,
                    frequency_hz=scene.antenna.frequency_hz, eps_r=scene.medium.eps_r,
                    orientations_quat_wxyz=quat_from_yaw(np.zeros(len(x))),
                    metadata={"format": "forward", "scene": scene.to_dict(), "simulation": info,
                              "antenna": "forward model"})
    return survey, info
