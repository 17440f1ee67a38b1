"""The end-to-end demonstration behind ``gpr3d demo``.

Stages so far (each later stage of the system adds its own):

1. **Real data** — read the embedded GSSI recording, process it (time zero,
   dewow, background removal, gain, band-pass) and draw it raw and processed, on
   time and depth axes.
2. **Synthetic data** — an analytic B-scan of point targets with known apexes,
   the same processing, and a check that the processed hyperbola apexes sit
   where the travel-time equation puts them; then the paper's wave-equation
   step, 2D reverse-time migration (Maxwell TM FDTD), focusing each point.
3. **Random-motion survey** — the synthetic cart rig wanders over a 2 m x 2 m
   patch of soil (an L-shaped pipe, a diagonal pipe, two rebars) for 200 s,
   steering to random waypoints, with stops; its survey wheel fires a trace
   every centimetre of the antenna's path, and the fast forward model makes each
   A-scan at the antenna's true 6-DoF pose, with clutter and noise. The poses the
   survey carries are estimated, as a user's would be: the visual-inertial
   fusion of its IMU, visual odometry (with gross errors), survey wheel and flat
   ground, smoothed, with loop closures where it crosses ground seen before, put
   into the site frame by the marked start. The survey, its
   estimated TUM trajectory and the true one are written for the stages that
   follow.
4. **3D reconstruction** — back projection of that survey from its estimated
   antenna poses into a voxel grid, target extraction, and the errors of the
   extracted targets against the true pipes (what ``gpr3d reconstruct`` does),
   beside the same from the true poses: what the pose error costs; then the
   same survey in site tiles (``gpr3d reconstruct --tile``), checked equal to the
   one-pass volume.
5. **Detection** — the shipped Faster R-CNN finds the hyperbolas in the
   random-motion survey's trace sequence (B-scans of consecutive traces) and in
   the real recording, and (with its target kinds) in a real labelled 1.6 GHz
   B-scan of a wall from P-GPR; overlays show its boxes and apexes; the survey is then
   migrated from the data inside the detected boxes only, with the rest as the
   noise map (``gpr3d reconstruct --mask detect``). Needs the ``dl`` extra
   (PyTorch); without it the stage is skipped with a one-line hint.
6. **Permittivity and depth** — from the data alone: DepthNet, the hyperbola fit
   and their hybrid estimate the host's eps_r and every detected target's depth
   (against the true eps_r 9 and the true depths of the pipes), and the eps_r that
   focuses the migrated boxes best (3D, from the poses); the masked migration of
   stage 5 runs with that estimate, not the truth; the real
   recording's estimate is shown beside its header's eps_r.
7. **Visual-inertial pose** — the synthetic cart rig (60 s of random motion with
   turns and stops, a 200 Hz IMU, 15 Hz visual odometry against keyframes with noise, gross
   errors and a 2 s tracking loss) fused by the error-state EKF; the fused
   path, odometry alone and the truth (TUM files and a plan view), with their
   APE through evo (needs the ``pose`` extra; skipped with a hint without it).

Everything goes to ``out_dir``: PNG figures, the processed survey as gpr3d HDF5,
``config.json`` and ``summary.json`` (all written atomically).
"""

from __future__ import annotations

import json
import platform
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from gpr3d import __version__
from gpr3d.core.atomic import atomic_write_text
from gpr3d.core.timing import stage
from gpr3d.core.units import velocity_from_eps_r

__all__ = ["DemoConfig", "run_demo"]


@dataclass
class DemoConfig:
    """What the demo runs on and how it processes."""

    input: str | None = None  #: radar file; None = the embedded example
    channel: int = 0
    time_zero_method: str = "first_break"
    time_zero_threshold: float = 0.3
    background_window_traces: int | None = None
    gain_power: float = 1.0
    bandpass: tuple[float, float] | None = None  #: (fmin_hz, fmax_hz); None = 0.4x..2x centre frequency
    synthetic_targets_xz: list = field(default_factory=lambda: [[0.3, 0.15], [0.9, 0.35]])
    synthetic_noise: float = 0.002
    cmap: str = "gray"
    walk_seconds: float = 200.0  #: the random-motion cart's run (about 0.4 m/s, with stops)
    walk_turn_rate: float = 1.0  #: rad/s, the most it turns by (steering to random waypoints in the patch)
    trace_spacing_m: float = 0.01  #: its survey wheel fires a trace every this much of the antenna's path
    walk_seed: int = 0


#: how the demo names the box refiner's label rules (gpr3d.detection.refine.RULES)
_RULE_NAMES = {"gpr3d": "gpr3d's label rule (recordings)", "pgpr": "P-GPR's label rule (pictures)"}

def _process(survey, cfg: DemoConfig, *, gain: bool = True):
    s = survey.time_zero(method=cfg.time_zero_method, threshold=cfg.time_zero_threshold)
    s = s.dewow()
    s = s.remove_background(window_traces=cfg.background_window_traces)
    if gain:
        s = s.gain_tpow(power=cfg.gain_power)
    if cfg.bandpass is None:
        s = s.bandpass()
    else:
        s = s.bandpass(fmin_hz=cfg.bandpass[0], fmax_hz=cfg.bandpass[1])
    return s


def _rtm_of_synthetic(syn, out: Path, log) -> dict:
    """The paper's wave-equation step on the synthetic B-scan: 2D reverse-time migration (Maxwell TM FDTD), and how
    far each focus lies from its point target."""
    from scipy.signal import hilbert

    from gpr3d.migration.rtm import rtm_bscan
    from gpr3d.viz._figures import pyplot, save_figure

    # the raw B-scan less its mean trace (the direct wave), from the synthetic's own time zero: the processed one
    # starts at the estimated time zero, which lies 0.65 ns early here (the direct wave's first break), and RTM
    # would place every point that much too deep
    x = syn.positions_xyz[:, 0]
    truth = syn.metadata["truth"]
    data = syn.data - syn.data.mean(axis=0, keepdims=True)
    r = rtm_bscan(data, x, syn.dt_s, frequency_hz=syn.frequency_hz, eps_r=syn.eps_r,
                  depth_m=max(t["depth_m"] for t in truth) + 0.2, t0_s=syn.metadata["true_t0_s"])
    env = np.abs(hilbert(r.image, axis=1))
    errs = []
    for t in truth:
        near = (np.abs(r.x_m - t["x_m"]) <= 0.1)[:, None] & (np.abs(r.depth_m - t["depth_m"]) <= 0.1)[None, :]
        i, k = np.unravel_index(int(np.argmax(np.where(near, env, -1.0))), env.shape)
        errs.append(float(np.hypot(r.x_m[i] - t["x_m"], r.depth_m[k] - t["depth_m"])))
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.2))
    ax.imshow(env.T, extent=(r.x_m[0], r.x_m[-1], r.depth_m[-1], r.depth_m[0]), cmap="gray_r", aspect="auto")
    ax.plot([t["x_m"] for t in truth], [t["depth_m"] for t in truth], "r+", ms=10)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("depth (m)")
    ax.set_title("synthetic B-scan, reverse-time migrated (envelope; red: true points)", fontsize=9)
    save_figure(fig, out / "synthetic_rtm.png", dpi=110)
    log(f"      reverse-time migration (2D Maxwell TM, {r.steps} steps of a {r.cell_m * 1e3:.1f} mm grid, "
        f"{r.wall_s:.2f} s): foci " + ", ".join(f"{e * 100:.1f} cm" for e in errs) + " from the true points")
    return {"focus_error_m": errs, "cell_m": r.cell_m, "steps": r.steps, "wall_s": r.wall_s,
            "figure": "synthetic_rtm.png"}


