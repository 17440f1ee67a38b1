"""Survey-scale B-scans: real-world sizes, survey geometry and recording artefacts.

The scenes of :mod:`gpr3d.simulation.sampler` are short (25-40 traces) so that
gprMax stays cheap; real recordings are not. :func:`sample_survey_scene` draws
scenes at the sizes practitioners meet (ranges stated in ``SURVEY_RANGES`` and
``docs/labels.md``):

==========  ============  =======  ==========================================================
host        frequency     eps_r    geometry
==========  ============  =======  ==========================================================
concrete    1.0-2.6 GHz   4-12     100-600 traces 2-10 mm apart; rebars 10-32 mm diameter,
                                   10-30 cm apart, 2-15 cm cover, a second layer in half of
                                   the scans; a few conduits (steel, PVC) and voids; a slab
                                   bottom in half of them
soil        100-900 MHz   3-25     100-600 traces 1-10 cm apart; pipes 2-60 cm diameter at
                                   0.3-2 m (steel, PVC with air or water, voids, tanks), stones
==========  ============  =======  ==========================================================

:func:`synthesize_survey` turns a scene into a recorded-looking B-scan with the
fast forward model and the artefacts of real radars, each drawn at random:
uneven trace spacing, dropped traces and stops (repeated traces), a pre-trigger
time shift, direct waves, antenna ringing, wow, gain curves, clutter points and
noise, and another wavelet. Labels follow the same box rule as every other sample
(:func:`gpr3d.simulation.labels.label_traces`), computed at the traces' actual
positions and time shift.
"""

from __future__ import annotations

import math

import numpy as np

from gpr3d.simulation.scene import Antenna, Medium, Scene, Stone, Target

__all__ = ["SURVEY_RANGES", "SURVEY_PROFILES", "WALL_RANGES", "display_8bit", "echo_ringing", "sample_survey_scene", "sample_gprmax_survey_scene", "synthesize_survey", "survey_sample", "SurveySource"]

SURVEY_RANGES = {
    "concrete": {"frequency_hz": (1.0e9, 2.6e9), "eps_r": (4.0, 12.0), "conductivity_s_m": (0.001, 0.03),
                 "step_m": (0.002, 0.01), "rebar_radius_m": (0.005, 0.016), "rebar_spacing_m": (0.10, 0.30),
                 "cover_m": (0.02, 0.15), "second_layer": 0.5, "slab_bottom": 0.5},
    "soil": {"frequency_hz": (1.0e8, 9.0e8), "eps_r": (3.0, 25.0), "conductivity_s_m": (0.0005, 0.02),
             "step_m": (0.01, 0.10), "pipe_radius_m": (0.01, 0.30), "depth_m": (0.3, 2.0),
             "kinds": {"steel_pipe": 0.35, "pvc_pipe": 0.3, "void": 0.15, "tank": 0.05, "rebar": 0.15}},
    "n_traces": (100, 600),
}

#: how scenes are drawn from SURVEY_RANGES. "train": the detector's training and test records
#: (forward model). "gprmax_eval": the held-out gprMax set at survey scale - soil targets of every
#: kind in equal shares (so that each kind gathers >= 200 targets), 100-200 traces and a shorter
#: record below the deepest target, so that one B-scan costs minutes of FDTD, not hours.
SURVEY_PROFILES = {
    "train": {"p_concrete": 0.5, "n_traces": (100, 600), "soil_kinds": SURVEY_RANGES["soil"]["kinds"],
              "soil_n_targets": (1, 6), "concrete_extra": (0, 2), "depth_factor": (1.1, 1.8)},
    "gprmax_eval": {"p_concrete": 0.25, "n_traces": (100, 200),
                    "soil_kinds": {"steel_pipe": 0.2, "pvc_pipe": 0.2, "void": 0.2, "tank": 0.4},
                    "soil_n_targets": (4, 9), "concrete_extra": (1, 3), "depth_factor": (1.1, 1.4)},
    "wall": {"p_concrete": 1.0, "n_traces": (300, 1800), "concrete_extra": (0, 3)},
}

