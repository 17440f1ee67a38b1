"""Random scenes, reproducible from ``(seed, index)``.

Ranges (stated, so a dataset can be described and regenerated):

=========  ==============  ======  =============  ===============================================
host       frequency       eps_r   sigma (S/m)    targets (radius)
=========  ==============  ======  =============  ===============================================
concrete   1.5 - 2.6 GHz   4 - 12  0.001 - 0.02   rebar 4-16 mm, steel pipe 15-40 mm, PVC pipe
                                                  15-40 mm (air or water filled), void 10-30 mm
soil       0.4 - 1.0 GHz   3 - 20  0.0005 - 0.01  steel pipe 25-100 mm, PVC pipe 25-100 mm,
                                                  void 30-100 mm, tank 120-250 mm, rebar 6-16 mm
=========  ==============  ======  =============  ===============================================

1 to 6 targets, crossing the line (gprMax runs in 2D), never overlapping. The scene
scales with the wavelength in the host, ``lambda = v / f``: 7 lambda wide, 3.5 lambda deep,
32 traces; so every scene costs gprMax about the same (about 8 s on one core). Soil scenes get clutter stones
(0-4) and, in a quarter of them, a rough surface.
"""

from __future__ import annotations

import math

import numpy as np

from gpr3d.simulation.scene import Antenna, Medium, Scene, Stone, Target

__all__ = ["sample_scene", "RANGES"]

RANGES = {
    "concrete": {"frequency_hz": (1.5e9, 2.6e9), "eps_r": (4.0, 12.0), "conductivity_s_m": (0.001, 0.02),
                 "kinds": {"rebar": 0.55, "steel_pipe": 0.15, "pvc_pipe": 0.15, "void": 0.15},
                 "radius_m": {"rebar": (0.004, 0.016), "steel_pipe": (0.015, 0.04), "pvc_pipe": (0.015, 0.04),
                              "void": (0.01, 0.03)}},
    "soil": {"frequency_hz": (0.4e9, 1.0e9), "eps_r": (3.0, 20.0), "conductivity_s_m": (0.0005, 0.01),
             "kinds": {"steel_pipe": 0.3, "pvc_pipe": 0.3, "void": 0.15, "tank": 0.1, "rebar": 0.15},
             "radius_m": {"steel_pipe": (0.025, 0.1), "pvc_pipe": (0.025, 0.1), "void": (0.03, 0.1),
                          "tank": (0.12, 0.25), "rebar": (0.006, 0.016)}},
    "n_targets": (1, 6),
    "n_traces": 32,
    "width_wavelengths": 7.0,
    "depth_wavelengths": 3.5,
}


def _rng(seed: int, index: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(index)]))


def sample_scene(seed: int, index: int, *, host: str | None = None) -> Scene:
    """The ``index``-th random scene of the dataset with master ``seed``.

    ``host`` forces "concrete" or "soil"; by default two thirds are concrete.
    """
    rng = _rng(seed, index)
    host = host or ("concrete" if rng.random() < 2 / 3 else "soil")
    r = RANGES[host]
    f = float(rng.uniform(*r["frequency_hz"]))
    eps = float(rng.uniform(*r["eps_r"]))
    sigma = float(np.exp(rng.uniform(np.log(r["conductivity_s_m"][0]), np.log(r["conductivity_s_m"][1]))))
    medium = Medium(kind=host, eps_r=round(eps, 3), conductivity_s_m=round(sigma, 5))
    lam = medium.velocity_m_s / f
    width = RANGES["width_wavelengths"] * lam
    depth = RANGES["depth_wavelengths"] * lam
    offset = round(0.25 * lam, 4)
    scene = Scene(medium=medium, antenna=Antenna(frequency_hz=round(f, -6), offset_m=offset), width_m=round(width, 4),
                  depth_m=round(depth, 4), n_traces=RANGES["n_traces"], seed=int(seed), name=f"{host}_{seed}_{index:06d}")
    dx = scene.dx
    scene.air_m = round(max(0.5 * lam, 25 * dx), 4)
    margin = max(0.06 * width, 16 * dx) + offset / 2
    scene.x_start_m = round(margin, 4)
    scene.trace_step_m = round((width - 2 * margin) / (scene.n_traces - 1), 5)

    kinds, probs = zip(*r["kinds"].items())
    n_targets = int(rng.integers(RANGES["n_targets"][0], RANGES["n_targets"][1] + 1))
    placed: list[Target] = []
    x_lo, x_hi = margin + 0.5 * lam, width - margin - 0.5 * lam
    for _ in range(200):
        if len(placed) == n_targets:
            break
        kind = str(rng.choice(kinds, p=np.asarray(probs) / sum(probs)))
        rad = float(rng.uniform(*r["radius_m"][kind]))
        # the target must fit between 0.5 lambda below the surface and 0.6 lambda above the bottom
        room = depth - 1.1 * lam
        if 2 * rad > room:
            continue
        top = float(rng.uniform(0.5 * lam, depth - 2 * rad - 0.6 * lam))
        x = float(rng.uniform(x_lo, x_hi))
        t = Target(kind=kind, x_m=round(x, 4), depth_m=round(top, 4), radius_m=round(rad, 4))
        if kind == "pvc_pipe":
            t.material, t.fill = "pvc", str(rng.choice(["air", "water"], p=[0.7, 0.3]))
            t.wall_m = round(max(min(0.004 + 0.05 * rad, 0.5 * rad), 2 * dx), 4)
        elif kind == "void":
            t.material = "air"
        # keep 0.6 lambda (and 1.5 radii) between neighbours, so hyperbola apexes stay apart
        if all(math.hypot(t.x_m - o.x_m, t.centre_depth_m - o.centre_depth_m)
               > 1.5 * (t.radius_m + o.radius_m) + 0.6 * lam for o in placed):
            placed.append(t)
    scene.targets = placed
    if host == "soil":
        for _ in range(int(rng.integers(0, 5))):
            st = Stone(x_m=round(float(rng.uniform(margin, width - margin)), 4),
                       depth_m=round(float(rng.uniform(0.1 * lam, depth - 0.3 * lam)), 4),
                       radius_m=round(float(rng.uniform(3 * dx, max(3 * dx, 0.15 * lam))), 4),
                       eps_r=round(float(rng.uniform(5.0, 9.0)), 2))
            # stones lie in the host, not inside or touching a target
            if all(math.hypot(st.x_m - t.x_m, st.depth_m + st.radius_m - t.centre_depth_m)
                   > st.radius_m + t.radius_m + 2 * dx for t in placed):
                scene.stones.append(st)
        if rng.random() < 0.25:
            scene.rough_surface_m = round(float(rng.uniform(0.02, 0.06) * lam), 4)
    return scene