def _envelope_peak_near(survey, trace, time_s, half_traces=5, half_s=1.5e-9):
    """The strongest envelope pick among the traces near ``trace``: (trace, time s from the first sample)."""
    from gpr3d.processing.picking import pick_peak

    env = survey.envelope().data
    i = int(round(trace))
    picks = [(pick_peak(env, survey.dt_s, j, time_s, half_s), j)
             for j in range(max(i - half_traces, 0), min(i + half_traces + 1, survey.n_traces))]
    (t, _), j = max(picks, key=lambda p: p[0][1])
    return j, t


def demo_scene():
    """The demo's buried scene (soil, eps_r 9): an L-shaped pipe, a diagonal pipe and two rebars."""
    from gpr3d.simulation.forward import ForwardScene, Pipe

    z_l, r_l = -0.5 - 0.04, 0.04
    return ForwardScene(
        eps_r=9.0, conductivity_s_m=0.002,
        pipes=[Pipe((0.4, 0.5, z_l), (1.6, 0.5, z_l), r_l), Pipe((1.6, 0.5, z_l), (1.6, 1.7, z_l), r_l),
               Pipe((0.3, 0.9, -0.35 - 0.03), (1.2, 1.8, -0.35 - 0.03), 0.03),
               Pipe((0.2, 0.2, -0.2 - 0.01), (0.2, 1.8, -0.2 - 0.01), 0.01),
               Pipe((1.85, 0.2, -0.25 - 0.01), (1.85, 1.8, -0.25 - 0.01), 0.01)],
    )