#: "wall": handheld scans of walls as concrete scanners record them (the sizes P-GPR's train
#: labels show: 1.6 GHz, 256 rows over 8 ns, hyperbolas 40-200 traces wide and their apexes
#: 0.65-1.7 ns down, bars 50-290 traces apart): fine trace steps, shallow cover, a fixed
#: window of 6-10 ns, recorded as an 8-bit picture with the direct wave clipped
WALL_RANGES = dict(SURVEY_RANGES["concrete"], frequency_hz=(1.2e9, 2.0e9), eps_r=(4.0, 10.0), step_m=(0.0006, 0.0025),
                   rebar_radius_m=(0.004, 0.012), rebar_spacing_m=(0.1, 0.3), cover_m=(0.012, 0.07),
                   second_layer=0.3, window_s=(6e-9, 10e-9), display=0.8)

#: the most FDTD work (cells x iterations x traces) a "gprmax_eval" scene may cost; dearer draws are redrawn
GPRMAX_EVAL_MAX_CELL_STEPS = 8e9


def _rng(seed: int, index: int, *salt: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(index), 0x5157, *salt]))


def _log_uniform(rng, lo, hi):
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def sample_survey_scene(seed: int, index: int, *, host: str | None = None, profile: str = "train",
                        attempt: int = 0) -> Scene:
    """The ``index``-th survey-scale scene of ``seed`` (2D: every target crosses the line).

    ``profile`` names the draw rules in ``SURVEY_PROFILES``; ``attempt`` > 0 gives another
    draw for the same index (used to redraw scenes over a cost limit).
    """
    if profile not in SURVEY_PROFILES:
        raise ValueError(f"unknown survey profile {profile!r} (use {', '.join(SURVEY_PROFILES)})")
    prof = SURVEY_PROFILES[profile]
    if profile == "wall" and host not in (None, "concrete"):
        raise ValueError(f"wall scans are of concrete, got host {host!r}")
    rng = _rng(seed, index) if profile == "train" and attempt == 0 else \
        _rng(seed, index, 0xE7A1 if profile != "wall" else 0x3A11, attempt)
    host = host or ("concrete" if rng.random() < prof["p_concrete"] else "soil")
    r = WALL_RANGES if profile == "wall" else SURVEY_RANGES[host]
    f = _log_uniform(rng, *r["frequency_hz"])
    eps = float(rng.uniform(*r["eps_r"]))
    sigma = _log_uniform(rng, *r["conductivity_s_m"])
    medium = Medium(kind=host, eps_r=round(eps, 3), conductivity_s_m=round(sigma, 5))
    v = medium.velocity_m_s
    n_traces = int(rng.integers(prof["n_traces"][0], prof["n_traces"][1] + 1))
    step = _log_uniform(rng, *r["step_m"])
    targets: list[Target] = []
    if host == "concrete":
        length = n_traces * step
        rad = float(rng.uniform(*r["rebar_radius_m"]))
        spacing = float(rng.uniform(*r["rebar_spacing_m"]))
        cover = float(rng.uniform(*r["cover_m"]))
        x = float(rng.uniform(0.0, spacing))
        while x < length:
            targets.append(Target("rebar", x_m=round(x, 4), depth_m=round(cover, 4), radius_m=round(rad, 4)))
            x += spacing * float(rng.uniform(0.95, 1.05))
        if rng.random() < r["second_layer"]:
            rad2 = float(rng.uniform(*r["rebar_radius_m"]))
            sp2 = float(rng.uniform(*r["rebar_spacing_m"]))
            d2 = cover + 2 * rad + float(rng.uniform(0.04, 0.12))
            x = float(rng.uniform(0.0, sp2))
            while x < length:
                t = Target("rebar", x_m=round(x, 4), depth_m=round(d2, 4), radius_m=round(rad2, 4))
                if all(abs(t.x_m - o.x_m) > 2.5 * (t.radius_m + o.radius_m) for o in targets):
                    targets.append(t)
                x += sp2 * float(rng.uniform(0.95, 1.05))
        if not targets:  # a short scan between two bars of a wide mesh: put one bar on it
            targets.append(Target("rebar", x_m=round(float(rng.uniform(0.2, 0.8)) * length, 4),
                                  depth_m=round(cover, 4), radius_m=round(rad, 4)))
        deepest = max(t.depth_m + 2 * t.radius_m for t in targets)
        for _ in range(int(rng.integers(prof["concrete_extra"][0], prof["concrete_extra"][1] + 1))):
            # conduits and voids between or below the bars
            kind = str(rng.choice(["steel_pipe", "pvc_pipe", "void"], p=[0.3, 0.6, 0.1] if profile == "wall" else None))
            t = Target(kind, x_m=round(float(rng.uniform(0, length)), 4),
                       depth_m=round(float(rng.uniform(cover + 0.02, deepest + 0.12)), 4),
                       radius_m=round(float(rng.uniform(0.008, 0.025)), 4))
            _finish_target(t, rng)
            if all(math.hypot(t.x_m - o.x_m, t.centre_depth_m - o.centre_depth_m) > 2 * (t.radius_m + o.radius_m)
                   + 0.02 for o in targets):
                targets.append(t)
        depth_range = max(t.depth_m + 2 * t.radius_m for t in targets) + float(rng.uniform(0.05, 0.25))
    else:
        # the sampler keeps boxes within ~100 traces each side: trace step >= depth / 100
        max_depth = float(rng.uniform(0.5, r["depth_m"][1]))
        step = max(step, 1.2 * max_depth / 100)
        length = n_traces * step
        kinds, probs = zip(*prof["soil_kinds"].items())
        n_want = int(rng.integers(prof["soil_n_targets"][0], prof["soil_n_targets"][1] + 1))
        for _ in range(200):
            if len(targets) >= n_want:
                break
            kind = str(rng.choice(kinds, p=np.asarray(probs) / sum(probs)))
            rad = {"rebar": (0.006, 0.016), "tank": (0.3, 0.6)}.get(kind, r["pipe_radius_m"])
            rad = _log_uniform(rng, *rad)
            top = float(rng.uniform(r["depth_m"][0], max(max_depth, r["depth_m"][0] + 0.05)))
            t = Target(kind, x_m=round(float(rng.uniform(0.05, 0.95) * length), 4), depth_m=round(top, 4),
                       radius_m=round(rad, 4))
            _finish_target(t, rng)
            if not targets or all(math.hypot(t.x_m - o.x_m, t.centre_depth_m - o.centre_depth_m)
                                  > 1.5 * (t.radius_m + o.radius_m) + 0.25 * v / f for o in targets):
                targets.append(t)
        depth_range = max(t.depth_m + 2 * t.radius_m for t in targets) * float(rng.uniform(*prof["depth_factor"]))
    scene = Scene(medium=medium, antenna=Antenna(frequency_hz=round(f, -6), offset_m=round(0.2 * v / f, 4)),
                  width_m=round(length, 4), depth_m=round(depth_range, 4), n_traces=n_traces,
                  trace_step_m=round(step, 5), x_start_m=0.0, seed=int(seed),
                  name=f"survey_{'wall' if profile == 'wall' else host}_{seed}_{index:06d}")
    scene.targets = targets
    scene.time_window_s = 2 * depth_range / v + 2.5 / f
    if profile == "wall":
        scene.time_window_s = max(scene.time_window_s, float(rng.uniform(*r["window_s"])))
    if host == "soil":
        for _ in range(int(rng.integers(0, 8))):
            scene.stones.append(Stone(x_m=round(float(rng.uniform(0, length)), 4),
                                      depth_m=round(float(rng.uniform(0.05, depth_range)), 4),
                                      radius_m=round(float(rng.uniform(0.01, 0.05)), 4),
                                      eps_r=round(float(rng.uniform(5.0, 9.0)), 2)))
    return scene


