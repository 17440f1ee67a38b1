"""Live mode (issue 32): how many traces a second ``gpr3d live`` keeps up with, its lag and trace-to-target
latency, its memory over a long replay, and how far its final volume is from the batch ``reconstruct`` of the same
traces.

The survey is ``bench_stages.py``'s (``--traces`` raw A-scans of a cart's random path over 4 m x 4 m, 512 samples
over 40 ns, 500 MHz, the L-pipe scene, eps_r 9), written as ``survey.h5`` + ``path.tum``. ``gpr3d replay`` serves it
over TCP at each ``--rates`` (traces/s) and ``gpr3d live`` (a process of its own, every setting its default: 3 x 3 x
2 cm voxels, 50 degree aperture, detection on, 256-trace background window) takes it in; a rate is sustained when
live ends less than a second behind the last trace (its lag). ``--long N`` replays the survey N times more, each
pass 5 m further along x (``--loops``, ``--loop-shift``), and samples live's resident memory every second.
The batch reference: ``reconstruct`` of the same survey with the settings live wrote to ``config.json``.

    python benchmarks/bench_live.py [--traces 8000] [--rates 400 800 1600] [--long 25] [--threads 2]
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _report import cpu_name, threads_from_argv, write_table  # noqa: E402

if __name__ == "__main__":  # numba reads the thread count at import
    threads_from_argv()

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import shlex  # noqa: E402
import socket  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from bench_reconstruct import cart_path  # noqa: E402
from eval_reconstruction import EPS, F, NS, OFFSET, WINDOW, scene  # noqa: E402

from gpr3d.core.survey import Survey  # noqa: E402
from gpr3d.io.trajectory import write_tum  # noqa: E402
from gpr3d.io.volume import read_volume  # noqa: E402
from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct  # noqa: E402
from gpr3d.simulation.forward import forward_model  # noqa: E402


def free_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def rss_mib(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def _busy(summary: dict) -> str:
    """The seconds a live run spent migrating, detecting and refreshing (its summary's ``busy_s``)."""
    b = summary.get("busy_s") or {}
    return " / ".join(f"{b[k]:.1f}" if k in b else "-" for k in ("migrate", "detect", "refresh"))


def run_live_process(work: Path, name: str, source, env: dict, args=()) -> dict:
    """``gpr3d live SOURCE --out WORK/NAME --until-idle 3 ARGS`` in a process of its own, its resident memory
    sampled every second; its summary (``live.json``) with ``rss_mib`` (time, MiB), ``last_line`` and ``out``."""
    out = work / name
    t = time.perf_counter()
    # (its progress lines to a file: a pipe nobody reads while it runs would fill and stall it)
    with open(work / f"{name}.log", "w") as log:
        live = subprocess.Popen([sys.executable, "-m", "gpr3d", "live", source, "--out", out, "--until-idle", "3",
                                 *args], env=env, stdout=log, stderr=subprocess.STDOUT, text=True)
        samples = []
        while live.poll() is None:
            m = rss_mib(live.pid)
            if m is not None:
                samples.append((time.perf_counter() - t, m))
            time.sleep(1.0)
    stdout = (work / f"{name}.log").read_text()
    if live.returncode != 0:
        raise SystemExit(f"gpr3d live failed: {stdout.strip()[-2000:]}")
    summary = json.loads((out / "live.json").read_text())["summary"]
    summary.update(rss_mib=samples, last_line=stdout.strip().splitlines()[-1], out=out)
    return summary


def live_run(work: Path, rate: float, env: dict, name: str, *, loops: int = 1, extra=()) -> dict:
    port = free_port()
    server = subprocess.Popen([sys.executable, "-m", "gpr3d", "replay", work / "survey.h5", "--poses",
                               work / "path.tum", "--to", f"tcp://127.0.0.1:{port}", "--rate", str(rate),
                               "--loops", str(loops), "--loop-shift", "5"], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    summary = run_live_process(work, name, f"tcp://127.0.0.1:{port}", env, extra)
    server.wait(timeout=60)
    return summary


def fused_bag(work: Path, rate: float, n: int) -> tuple[Path, Path]:
    """A cart's run as a ROS 2 bag for ``gpr3d live --fuse``: ``/imu`` (200 Hz), ``/odometry`` (the camera's
    poses, 15 Hz) and ``/gpr/traces``: ``n`` traces at ``rate`` a second from the end of the still start, the
    benchmark's scene recorded along the antenna's true path; with its rig file."""
    from gpr3d.io.rosbag import write_bag
    from gpr3d.io.trajectory import read_tum
    from gpr3d.pipeline.poses import write_rig_recordings
    from gpr3d.pose.rig import RigConfig, simulate_rig

    still = 3.0
    run = simulate_rig(RigConfig(duration_s=still + max(n / rate + 1.0, 10.0), area=((0.0, 4.0), (0.0, 4.0)),
                                 turn_rate_rad_s=1.0, still_start_s=still), seed=1)
    folder = work / "fused"
    write_rig_recordings(run, folder)
    t = still + np.arange(n) / rate
    at = read_tum(folder / "truth.tum").at(t)
    data = forward_model(scene(), at.positions_xyz, at.orientations_quat_wxyz, offset_m=OFFSET, frequency_hz=F,
                         n_samples=NS, time_window_s=WINDOW, air_wave=1.0, ground_wave=0.5)
    write_bag(folder / "run", imu=run.imu, trajectory=read_tum(folder / "odometry.tum"), traces=(t, data))
    Survey(data=data, dt_s=WINDOW / NS, offset_m=OFFSET, frequency_hz=F, eps_r=EPS, timestamps_s=t).save(
        folder / "survey.h5")  # (the same traces, times on the IMU clock: for the TCP stream with sensor messages)
    return folder / "run", folder / "rig.json"


def tcp_fused_run(work: Path, rate: float, env: dict, extra=()) -> dict:
    """The fused bag's traces, IMU samples and camera poses sent over TCP by ``gpr3d replay --imu --odometry``, each
    message at its time; ``gpr3d live --fuse`` fuses the poses from them."""
    folder = work / "fused"
    port = free_port()
    server = subprocess.Popen([sys.executable, "-m", "gpr3d", "replay", folder / "survey.h5", "--imu",
                               folder / "imu.csv", "--odometry", folder / "odometry.tum", "--to",
                               f"tcp://127.0.0.1:{port}", "--rate", str(rate)], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    summary = run_live_process(work, "tcp_fused", f"tcp://127.0.0.1:{port}", env,
                               ["--fuse", "--rig", folder / "rig.json", "--still", "2", *extra])
    server.wait(timeout=60)
    return summary


def bag_run(work: Path, bag: Path, rig: Path, env: dict, extra=()) -> dict:
    return run_live_process(work, "bag_fused", bag, env, ["--dt", str(WINDOW / NS * 1e9), "--fuse", "--rig", rig,
                                                          "--still", "2", "--eps-r", str(EPS), "--offset",
                                                          str(OFFSET), *extra])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--traces", type=int, default=8000)
    ap.add_argument("--rates", type=float, nargs="+", default=[400.0, 800.0, 1600.0])
    ap.add_argument("--long", type=int, default=25, help="passes of the long replay (0: none)")
    ap.add_argument("--long-rate", type=float, default=800.0)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--bag-rate", type=float, default=800.0,
                    help="a ROS bag of as many traces at this rate, its poses fused by live mode (--fuse; 0: none)")
    ap.add_argument("--live-args", default="", help="more arguments for every gpr3d live run, e.g. '--refiner none'")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    args = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="gpr3d-bench-live-"))
    traj = cart_path(args.traces)
    data = forward_model(scene(), traj.positions_xyz, traj.orientations_quat_wxyz, offset_m=OFFSET, frequency_hz=F,
                         n_samples=NS, time_window_s=WINDOW, air_wave=1.0, ground_wave=0.5)
    s = Survey(data=data, dt_s=WINDOW / NS, offset_m=OFFSET, frequency_hz=F, eps_r=EPS)
    s.save(work / "survey.h5")
    write_tum(traj, work / "path.tum")
    env = {**os.environ, "NUMBA_NUM_THREADS": str(args.threads)}
    more = tuple(shlex.split(args.live_args))
    live_run(work, 4000.0, env, "warm", extra=("--no-detect",))  # numba's cache filled: compile apart
    rows = []
    first = None
    for rate in args.rates:
        r = live_run(work, rate, env, f"rate{rate:g}", extra=more)
        first = first or r
        rows.append((f"replayed at {rate:g} traces/s", r))
    r = live_run(work, 100000.0, env, "flat_out", extra=more)
    rows.append(("replayed as fast as it can send", r))
    if args.bag_rate:
        bag, rig = fused_bag(work, args.bag_rate, args.traces)
        rows.append((f"ROS bag at {args.bag_rate:g} traces/s (its own pace), poses fused from its IMU (200 Hz) and "
                     "odometry (15 Hz) as they come (`--fuse`)", bag_run(work, bag, rig, env, extra=more)))
        rows.append((f"TCP stream at {args.bag_rate:g} traces/s with the same IMU and camera pose messages, poses "
                     "fused as they come (`--fuse`)", tcp_fused_run(work, args.bag_rate, env, extra=more)))
    # the batch volume of the same traces with live's settings
    cfg = json.loads((first["out"] / "config.json").read_text())["config"]
    survey = s.replace(positions_xyz=traj.positions_xyz, orientations_quat_wxyz=traj.orientations_quat_wxyz)
    t = time.perf_counter()
    batch = reconstruct(survey, ReconstructConfig(**cfg))
    t_batch = time.perf_counter() - t
    vol = read_volume(first["out"] / "volume.h5")
    same_grid = vol.grid == batch.grid
    diff = float(np.abs(vol.arrays["image"] - batch.image).max() / np.abs(batch.image).max()) if same_grid else None
    host = cpu_name()
    lines = [f"Host CPU: {host}, {args.threads} threads; `gpr3d live` on {args.traces} traces x {NS} samples of a "
             f"random-motion survey served by `gpr3d replay` over TCP (poses in the stream), default settings "
             f"(3 x 3 x 2 cm voxels to {batch.grid.depth[-1]:.2f} m, 50 deg aperture, detection on)", "",
             "| run | traces | traces/s | lag at the end (s) | trace-to-target latency median / p99 / max (s) | "
             "tiles in memory at most | peak RSS (MiB) | targets | detections | detector behind: windows without "
             "overlap / traces no window saw | busy migrating / detecting / refreshing (s) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in rows:
        peak = max((m for _, m in r["rss_mib"]), default=float("nan"))
        lines.append(f"| {name} | {r['n_traces']} | {r['traces_per_s']:.0f} | {r['lag_s']:.2f} | "
                     f"{r['latency_s']['median']:.2f} / {r['latency_s']['p99']:.2f} / {r['latency_s']['max']:.2f} | "
                     f"{r['peak_tiles']} | "
                     f"{peak:.0f} | {r['n_targets']} | {r['n_detections']} | {r.get('detect_thinned', 0)} / "
                     f"{r.get('detect_skipped', 0)} | {_busy(r)} |")
    lines += ["", f"Final volume against the batch `reconstruct` of the same traces with live's settings "
                  f"({batch.grid.nx} x {batch.grid.ny} x {batch.grid.nd}, batch {t_batch:.1f} s in-process): same grid "
                  f"{same_grid}, max |live - batch| / max |batch| = {diff:.2e}" if diff is not None else
              f"grids differ: live {vol.grid}, batch {batch.grid}"]
    if args.long:
        r = live_run(work, args.long_rate, env, "long", loops=args.long + 1, extra=more)
        rss = r["rss_mib"]
        n = len(rss)
        marks = [rss[min(n - 1, int(f * (n - 1)))] for f in (0.1, 0.25, 0.5, 0.75, 1.0)] if n else []
        lines += ["", f"Long replay: {r['n_traces']} traces at {args.long_rate:g} traces/s ({args.long + 1} passes, "
                      f"each 5 m further along x): {r['traces_per_s']:.0f} traces/s, lag {r['lag_s']:.2f} s, latency "
                      f"median {r['latency_s']['median']:.2f} s / p99 {r['latency_s']['p99']:.2f} s / max "
                      f"{r['latency_s']['max']:.2f} s, at most "
                      f"{r['peak_tiles']} tiles in memory, {r['n_detections']} detections (detector behind: "
                      f"{r.get('detect_thinned', 0)} windows without overlap, {r.get('detect_skipped', 0)} traces "
                      f"no window saw; busy migrating / detecting / refreshing {_busy(r)} s); final volume "
                      f"written: {r['final_volume']}", "",
                  "| time (s) | " + " | ".join(f"{t:.0f}" for t, _ in marks) + " |",
                  "|---|" + "---|" * len(marks),
                  "| resident memory (MiB) | " + " | ".join(f"{m:.0f}" for _, m in marks) + " |",
                  "", f"last line: `{r['last_line']}`"]
    write_table(args.out, "bench_live.md", "\n".join(lines), "bench_live.py", argv)


if __name__ == "__main__":
    main()