def _survey_poses(cfg: DemoConfig, log, rig_dir=None):
    """The cart's true antenna poses at its survey wheel's traces, and the poses the visual-inertial fusion
    estimates for them (what a user has), in the site frame; the sensors' recordings written into ``rig_dir``
    (what ``gpr3d run --imu`` fuses)."""
    import numpy as np

    from gpr3d.pose.eskf import fuse
    from gpr3d.pose.graph import close_loops
    from gpr3d.pose.rig import RigConfig, simulate_rig
    from gpr3d.pose.sync import trajectory_triggers

    # the antenna 0.3 m behind the IMU at its height (the ground); the cart steers over the 2 m x 2 m patch
    rig = RigConfig(duration_s=cfg.walk_seconds, area=((0.0, 2.0), (0.0, 2.0)), turn_rate_rad_s=cfg.walk_turn_rate,
                    stops=max(3, int(cfg.walk_seconds // 60)), vo_keyframe_m=0.1,
                    imu_T_antenna=np.array([[1.0, 0, 0, -0.3], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    run = simulate_rig(rig, seed=cfg.walk_seed)
    if rig_dir is not None:
        from gpr3d.pipeline.poses import write_rig_recordings

        write_rig_recordings(run, rig_dir)
    truth = run.truth_trajectory()
    trig = trajectory_triggers(truth, cfg.trace_spacing_m)
    t = time.perf_counter()
    res = fuse(run.imu, run.vo, run.filter_config(flat_ground_sigma_m=0.01), wheel=run.wheel(), smooth=True)
    # revisits of ground seen before close loops (modelled as a camera measures them; 5 % wrong)
    closures = run.loop_closures(res.frame_t_s, outlier_rate=0.05, seed=cfg.walk_seed)
    res = close_loops(res, closures)
    wall = time.perf_counter() - t
    est = run.to_world(res.antenna_trajectory()).at(trig)
    true = truth.at(trig)
    err = np.linalg.norm(est.positions_xyz - true.positions_xyz, axis=1)
    info = {"rig_seconds": rig.duration_s, "imu_hz": rig.imu_rate_hz, "camera_hz": rig.camera_rate_hz,
            "fuse_s": wall, "vo_outliers": int(run.vo_outliers.sum()), "vo_rejected": int(res.vo_rejected.sum()),
            "loop_closures": len(closures),
            "antenna_error_mean_m": float(err.mean()), "antenna_error_max_m": float(err.max())}
    return true, est, info


def _random_motion_stage(out: Path, cfg: DemoConfig, log) -> dict:
    from gpr3d.core.deps import available
    from gpr3d.core.survey import Survey
    from gpr3d.io.trajectory import write_tum
    from gpr3d.simulation.forward import forward_model
    from gpr3d.viz.bscan import save_bscan_png
    from gpr3d.viz.maps import save_survey_map_png

    scene = demo_scene()
    true, est, pose = _survey_poses(cfg, log, rig_dir=out / "rig")
    f, n_samples, window = 500e6, 512, 40e-9
    kw = dict(offset_m=0.1, frequency_hz=f, n_samples=n_samples, time_window_s=window, air_wave=1.0,
              ground_wave=0.5, clutter=30, noise=0.002, seed=cfg.walk_seed)
    forward_model(scene, true.positions_xyz[:8], true.orientations_quat_wxyz[:8], **kw)  # compile once
    t = time.perf_counter()
    data = forward_model(scene, true.positions_xyz, true.orientations_quat_wxyz, **kw)  # the ground's truth
    t_fwd = time.perf_counter() - t
    # the survey carries the poses the fusion estimated, as a user's would; the truth goes beside it
    survey = Survey(data=data, dt_s=window / n_samples, timestamps_s=est.timestamps_s,
                    positions_xyz=est.positions_xyz, orientations_quat_wxyz=est.orientations_quat_wxyz,
                    offset_m=0.1, frequency_hz=f, eps_r=scene.eps_r,
                    metadata={"format": "forward", "antenna": "forward model, 500 MHz",
                              "poses": "visual-inertial fusion (IMU, odometry, survey wheel, flat ground; smoothed, "
                                       "loop closures)",
                              "scene": {"eps_r": scene.eps_r, "pipes": [p.__dict__ for p in scene.pipes]},
                              "truth_t0_s": 2 ** 0.5 / f})
    survey.save(out / "random_walk_survey.h5")
    write_tum(est, out / "random_walk.tum")
    write_tum(true, out / "random_walk_truth.tum")
    save_survey_map_png(out / "random_walk_map.png", true.positions_xyz, pipes=scene.pipes,
                        title=f"random-motion survey: {len(true)} traces over the buried pipes")
    shown = survey[: min(800, survey.n_traces)].time_zero(method="peak", search_s=6e-9).remove_background()
    save_bscan_png(shown.gain_tpow(power=1.0), out / "random_walk_bscan.png", cmap="gray",
                   title="random-motion survey, first 800 traces (time zero, background removed, t-gain)")
    rate = survey.n_traces / t_fwd
    path = float(true.path_length_m()[-1])
    if available("evo"):
        from gpr3d.pose.metrics import ape

        pose["fused_ape_m"] = ape(est, true)["rmse"]
    log(f"[3/8] random-motion survey: {survey.n_traces} A-scans x {n_samples} samples from the forward model "
        f"in {t_fwd * 1e3:.0f} ms ({rate:,.0f} A-scans/s); a trace every {cfg.trace_spacing_m * 100:g} cm of "
        f"the antenna's {path:.1f} m path")
    log(f"      antenna poses from the visual-inertial fusion ({pose['rig_seconds']:.0f} s of IMU and odometry, "
        f"{pose['vo_rejected']} frames gated out, smoothed, {pose['loop_closures']} loop closures, "
        f"{pose['fuse_s']:.1f} s): error at the traces mean "
        f"{pose['antenna_error_mean_m'] * 100:.1f} cm, max {pose['antenna_error_max_m'] * 100:.1f} cm"
        + (f", APE {pose['fused_ape_m'] * 100:.1f} cm" if "fused_ape_m" in pose else ""))
    log(f"      the cart's recordings in {out / 'rig'}/ (imu.csv, odometry.tum, wheel.csv, rig.json): "
        f"gpr3d run {out / 'random_walk_survey.h5'} --imu {out / 'rig' / 'imu.csv'} ... fuses them itself")
    return {"n_traces": survey.n_traces, "n_samples": n_samples, "forward_s": t_fwd, "ascans_per_s": rate,
            "path_m": path, "poses": pose,
            "files": ["random_walk_survey.h5", "random_walk.tum", "random_walk_truth.tum", "random_walk_map.png",
                      "random_walk_bscan.png", "rig/imu.csv", "rig/odometry.tum", "rig/wheel.csv", "rig/rig.json",
                      "rig/truth.tum"]}


def _named(ev: dict) -> dict:
    """``evaluate_targets``' target indices as the names ``targets.json`` and the figures give them (T1, ...)."""
    from gpr3d.migration.targets import target_name

    for r in ev["truth"]:
        r["found_as"] = [target_name(i) for i in r["found_as"]]
    ev["false"] = [target_name(i) for i in ev["false"]]
    return ev


def _as(r) -> str:
    return f" as {', '.join(r['found_as'])}" if r["found_as"] else ""


def _reconstruction_stage(out: Path, log) -> dict:
    from gpr3d.core.survey import Survey
    from gpr3d.io.trajectory import read_tum
    from gpr3d.migration.metrics import evaluate_targets, truth_lines_from_pipes
    from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct
    from gpr3d.pipeline.reconstruction import write_result

    survey = Survey.load(out / "random_walk_survey.h5")
    true = read_tum(out / "random_walk_truth.tum")
    pipes = demo_scene().pipes
    names = ["L leg along x", "L leg along y", "diagonal pipe", "rebar at x=0.2", "rebar at x=1.85"]
    rows = {}
    for key, s, folder in (("estimated", survey, "reconstruction"),
                           ("true", survey.replace(positions_xyz=true.positions_xyz,
                                                   orientations_quat_wxyz=true.orientations_quat_wxyz), None)):
        t = time.perf_counter()
        result = reconstruct(s, ReconstructConfig(spacing_m=0.02, max_depth_m=0.8))
        wall = time.perf_counter() - t
        if folder:
            write_result(result, out / folder, source="random_walk_survey.h5")
        ev = _named(evaluate_targets(result.targets, truth_lines_from_pipes(pipes)))
        rows[key] = {"wall_s": wall, "n_targets": len(result.targets), "false_targets": ev["false_targets"],
                     "false_lines": ev["false_lines"], "false_points": ev["false_points"], "false": ev["false"],
                     "excess_fraction": ev["excess_fraction"],
                     "truth": [{"target": n, **r} for n, r in zip(names, ev["truth"])],
                     "updates_per_s": result.updates_per_s, "grid": result.grid.to_dict()}
        if key == "estimated":
            g, mig = result.grid, result.timings_s["migrate"]
            result_targets, result_refine = result.targets, result.refine or {}
    log(f"[4/8] 3D reconstruction: {survey.n_traces} traces -> {g.nx} x {g.ny} x {g.nd} voxels in "
        f"{rows['estimated']['wall_s']:.1f} s (migration {mig:.1f} s, "
        f"{rows['estimated']['updates_per_s'] / 1e9:.2f} G updates/s counted over every voxel); targets from the fused "
        "poses (from the true poses):")
    for i, name in enumerate(names):
        cells = []
        for key in ("estimated", "true"):
            r = rows[key]["truth"][i]
            cells.append(f"position {r['position_error_m'] * 100:4.1f} cm, depth {r['depth_error_m'] * 100:4.1f} cm, "
                         f"orientation {r['orientation_error_deg']:4.1f} deg, ends {r['endpoint_error_m'] * 100:4.1f} cm "
                         f"off, complete {r['completeness'] * 100:3.0f} %" if "position_error_m" in r
                         else f"found as points only, complete {r['completeness'] * 100:3.0f} %" if r["completeness"] > 0
                         else "not found")
        log(f"      {name:<16}{_as(rows['estimated']['truth'][i]):<9} {cells[0]}  ({cells[1]})")
    est_, tru_ = rows["estimated"], rows["true"]
    false_names = f" ({', '.join(est_['false'])})" if est_["false"] else ""
    log(f"      {est_['n_targets']} targets (T1..T{est_['n_targets']} in reconstruction/: targets.json and the "
        f"figures): {est_['false_lines']} false lines, {est_['false_points']} false points{false_names}, "
        f"overshoot {est_['excess_fraction'] * 100:.0f} % of the true length ({tru_['n_targets']} targets, "
        f"{tru_['false_lines']} false lines, {tru_['false_points']} false points, {tru_['excess_fraction'] * 100:.0f} % "
        "from the true poses)")
    # the depth range that gpr3d reconstruct --signal-depth would choose (the demo images to 0.8 m, its pipes')
    from gpr3d.core.units import velocity_from_eps_r
    from gpr3d.migration.reconstruct import grid_depth_m, time_zero_search_s

    prepared = survey.time_zero(method="peak", search_s=time_zero_search_s(survey)).remove_background()
    _, depth = grid_depth_m(prepared, ReconstructConfig(signal_depth=True), velocity_from_eps_r(survey.eps_r),
                            survey.positions_xyz)
    log(f"      depth range: {depth['why']}; gpr3d reconstruct --signal-depth would image to {depth['depth_m']:.2f} m "
        f"of the record's {depth['record_m']:.2f} m (the demo to 0.8 m, its pipes' depth)")
    # coarse-to-fine is the default (a coarse pass over every few columns, then every voxel of the depths where
    # that image holds energy): the same survey with every voxel migrated (gpr3d reconstruct --no-coarse-to-fine),
    # and the targets against the default's
    ref = result_refine
    t = time.perf_counter()
    every = reconstruct(survey, ReconstructConfig(spacing_m=0.02, max_depth_m=0.8, coarse_to_fine=False))
    wall_every = time.perf_counter() - t
    ev_every = _named(evaluate_targets(every.targets, truth_lines_from_pipes(pipes)))
    matched, moved = _counterparts(result_targets, every.targets)
    log(f"      coarse-to-fine (the default): {ref.get('refined_fraction', 1.0) * 100:.0f} % of the voxels migrated at "
        f"full resolution (coarse columns every {ref.get('stride', 1)}), migration {mig:.1f} s against "
        f"{every.timings_s['migrate']:.1f} s for every voxel (--no-coarse-to-fine); {len(result_targets)} targets "
        f"against {len(every.targets)}, {matched} of them within {moved * 100:.1f} cm of one there; false targets "
        f"{rows['estimated']['false_targets']} against {ev_every['false_targets']}")
    # site scale: the same survey in tiles, each from only the traces whose cone reaches it (gpr3d reconstruct
    # --tile / --workers, every voxel migrated); the volume must be the every-voxel one-pass volume bit for bit
    from gpr3d.migration.sitetiles import plan_tiles

    t = time.perf_counter()
    tiled = reconstruct(survey, ReconstructConfig(spacing_m=0.02, max_depth_m=0.8, tile_m=0.64))
    wall_tiles = time.perf_counter() - t
    same = bool(np.array_equal(tiled.image, every.image))
    n_tiles = len(plan_tiles(tiled.grid, 0.64))
    log(f"      site scale: in {n_tiles} tiles of 0.64 m with the cone's halo ({wall_tiles:.1f} s), the volume "
        f"{'equals the one-pass volume bit for bit' if same else 'DIFFERS from the one-pass volume'}")
    # an aperture radius (gpr3d reconstruct --aperture-radius): each trace's cone cut off at 0.5 m about its
    # midpoint, so a deep voxel sums no more traces than one 0.42 m down (the cone reaches 0.95 m at 0.8 m)
    rad = reconstruct(survey, ReconstructConfig(spacing_m=0.02, max_depth_m=0.8, aperture_m=0.5))
    ev_rad = _named(evaluate_targets(rad.targets, truth_lines_from_pipes(pipes)))
    matched_r, moved_r = _counterparts(rad.targets, result_targets)
    log(f"      aperture radius 0.5 m: migration {rad.timings_s['migrate']:.1f} s against {mig:.1f} s; "
        f"{len(rad.targets)} targets against {len(result_targets)}, {matched_r} of them within {moved_r * 100:.1f} cm "
        f"of one there; false targets {ev_rad['false_targets']} against {rows['estimated']['false_targets']}")
    est = rows["estimated"]
    return {"wall_s": est["wall_s"], "grid": est["grid"], "updates_per_s": est["updates_per_s"],
            "n_targets": est["n_targets"], "false_targets": est["false_targets"], "truth": est["truth"],
            "false_lines": est["false_lines"], "false_points": est["false_points"], "false": est["false"],
            "excess_fraction": est["excess_fraction"],
            "poses": "estimated (visual-inertial fusion)", "with_true_poses": rows["true"], "folder": "reconstruction",
            "depth_range": depth,
            "tiles": {"n": n_tiles, "tile_m": 0.64, "wall_s": wall_tiles, "equal_to_one_pass": same},
            "coarse_to_fine": {"migrate_s": mig, "refine": ref, "every_voxel": {
                "wall_s": wall_every, "migrate_s": every.timings_s["migrate"], "n_targets": len(every.targets),
                "false_targets": ev_every["false_targets"]}, "matched": matched, "largest_move_m": moved},
            "aperture_radius": {"radius_m": 0.5, "migrate_s": rad.timings_s["migrate"], "n_targets": len(rad.targets),
                                "false_targets": ev_rad["false_targets"], "matched": matched_r,
                                "largest_move_m": moved_r,
                                "completeness": [float(r["completeness"]) for r in ev_rad["truth"]]}}


def _counterparts(a, b, within_m: float = 0.05) -> tuple[int, float]:
    """How many targets of ``a`` have a counterpart in ``b`` (the same kind and number of points, every point
    within ``within_m`` of its own), and the farthest any of those lies from it (m; 0 when none)."""
    n, far = 0, 0.0
    for x in a:
        px = np.asarray(x.points_xyz, float)
        moves = [float(np.abs(px - np.asarray(y.points_xyz, float)).max()) for y in b
                 if y.kind == x.kind and np.shape(y.points_xyz) == px.shape]
        if moves and min(moves) <= within_m:
            n, far = n + 1, max(far, min(moves))
    return n, far


def _detection_stage(out: Path, real_path: str, log) -> dict:
    from gpr3d.core.deps import available
    from gpr3d.core.survey import Survey

    if not (available("torch") and available("torchvision")):
        log("[5/8] detection skipped: PyTorch is not installed (pip install 'gpr3d[dl]')")
        return {"skipped": "torch not installed"}
    from gpr3d.detection.infer import load_detector
    from gpr3d.io.detections import write_detections
    from gpr3d.io.registry import read
    from gpr3d.migration.metrics import evaluate_targets, truth_lines_from_pipes
    from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct
    from gpr3d.pipeline.reconstruction import write_result
    from gpr3d.viz.bscan import save_bscan_png

    det = load_detector()  # ONNX Runtime when installed, else PyTorch
    survey = Survey.load(out / "random_walk_survey.h5")
    t = time.perf_counter()
    found = det.detect(survey, score_threshold=0.5, input_name="random_walk_survey.h5")
    t_det = time.perf_counter() - t
    write_detections([found], out / "detections.json")
    boxes = [tg["box"] for tg in found["targets"]]
    shown = survey[:800].dewow().remove_background()
    first = [tg for tg in found["targets"] if tg["box"][0] < 800]
    save_bscan_png(shown, out / "detections_bscan.png", cmap="gray", boxes=[tg["box"] for tg in first],
                   apexes=[(tg["apex_trace"], tg["apex_time_s"]) for tg in first],
                   title=f"detected hyperbolas, first 800 of {survey.n_traces} traces (score >= 0.5)")
    real = read(real_path)
    real_found = det.detect(real, score_threshold=0.5, input_name=Path(real_path).name)
    save_bscan_png(real.dewow().remove_background(), out / "detections_real.png", cmap="gray",
                   boxes=[tg["box"] for tg in real_found["targets"]],
                   apexes=[(tg["apex_trace"], tg["apex_time_s"]) for tg in real_found["targets"]],
                   title=f"{Path(real_path).name}: {len(real_found['targets'])} detections (score >= 0.5)")
    log(f"[5/8] detection: {len(boxes)} hyperbolas in the {survey.n_traces}-trace survey ({found['n_windows']} "
        f"windows in {t_det:.1f} s), {len(real_found['targets'])} in {Path(real_path).name}")
    how = found.get("refine") or {}
    if how.get("rule") or how.get("quality_weight"):
        log(f"      boxes placed by the refiner's head for {_RULE_NAMES.get(how.get('rule'), 'its rule')}"
            + (f", each score times the box's predicted fit (IoU with its label) to the power "
               f"{how['quality_weight']:g}" if how.get("quality_weight") else ""))
    row = {"n_boxes": len(boxes), "detect_s": t_det, "n_windows": found["n_windows"],
           "real_detections": len(real_found["targets"]), "refine": found.get("refine"),
           "pgpr": _pgpr_rows(det, out, log)}
    if not boxes:
        log("      no boxes: depth estimation and masked migration skipped")
        return row
    from gpr3d.io.trajectory import read_tum

    depth = _depth_rows(survey, found, real, real_found, log, read_tum(out / "random_walk_truth.tum").positions_xyz[:, :2])
    row["depth"] = depth
    # the B-scan estimators read oblique crossings as a faster wave: with 3D poses, the eps_r that focuses the
    # migrated boxes best is the one to migrate with
    import numpy as np

    from gpr3d.migration.velocity import focus_eps

    hyb = depth["random_walk"]["eps_r"]
    t = time.perf_counter()
    # images compared in migrated time (focus_eps's default window), 4 cm cells: on a fixed depth grid of 5 cm
    # cells the entropy drifts down at high eps_r and a detector with 18 more boxes moved the focus from 8.6 to 12.7
    # (benchmarks/results/intel/focus_window.md)
    foc = focus_eps(survey, boxes=boxes, eps_grid=np.linspace(np.sqrt(0.6 * hyb), np.sqrt(1.8 * hyb), 7) ** 2,
                    spacing_m=0.04, max_depth_m=0.8)
    depth["random_walk"]["focus"] = {"eps_r": foc["eps_r"], "at_edge": foc["at_edge"], "wall_s": time.perf_counter() - t}
    log(f"      migration focus (3D, from the poses) eps_r {foc['eps_r']:5.2f} in {time.perf_counter() - t:.0f} s "
        f"(the hybrid's {hyb:.2f}; true {depth['random_walk']['eps_r_true']:g})")
    eps_est = foc["eps_r"]
    t = time.perf_counter()
    result = reconstruct(survey, ReconstructConfig(eps_r=eps_est, spacing_m=0.02, max_depth_m=0.8), boxes=boxes)
    wall = time.perf_counter() - t
    write_result(result, out / "reconstruction_masked", source="random_walk_survey.h5")
    names = ["L leg along x", "L leg along y", "diagonal pipe", "rebar at x=0.2", "rebar at x=1.85"]
    ev = _named(evaluate_targets(result.targets, truth_lines_from_pipes(demo_scene().pipes)))
    for name, r in zip(names, ev["truth"]):
        if "position_error_m" in r:
            log(f"      {name:<16}{_as(r):<9} position {r['position_error_m'] * 100:4.1f} cm, complete "
                f"{r['completeness'] * 100:3.0f} %")
        else:
            log(f"      {name:<16}{_as(r):<9} " + ("found as points only" if r["found_as"] else "not found"))
    log(f"      migrated inside the detected boxes only, with the estimated eps_r {eps_est:.2f}, in {wall:.1f} s: "
        f"{len(result.targets)} targets, {ev['false_targets']} false"
        + (f" ({', '.join(ev['false'])})" if ev["false"] else "") + " (noise map in reconstruction_masked/)")
    row.update({"masked_eps_r": eps_est, "masked_eps_r_source": "estimated (migration focus)", "masked_wall_s": wall, "masked_targets": len(result.targets),
                "masked_false_targets": ev["false_targets"], "masked_false": ev["false"], "masked_truth": ev["truth"],
                "folder": "reconstruction_masked"})
    return row


def _pgpr_rows(det, out: Path, log) -> dict:
    """The detector on the embedded real P-GPR B-scan (1.6 GHz, a wall with rebars and pipes), against its labels."""
    from gpr3d.data import example_pgpr
    from gpr3d.detection.evaluate import box_matches
    from gpr3d.io.yolo import read_yolo
    from gpr3d.viz.bscan import save_bscan_png

    (survey, labels), = read_yolo(example_pgpr(), names=["steel", "pipe"], kinds="pipe=pvc_pipe",
                                  pixel_map="s_per_px=3.125e-11", frequency_hz=1.6e9)
    name = Path(labels["image"]).name
    t = time.perf_counter()
    res = det.detect(survey, score_threshold=0.5, input_name=name)
    wall = time.perf_counter() - t
    truth = labels["labels"]
    # one to one, best score first: a label is found by a box at IoU >= 0.5, of the right kind or not
    px = np.array([1.0, 1 / survey.dt_s, 1.0, 1 / survey.dt_s])  # traces and samples

    def matches(found):
        return box_matches([np.asarray(lab["box"]) * px for lab in truth], [lab["kind"] for lab in truth],
                           [np.asarray(tg["box"]) * px for tg in found], [tg["kind"] for tg in found],
                           [tg["score"] for tg in found])

    hits = matches(res["targets"])
    found = sum(h is not None for h in hits)
    right = sum(bool(h and h[2]) for h in hits)
    fit = {"refined": _mean_best_iou(truth, res["targets"], px)}
    if det.refiner is not None:  # the same detector without its box refiner: the network's own boxes
        refiner, det.refiner = det.refiner, None
        try:
            fit["network"] = _mean_best_iou(truth, det.detect(survey, score_threshold=0.5)["targets"], px)
        finally:
            det.refiner = refiner
        if res["refine"].get("fine"):  # and without the refiner's fine stage: its passes' boxes
            fine, refiner.fine = refiner.fine, None
            try:
                fit["no_fine"] = _mean_best_iou(truth, det.detect(survey, score_threshold=0.5)["targets"], px)
            finally:
                refiner.fine = fine
    # the picture seen mirrored too (gpr3d detect --mirror): both views' boxes fused
    mirror, det.mirror = det.mirror, True
    try:
        both = det.detect(survey, score_threshold=0.5)["targets"]
    finally:
        det.mirror = mirror
    fit["mirrored"] = _mean_best_iou(truth, both, px)
    found_both = sum(h is not None for h in matches(both))
    kinds = [tg["kind"] for tg in res["targets"]]
    named = ", ".join(f"{kinds.count(k)} {k}" for k in sorted(set(kinds))) or "none"
    truth_kinds = [lab["kind"] for lab in truth]
    save_bscan_png(survey, out / "detections_pgpr.png", cmap="gray", boxes=[tg["box"] for tg in res["targets"]],
                   box_labels=[f"{tg['kind']} {tg['score']:.2f}" for tg in res["targets"]],
                   truth_boxes=[lab["box"] for lab in truth],
                   title=f"real 1.6 GHz B-scan {name} (P-GPR, CC BY 4.0): detections (cyan), labels (yellow)")
    log(f"      real P-GPR B-scan {name} (1.6 GHz wall; Yue et al., CC BY 4.0): {len(kinds)} hyperbolas ({named}) "
        f"in {wall:.1f} s; of its {len(truth)} labelled ({truth_kinds.count('rebar')} rebar, "
        f"{truth_kinds.count('pvc_pipe')} pipe) {found} found at IoU >= 0.5, {right} of them of the right kind")
    shares = [tg["kind_shares"] for tg in res["targets"] if tg.get("kind_shares")]
    sure = None
    if shares:  # how sure the detector was of the kinds it named: the mean share, and its least sure box's two best
        least = min(shares, key=lambda sh: max(sh.values()))
        two = sorted(least, key=least.get, reverse=True)[:2]
        sure = {"mean": float(np.mean([max(sh.values()) for sh in shares])),
                "least_sure": {k: float(least[k]) for k in two}}
        log(f"      kinds named with a mean share of {sure['mean']:.2f}; the least sure box: "
            f"{two[0]} {least[two[0]]:.2f}, {two[1]} {least[two[1]]:.2f} (every kind's share in detections: "
            "kind_shares)")
    if "network" in fit:
        how = res["refine"]
        looks = f"{'each box also seen mirrored, ' if how['mirror'] else ''}{how['passes']} pass" + \
            ("es" if how["passes"] > 1 else "")
        rule = f"{_RULE_NAMES[how['rule']]}, " if how.get("rule") in _RULE_NAMES else ""
        then = f", then its fine stage {how['fine']}" if how.get("fine") else ""
        without = f" ({fit['no_fine']:.2f} without the fine stage)" if "no_fine" in fit else ""
        log(f"      boxes placed by the box refiner ({res['refiner']}; {rule}{looks}{then}): mean IoU with the labels "
            f"{fit['refined']:.2f}{without}, the network's own boxes {fit['network']:.2f}")
    log(f"      seen mirrored too (--mirror, the two views' boxes fused): {found_both} of {len(truth)} found, mean IoU "
        f"{fit['mirrored']:.2f}")
    return {"image": name, "n_detections": len(kinds), "kinds": {k: kinds.count(k) for k in set(kinds)},
            "n_labelled": len(truth), "found_iou50": found, "found_iou50_mirrored": found_both, "right_kind": right,
            "kind_shares": sure, "detect_s": wall,
            "mean_iou": fit, "refiner": res["refiner"], "refine": res["refine"],
            "figure": "detections_pgpr.png"}


def _mean_best_iou(truth, targets, px) -> float:
    """The mean over the labels of the best IoU any of ``targets`` reaches with each (0 where none overlaps)."""
    from gpr3d.detection.refine import pair_iou

    if not truth:
        return float("nan")
    lab = np.array([np.asarray(x["box"]) * px for x in truth]).reshape(-1, 4)
    if not targets:
        return 0.0
    box = np.array([np.asarray(x["box"]) * px for x in targets]).reshape(-1, 4)
    return float(pair_iou(lab[:, None, :], box[None, :, :]).max(axis=1).mean())


def _true_top_depth(point_xy, apex_time_s, pipes, *, t0_s, v_m_s, offset_m, tolerance_s) -> float:
    """Depth of the top of the buried pipe whose echo explains a detection: the pipe whose first arrival at
    the surface point ``point_xy`` (slant range to its surface, tx-rx offset included) comes closest to the
    detection's apex time; NaN when none comes within ``tolerance_s`` (clutter, a false detection)."""
    import numpy as np

    p = np.array([point_xy[0], point_xy[1], 0.0])
    best = (np.inf, np.nan)
    for pp in pipes:
        a, b = np.asarray(pp.p0, float), np.asarray(pp.p1, float)
        u = np.clip(np.dot(p - a, b - a) / max(np.dot(b - a, b - a), 1e-12), 0, 1)
        q = a + u * (b - a)
        r = float(np.linalg.norm(p - q)) - pp.radius_m
        t = t0_s + 2 * np.hypot(r, offset_m / 2) / v_m_s
        best = min(best, (abs(t - apex_time_s), -q[2] - pp.radius_m))
    return best[1] if best[0] <= tolerance_s else float("nan")


def _depth_rows(survey, found, real, real_found, log, true_xy) -> dict:
    """Host eps_r and target depths estimated from the data (DepthNet, fit, hybrid) against the truth
    (``true_xy``: the antenna's true positions at the traces, which the truth of each echo needs)."""
    import numpy as np

    from gpr3d.inversion.depthnet import DepthEstimator
    from gpr3d.inversion.estimate import estimate_depths

    est = DepthEstimator.load()
    pipes = demo_scene().pipes
    truth_eps = demo_scene().eps_r
    kw = dict(t0_s=survey.metadata["truth_t0_s"], v_m_s=velocity_from_eps_r(truth_eps), offset_m=survey.offset_m,
              tolerance_s=1.0 / survey.frequency_hz)
    truth = [_true_top_depth(true_xy[int(t["apex_trace"])], t["apex_time_s"], pipes, **kw)
             for t in found["targets"]]
    out = {"random_walk": {"eps_r_true": truth_eps, "n_matched": int(np.sum(np.isfinite(truth)))}}
    for m in ("net", "fit", "hybrid"):
        r = estimate_depths(survey, found["targets"], method=m, estimator=est)
        errs = []
        for d_true, e in zip(truth, r["targets"]):
            if np.isfinite(e["depth_m"]) and np.isfinite(d_true):
                errs.append(e["depth_m"] - d_true)
        out["random_walk"][m] = {"eps_r": r["permittivity"]["eps_r"], "sigma_eps_r": r["permittivity"]["sigma_eps_r"],
                                 "depth_mae_m": float(np.mean(np.abs(errs))) if errs else None,
                                 "depth_median_abs_m": float(np.median(np.abs(errs))) if errs else None,
                                 "n_depths": len(errs)}
        if m == "hybrid":
            out["random_walk"]["eps_r"] = r["permittivity"]["eps_r"]
            out["random_walk"]["targets"] = [{"apex_trace": t["apex_trace"], "depth_m": e["depth_m"],
                                              "depth_true_m": d_true}
                                             for t, e, d_true in zip(found["targets"], r["targets"], truth)]
    rw = out["random_walk"]
    log(f"[6/8] depth from the data (random-motion survey, true eps_r {truth_eps:g}; depth error over the "
        f"{out['random_walk']['n_matched']} of {len(found['targets'])} detections that a pipe's echo explains, "
        "median / mean):")
    for m in ("net", "fit", "hybrid"):
        e = rw[m]
        depth = (f"{e['depth_median_abs_m'] * 100:.1f} / {e['depth_mae_m'] * 100:.1f} cm"
                 if e["depth_mae_m"] is not None else "n/a")
        log(f"      {m:<7} eps_r {e['eps_r']:5.2f} +- {e['sigma_eps_r']:.2f}, depth {depth}")
    if real_found["targets"] and real.distances_m is not None:
        r = estimate_depths(real, real_found["targets"], method="hybrid", estimator=est)
        p = r["permittivity"]
        out["real"] = {"eps_r": p["eps_r"], "sigma_eps_r": p["sigma_eps_r"], "eps_r_header": real.eps_r,
                       "net": p.get("net", {}).get("eps_r"), "fit": p.get("fit", {}).get("eps_r"),
                       "depth_m": [e["depth_m"] for e in r["targets"]]}
        log(f"      real recording: eps_r {p['eps_r']:.2f} +- {p['sigma_eps_r']:.2f} (hybrid; header says "
            f"{real.eps_r:g})")
    elif real.distances_m is None:
        out["real"] = {"skipped": "the recording has no trace positions"}
    return out


def _pose_stage(out: Path, log) -> dict:
    from gpr3d.core.deps import available
    from gpr3d.io.trajectory import write_tum
    from gpr3d.pose.eskf import fuse
    from gpr3d.pose.rig import RigConfig, simulate_rig
    from gpr3d.viz.maps import save_paths_png

    rig = RigConfig(duration_s=60.0, vo_gap=(30.0, 2.0), vo_keyframe_m=0.1)  # odometry against keyframes, as pose.vo
    run = simulate_rig(rig, seed=2)
    t = time.perf_counter()
    res = fuse(run.imu, run.vo, run.filter_config())
    wall = time.perf_counter() - t
    fused, vo, truth = res.antenna_trajectory(), run.vo_trajectory(), run.truth_trajectory()
    for name, tr in (("pose_fused.tum", fused), ("pose_vo_alone.tum", vo), ("pose_truth.tum", truth)):
        write_tum(tr, out / name)
    info = {"path_m": run.path_length_m, "duration_s": rig.duration_s, "fuse_s": wall,
            "vo_outliers": int(run.vo_outliers.sum()), "vo_rejected": int(res.vo_rejected.sum()),
            "zupt_updates": res.zupt_count,
            "files": ["pose_fused.tum", "pose_vo_alone.tum", "pose_truth.tum", "pose_paths.png"]}
    if available("evo"):
        from gpr3d.pose.metrics import ape

        info["fused_ape_m"] = ape(fused, truth)["rmse"]
        info["vo_alone_ape_m"] = ape(vo, run.truth_trajectory(vo.timestamps_s))["rmse"]
        msg = (f"APE {info['fused_ape_m'] * 100:.1f} cm fused ({100 * info['fused_ape_m'] / run.path_length_m:.2f} % of "
               f"the path) vs {info['vo_alone_ape_m'] * 100:.1f} cm odometry alone")
    else:
        info["skipped_ape"] = "evo is not installed: pip install 'gpr3d[pose]'"
        msg = "APE skipped (pip install 'gpr3d[pose]' for evo)"
    # plan view in one frame: the truth, and both estimates aligned to it at their first pose
    def at_start(tr):
        ref = run.truth_trajectory(tr.timestamps_s[:1])
        R0 = _quat_matrix(ref.orientations_quat_wxyz[0]) @ _quat_matrix(tr.orientations_quat_wxyz[0]).T
        return (tr.positions_xyz - tr.positions_xyz[0]) @ R0.T + ref.positions_xyz[0]
    save_paths_png(out / "pose_paths.png", {"truth": truth.positions_xyz, "odometry alone": at_start(vo),
                                            "fused (IMU + odometry)": at_start(fused)},
                   title=f"visual-inertial pose: {run.path_length_m:.0f} m in {rig.duration_s:.0f} s, "
                         "odometry lost for 2 s")
    log(f"[7/8] visual-inertial pose: {run.path_length_m:.1f} m of random motion fused in {wall:.1f} s; {msg}; "
        f"{info['vo_rejected']} odometry frames gated out ({info['vo_outliers']} gross errors planted)")
    return info


def _live_stage(out: Path, log, rate: float = 4000.0) -> dict:
    """The random-motion survey served over TCP (``gpr3d replay``'s server, in a thread) at ``rate`` traces/s to
    live mode (``gpr3d live``), then its final volume against the batch reconstruct with the settings it wrote."""
    import threading

    from gpr3d.core.survey import Survey
    from gpr3d.io.trajectory import read_tum
    from gpr3d.io.volume import read_volume
    from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct
    from gpr3d.pipeline.live import LiveConfig, open_source, run_live
    from gpr3d.pipeline.replay import replay_to_tcp

    survey = Survey.load(out / "random_walk_survey.h5")
    est = read_tum(out / "random_walk.tum")
    survey = survey.replace(positions_xyz=est.positions_xyz, orientations_quat_wxyz=est.orientations_quat_wxyz)
    ports: list = []
    ready = threading.Event()
    server = threading.Thread(target=replay_to_tcp, args=(survey, 0), daemon=True,
                              kwargs=dict(rate=rate, on_listen=lambda p: (ports.append(p), ready.set())))
    server.start()
    if not ready.wait(30):
        raise RuntimeError("the demo's replay server did not start")
    from gpr3d.core.deps import available

    detector = None
    if available("torch") and available("torchvision"):
        from gpr3d.detection.infer import fastest_engine, load_detector

        detector = load_detector(engine=fastest_engine())  # as gpr3d live: the 8-bit graph where it can
    cfg = LiveConfig(reconstruct=ReconstructConfig(spacing_m=0.03, depth_spacing_m=0.02, max_depth_m=0.8),
                     detect=detector is not None, until_idle_s=1.0)
    folder = out / "live"
    summ = run_live(open_source(f"tcp://127.0.0.1:{ports[0]}"), folder, cfg, detector=detector, log=None)
    server.join(30)
    settings = json.loads((folder / "config.json").read_text())["config"]
    batch = reconstruct(survey, ReconstructConfig(**settings))
    vol = read_volume(folder / "volume.h5")
    same = vol.grid == batch.grid
    diff = float(np.abs(vol.arrays["image"] - batch.image).max() / np.abs(batch.image).max()) if same else None
    found = (f"the detector ({detector.provenance.get('name', 'shipped')}) run on each window as it filled "
             f"({summ.n_detections} hyperbolas), " if detector else "")
    verdict = ("grids differ" if diff is None else
               f"the final volume {'equals' if diff < 1e-4 else 'DIFFERS from'} the batch reconstruct with the same "
               f"settings (max difference {diff:.1e} of its peak)")
    log(f"[8/8] live: the survey streamed over TCP at {rate:,.0f} traces/s (gpr3d replay) into gpr3d live: each "
        f"trace migrated once as it came, into tiles that follow the cart (at most {summ.peak_tiles} in memory), "
        f"{found}targets refreshed while it ran (trace-to-target latency median {summ.latency_s['median']:.2f} s); "
        f"{verdict}")
    log(f"      {summ.line()}")
    return {"n_traces": summ.n_traces, "traces_per_s": summ.traces_per_s, "lag_s": summ.lag_s,
            "latency_s": summ.latency_s, "peak_tiles": summ.peak_tiles, "n_targets": summ.n_targets,
            "n_detections": summ.n_detections if detector else None,
            "same_grid": same, "max_difference": diff, "folder": "live", "rate": rate}


def _quat_matrix(q_wxyz):
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat([q_wxyz[1], q_wxyz[2], q_wxyz[3], q_wxyz[0]]).as_matrix()


def _real_stage(out: Path, cfg: DemoConfig, log):
    """Stage 1: the embedded real recording read, processed and drawn; returns (its path, its summary)."""
    from gpr3d.data import example_dzt
    from gpr3d.io.registry import read
    from gpr3d.viz.bscan import save_bscan_png

    src = cfg.input or str(example_dzt())
    t = time.perf_counter()
    raw = read(src, channel=cfg.channel)
    t_read = time.perf_counter() - t
    t = time.perf_counter()
    proc = _process(raw, cfg)
    t_proc = time.perf_counter() - t
    log(f"[1/8] read {Path(src).name}: {raw}")
    log(f"      processed ({', '.join(h['step'] for h in proc.history)}) in {t_proc * 1e3:.0f} ms")
    voxel = None
    if raw.eps_r:  # the grid gpr3d reconstruct would image this record on: its voxel follows the antenna
        from gpr3d.migration.reconstruct import voxel_spacing_m

        voxel, how = voxel_spacing_m(raw.frequency_hz, raw.eps_r)
        log(f"      reconstruct's voxel for it: {voxel * 100:.3g} cm, {how} (the header's eps_r)")
    save_bscan_png(raw, out / "real_raw.png", cmap=cfg.cmap, title=f"{Path(src).name}: raw")
    save_bscan_png(proc, out / "real_processed.png", cmap=cfg.cmap, title=f"{Path(src).name}: processed")
    if proc.eps_r:
        save_bscan_png(proc, out / "real_processed_depth.png", axis="depth", cmap="hot",
                       title=f"{Path(src).name}: processed, depth axis (header eps_r)")
    proc.save(out / "real_processed.h5")
    return src, {
        "input": Path(src).name,
        "format": raw.metadata.get("format"),
        "n_traces": raw.n_traces,
        "n_samples": raw.n_samples,
        "dt_s": raw.dt_s,
        "range_s": raw.time_window_s,
        "antenna": raw.metadata.get("antenna"),
        "frequency_hz": raw.frequency_hz,
        "eps_r_header": raw.eps_r,
        "estimated_t0_s": proc.history[0]["result"]["t0_s"],
        "voxel_m": voxel,
        "processing": [{"step": h["step"], "args": h["args"]} for h in proc.history],
        "read_s": t_read,
        "process_s": t_proc,
        "traces_per_s": raw.n_traces / (t_read + t_proc),
        "figures": sorted(p.name for p in out.glob("real_*.png")),
    }


def _synthetic_stage(out: Path, cfg: DemoConfig, log) -> dict:
    """Stage 2: a synthetic B-scan with known apexes, its apexes found again, and its RTM."""
    from gpr3d.simulation.synthetic import point_targets_bscan
    from gpr3d.viz.bscan import save_bscan_png

    syn = point_targets_bscan(cfg.synthetic_targets_xz, noise=cfg.synthetic_noise)
    # no gain here: a time-varying gain moves the envelope peak later (by ~power/t' of the peak width)
    syn_proc = _process(syn, cfg, gain=False)
    # samples before the estimated time zero were cut: image time + t0_est = recorded time
    t0_est = syn_proc.history[0]["result"]["t0_s"]
    rows = []
    for truth in syn.metadata["truth"]:
        i, t_img = _envelope_peak_near(syn_proc, truth["apex_trace"], truth["apex_time_s"] - t0_est)
        t_abs = t_img + t0_est
        rows.append({
            "x_m": truth["x_m"], "depth_m": truth["depth_m"],
            "apex_trace_true": truth["apex_trace"], "apex_trace_found": i,
            "apex_time_true_s": truth["apex_time_s"], "apex_time_found_s": t_abs,
            "apex_time_error_s": t_abs - truth["apex_time_s"],
        })
    boxes = [(r["apex_trace_found"] - 15, r["apex_time_found_s"] - t0_est - 1.5e-9,
              r["apex_trace_found"] + 15, r["apex_time_found_s"] - t0_est + 3e-9) for r in rows]
    save_bscan_png(syn, out / "synthetic_raw.png", cmap=cfg.cmap, title="synthetic point targets: raw")
    save_bscan_png(syn_proc, out / "synthetic_processed.png", cmap="hot", boxes=boxes,
                   title="synthetic point targets: processed (boxes: windows around the found apexes)")
    log(f"[2/8] synthetic B-scan {syn.shape}: apex time errors "
        + ", ".join(f"{r['apex_time_error_s'] * 1e9:+.2f} ns" for r in rows)
        + f" (time zero estimated at {t0_est * 1e9:.2f} ns)")
    rtm = _rtm_of_synthetic(syn, out, log)
    return {
        "shape": list(syn.shape),
        "eps_r": syn.eps_r,
        "estimated_t0_s": t0_est,
        "true_t0_s": syn.metadata["true_t0_s"],
        "apexes": rows,
        "boxes": [[float(v) for v in b] for b in boxes],
        "rtm": rtm,
    }


def run_demo(out_dir="gpr3d_demo", config: DemoConfig | None = None, *, log=print) -> dict:
    """Run the demo into ``out_dir`` and return the summary (also written to ``summary.json``); where its time
    went, stage by stage (:mod:`gpr3d.core.timing`), is printed at the end and written to ``timings.json``."""
    from gpr3d.core.timing import collect, format_table

    with collect() as times:
        summary = _run_demo(Path(out_dir), config or DemoConfig(), log)
    out = Path(out_dir)
    rows = times.rows()
    summary["timings_s"] = dict(rows)
    atomic_write_text(out / "timings.json", json.dumps(times.to_dict(), indent=1))
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2, default=float))
    log(f"wrote {len(list(out.iterdir()))} files to {out}/ in {summary['total_s']:.1f} s")
    log(format_table(rows, title="where the demo's time went (seconds; 'compile': numba, once per machine)"))
    return summary


def _run_demo(out: Path, cfg: DemoConfig, log) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "config.json", json.dumps({"gpr3d": __version__, "config": asdict(cfg)}, indent=2))
    summary: dict = {"gpr3d": __version__, "python": platform.python_version(), "stages": {}}
    t_start = time.perf_counter()

    # 1. real recording; 2. synthetic B-scan with known apexes -------------------------------
    with stage("demo 1: real recording"):
        src, summary["stages"]["real"] = _real_stage(out, cfg, log)
    with stage("demo 2: synthetic B-scan"):
        summary["stages"]["synthetic"] = _synthetic_stage(out, cfg, log)

    # 3. random-motion survey from the forward model --------------------------------------
    with stage("demo 3: random-motion survey"):
        summary["stages"]["random_motion"] = _random_motion_stage(out, cfg, log)

    # 4. 3D reconstruction of the random-motion survey -------------------------------------
    with stage("demo 4: reconstruction"):
        summary["stages"]["reconstruction"] = _reconstruction_stage(out, log)

    # 5. detection and detection-masked migration ----------------------------------------------
    with stage("demo 5-6: detection, depths, masked migration"):
        summary["stages"]["detection"] = _detection_stage(out, src, log)

    # 7. visual-inertial pose of a random-motion cart ---------------------------------------
    with stage("demo 7: pose"):
        summary["stages"]["pose"] = _pose_stage(out, log)

    # 8. live: the same survey streamed as a radar delivers it, migrated as it comes -----------------
    with stage("demo 8: live"):
        summary["stages"]["live"] = _live_stage(out, log)

    # the report: the masked reconstruction of the random-motion survey on one page to open in a browser
    if (out / "reconstruction_masked" / "targets.json").exists():
        from gpr3d.pipeline.report import write_report

        t = time.perf_counter()
        with stage("demo: report"):
            page = write_report(out, survey=out / "random_walk_survey.h5", detections=out / "detections.json",
                                reconstruction=out / "reconstruction_masked", out=out / "report.html",
                                title="gpr3d demo: random-motion survey, detection-masked 3D reconstruction")
        summary["report"] = str(page.relative_to(out))
        log(f"      report: {page} ({time.perf_counter() - t:.1f} s; B-scan with boxes, depth slices, noise map, "
            "3D view: open it in a browser)")

    summary["total_s"] = time.perf_counter() - t_start
    return summary