def sample_gprmax_survey_scene(seed: int, index: int, *, max_cell_steps: float = GPRMAX_EVAL_MAX_CELL_STEPS,
                               host: str | None = None) -> Scene:
    """The ``index``-th scene of the held-out gprMax survey set (profile ``"gprmax_eval"``).

    Targets under 1.5 grid cells in radius (gprMax cannot build them) are drawn at 1.5
    cells, stones under 1.5 cells are left out, and draws over ``max_cell_steps`` of FDTD
    work (:func:`~gpr3d.simulation.gprmax_runner.following_cost`) or with targets that then touch are
    redrawn, so the set leans to the cheaper scans of each range.
    """
    from gpr3d.simulation.gprmax_runner import following_cost

    for attempt in range(200):
        scene = sample_survey_scene(seed, index, host=host, profile="gprmax_eval", attempt=attempt)
        dx = scene.dx_m = scene.dx  # fixed now: leaving stones out must not coarsen the grid
        scene.stones = [st for st in scene.stones if st.radius_m >= 1.5 * dx]  # finer clutter: below the grid
        for t in scene.targets:  # gprMax cannot build a cylinder under a cell or two: draw it at 1.5 cells
            t.radius_m = max(t.radius_m, round(1.5 * dx + 5e-5, 4))
            if t.wall_m:
                t.wall_m = min(max(t.wall_m, round(dx + 5e-5, 4)), round(t.radius_m - dx, 4))
        clash = any(math.hypot(a.x_m - b.x_m, a.centre_depth_m - b.centre_depth_m) < a.radius_m + b.radius_m + dx
                    for k, a in enumerate(scene.targets) for b in scene.targets[k + 1:])
        if not clash and following_cost(scene) <= max_cell_steps:
            scene.name = f"gprmax_survey_{scene.medium.kind}_{seed}_{index:06d}"
            return scene
    raise ValueError(f"no scene of seed {seed}, index {index} costs under {max_cell_steps:.3g} cell-steps")


def _finish_target(t: Target, rng) -> None:
    if t.kind == "pvc_pipe":
        t.material, t.fill = "pvc", str(rng.choice(["air", "water"], p=[0.7, 0.3]))
        t.wall_m = round(min(0.003 + 0.05 * t.radius_m, 0.5 * t.radius_m), 4)
    elif t.kind == "void":
        t.material = "air"


def _trace_positions(scene: Scene, rng, augment: bool) -> np.ndarray:
    """Antenna midpoints along x: even steps, or jittered with stops and dropped traces."""
    n = scene.n_traces
    if not augment:
        return scene.trace_midpoints_x()
    steps = scene.trace_step_m * np.clip(1 + rng.uniform(0, 0.3) * rng.standard_normal(n), 0.2, 2.0)
    steps[0] = 0.0
    if rng.random() < 0.3:  # stops: the wheel does not turn, the radar keeps recording
        for _ in range(int(rng.integers(1, 4))):
            i = int(rng.integers(1, n))
            steps[i : i + int(rng.integers(2, 12))] = 0.0
    if rng.random() < 0.3:  # dropped traces: a step of two or three
        k = rng.random(n) < 0.03
        steps[k] *= rng.integers(2, 4, size=int(k.sum()))
    return scene.x_start_m + np.cumsum(steps)


def synthesize_survey(scene: Scene, *, seed: int = 0, augment: bool = True, n_samples: int | None = None,
                      wall: bool = False, ringing: float = 0.0, box_pad: float | None = None,
                      pad_wavelet: bool = False):
    """A recorded-looking B-scan of ``scene`` (forward model) and its labels: ``(Survey, labels dict)``.

    With ``augment`` the artefacts listed in the module docstring are drawn from
    ``seed``; without it the B-scan is the clean forward model at even steps. ``wall``
    (with ``augment``): recorded as a handheld wall scanner records (``WALL_RANGES``): a
    narrower beam, the concrete's aggregate as many weak scatterers, noise correlated from
    trace to trace, and most often kept as an 8-bit picture (:func:`display_8bit`); ``ringing``: the share of
    wall records whose every echo rings (:func:`echo_ringing`, a draw of its own: 0 leaves the records as they were);
    ``box_pad``: the labels' time pad in periods (:func:`~gpr3d.simulation.labels.label_traces`' ``pad_periods``;
    None: the rule's 0.7). ``pad_wavelet``: that pad in periods of the wavelet the record was drawn with (the
    antenna's true centre frequency, 0.8-1.2x its label's with ``augment``), not of the label's frequency, so that
    a box reaches the same lobes of every record's echo. The record itself depends on neither.
    """
    from gpr3d.core.poses import quat_from_yaw
    from gpr3d.core.survey import Survey
    from gpr3d.simulation.forward import Layer, forward_model, scene_to_forward
    from gpr3d.simulation.labels import BOX_PAD_PERIODS, label_traces

    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xA06]))
    f = scene.antenna.frequency_hz
    window = scene.time_window
    if n_samples is None:
        n_samples = int(np.clip(round(window * f * rng.uniform(8, 30) if augment else window * f * 16), 256, 2048))
    dt = window / n_samples
    x = _trace_positions(scene, rng, augment)
    pos = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    delay = math.sqrt(2) / f + (rng.uniform(0, 0.08) * window if augment else 0.0)
    fs = scene_to_forward(scene)
    if scene.medium.kind == "concrete" and augment and rng.random() < SURVEY_RANGES["concrete"]["slab_bottom"]:
        deepest = max((t.depth_m + 2 * t.radius_m for t in scene.targets), default=0.05)
        fs.layers.append(Layer(depth_m=float(rng.uniform(deepest + 0.03, max(deepest + 0.05, scene.depth_m))),
                               eps_r=1.0))
    kw = dict(offset_m=scene.antenna.offset_m, frequency_hz=f, n_samples=n_samples, dt_s=dt, source_delay_s=delay,
              wavelet="ricker_half", spreading="2d", air_wave=1.0, ground_wave=0.5, seed=int(seed))
    if augment:
        f_eff = f * float(rng.uniform(0.8, 1.2))  # the antenna's true centre frequency differs from its label
        kw.update(frequency_hz=f_eff, wavelet=str(rng.choice(["ricker", "ricker_half", "ricker_d1"])),
                  spreading=str(rng.choice(["2d", "3d"])), air_wave=float(rng.uniform(0.2, 2.0)),
                  ground_wave=float(rng.uniform(0.1, 1.0)), clutter=int(rng.integers(0, 30)),
                  clutter_amplitude=float(rng.uniform(0.01, 0.06)))
        if wall:
            kw.update(beam_half_angle_deg=float(rng.uniform(20, 45)), clutter=int(rng.integers(60, 300)),
                      clutter_amplitude=float(rng.uniform(0.02, 0.12)))
    data = forward_model(fs, pos, **kw).astype(np.float64)
    if augment and wall:
        # (a draw of its own: the records' other draws stay what they were without it)
        ring_rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xA07]))
        if ring_rng.random() < ringing:
            data = echo_ringing(data, dt, f, ring_rng)
    if augment:
        data = _artefacts(data, dt, f, rng)
        if wall:
            data = data + _correlated_noise(data.shape, dt, f, rng) * float(rng.uniform(0.02, 0.06)) \
                * (float(np.percentile(np.abs(data), 99.5)) or 1.0)
            if rng.random() < WALL_RANGES["display"]:
                data = display_8bit(data, rng)
    survey = Survey(data=data.astype(np.float32), dt_s=dt, positions_xyz=pos, offset_m=scene.antenna.offset_m,
                    frequency_hz=f, eps_r=scene.medium.eps_r, orientations_quat_wxyz=quat_from_yaw(np.zeros(len(x))),
                    metadata={"format": "forward", "scene": scene.to_dict(), "antenna": "forward model",
                              "simulation": {"engine": "forward", "augment": augment, "seed": int(seed),
                                             "source_delay_s": delay}})
    pad = BOX_PAD_PERIODS if box_pad is None else box_pad
    if pad_wavelet:  # (the same pad of the drawn wavelet's periods, in the label's frequency's; 2 at most)
        pad = min(pad * f / kw["frequency_hz"], 2.0)
    labels = label_traces(scene, x, n_samples, dt, source_delay_s=delay, pad_periods=pad)
    return survey, {"eps_r": scene.medium.eps_r, "n_traces": len(x), "n_samples": n_samples, "dt_s": dt,
                    "labels": labels}


def _artefacts(data: np.ndarray, dt: float, f: float, rng) -> np.ndarray:
    n_tr, n_s = data.shape
    t = np.arange(n_s) * dt
    peak = float(np.percentile(np.abs(data), 99.9)) or 1.0
    if rng.random() < 0.6:  # antenna ringing: horizontal bands, slowly varying along the line
        fr = f * rng.uniform(0.6, 1.4)
        ring = np.sin(2 * np.pi * fr * t + rng.uniform(0, 2 * np.pi)) * np.exp(-t / (rng.uniform(2, 12) / f))
        ring *= rng.uniform(0.05, 0.5) * peak
        drift = 1 + 0.2 * np.sin(np.linspace(0, rng.uniform(1, 6), n_tr) + rng.uniform(0, 6))
        data = data + drift[:, None] * ring[None, :]
    if rng.random() < 0.5:  # wow: a low-frequency drift of each trace
        wow = np.exp(-t / (rng.uniform(0.2, 1.0) * t[-1])) * rng.uniform(0.05, 0.5) * peak
        data = data + wow[None, :] * (1 + 0.3 * rng.standard_normal((n_tr, 1)))
    if rng.random() < 0.7:  # the radar's gain curve
        tt = t / t[-1]
        gain = (1 + rng.uniform(0, 30) * tt ** rng.uniform(0.5, 3)) if rng.random() < 0.5 \
            else np.exp(rng.uniform(0, 4) * tt)
        data = data * gain[None, :]
    sig = float(np.percentile(np.abs(data), 99.5)) or 1.0
    data = data + rng.uniform(0.002, 0.08) * sig * rng.standard_normal(data.shape)
    if rng.random() < 0.3:  # DC offset
        data = data + rng.uniform(-0.2, 0.2) * sig
    return data


def echo_ringing(data: np.ndarray, dt: float, f: float, rng) -> np.ndarray:
    """Every echo of ``data`` followed by the antenna's ringing: each trace convolved with ``delta(t) + g sin(2 pi
    f_r (t - t1)) exp(-(t - t1) / tau)`` for ``t >= t1`` (one period of ``f`` after the echo's peak), ``f_r``
    0.7-1.3 ``f``, ``tau`` 1-4 periods, ``g`` such that an echo at ``f_r`` rings at 0.3-0.8 of its amplitude: the
    parallel copies of each hyperbola a few periods below it
    that a handheld scanner's pictures show under every bar (and that their labels leave out)."""
    n_s = data.shape[1]
    fr, tau, a = f * rng.uniform(0.7, 1.3), rng.uniform(1.0, 4.0) / f, rng.uniform(0.3, 0.8)
    t = np.arange(n_s) * dt - 1.0 / f
    tail = np.where(t >= 0, np.sin(2 * np.pi * fr * t) * np.exp(-np.maximum(t, 0) / tau), 0.0)
    # scaled so that an echo at f_r rings at a of its own amplitude (the tail's gain at f_r is 1 then)
    gain = abs(np.sum(tail * np.exp(-2j * np.pi * fr * np.arange(n_s) * dt)))
    kernel = a * tail / (gain or 1.0)
    kernel[0] += 1.0
    m = 2 * n_s
    spec = np.fft.rfft(data, m, axis=1) * np.fft.rfft(kernel, m)[None, :]
    return np.fft.irfft(spec, m, axis=1)[:, :n_s]


def _correlated_noise(shape, dt: float, f: float, rng) -> np.ndarray:
    """Unit-RMS noise in a band about ``f`` (a Gaussian of half its width in frequency) and smooth over a few
    traces: a wall's texture."""
    from scipy.ndimage import gaussian_filter1d

    n = gaussian_filter1d(rng.standard_normal(shape), float(rng.uniform(1.0, 6.0)), axis=0, mode="wrap")
    freqs = np.fft.rfftfreq(shape[1], dt)
    band = np.exp(-0.5 * ((freqs - f) / (0.5 * f)) ** 2)
    band[0] = 0.0  # no offset
    n = np.fft.irfft(np.fft.rfft(n, axis=1) * band, n=shape[1], axis=1)
    return n / (float(np.std(n)) or 1.0)


def display_8bit(data: np.ndarray, rng) -> np.ndarray:
    """``data`` as a scanner's 8-bit grey picture shows it: a gain that grows with time (sometimes), clipped at
    a level that saturates the direct wave (0.15-0.6 of the peak), 256 grey levels about mid-grey (128)."""
    n_s = data.shape[1]
    if rng.random() < 0.6:
        data = data * (1 + rng.uniform(0, 6) * (np.arange(n_s) / n_s) ** rng.uniform(0.7, 2.0))[None, :]
    level = float(rng.uniform(0.15, 0.6)) * (float(np.abs(data).max()) or 1.0)
    return np.round(np.clip(data / level, -1.0, 1.0) * 127.0) + 128.0


def survey_sample(seed: int, index: int, *, host: str | None = None, augment: bool = True, profile: str = "train",
                  ringing: float = 0.0, box_pad: float | None = None, pad_wavelet: bool = False):
    """``(Survey, labels)`` of survey-scale sample ``index``: the detector's training and test source
    (``profile="wall"``: P-GPR-like handheld wall scans, ``WALL_RANGES``; ``ringing``: the share of those whose
    echoes ring, :func:`echo_ringing`; ``box_pad``: the labels' time pad in periods, None: the rule's;
    ``pad_wavelet``: that pad in the drawn wavelet's periods, :func:`synthesize_survey`)."""
    scene = sample_survey_scene(seed, index, host=host, profile=profile)
    return synthesize_survey(scene, seed=int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1)[0]),
                             augment=augment, wall=profile == "wall", ringing=ringing, box_pad=box_pad,
                             pad_wavelet=pad_wavelet)


class SurveySource:
    """``source(i) -> survey_sample(seed, i)``: a picklable record source for training and evaluation."""

    def __init__(self, seed: int, *, augment: bool = True, profile: str = "train", ringing: float = 0.0,
                 box_pad: float | None = None, pad_wavelet: bool = False):
        if not isinstance(seed, int) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        if profile not in ("train", "wall"):
            raise ValueError(f"a survey source draws 'train' or 'wall' records, got {profile!r}")
        if not 0.0 <= ringing <= 1.0 or (ringing and profile != "wall"):
            raise ValueError(f"ringing is a share (0..1) of wall records, got {ringing!r} for profile {profile!r}")
        if box_pad is not None and not (isinstance(box_pad, (int, float)) and math.isfinite(box_pad)
                                        and 0.0 <= box_pad <= 2.0):
            raise ValueError(f"box_pad is the labels' time pad in periods (0..2), got {box_pad!r}")
        self.seed, self.augment, self.profile, self.ringing, self.box_pad = seed, augment, profile, ringing, box_pad
        self.pad_wavelet = bool(pad_wavelet)

    def __call__(self, i: int):
        return survey_sample(self.seed, i, augment=self.augment, profile=self.profile, ringing=self.ringing,
                             box_pad=self.box_pad, pad_wavelet=self.pad_wavelet)
