"""Live mode against the batch reconstruct of the same traces: the volume it puts together from its tiles equals
the batch one (with the settings live mode writes to config.json) whether the traces come over TCP or from a
DZT file that grows, and whether its tiles stayed in memory or went to disk and came back."""

import json
import threading
import time
from dataclasses import replace

import numpy as np
import pytest

from gpr3d import Survey
from gpr3d.core.errors import GPR3DError, InvalidDataError
from gpr3d.core.poses import quat_from_yaw
from gpr3d.io.dzt import read_dzt
from gpr3d.io.stream import StreamHeader
from gpr3d.io.volume import read_volume
from gpr3d.migration.reconstruct import ReconstructConfig, reconstruct
from gpr3d.pipeline.live import (BagSource, LiveConfig, LiveReconstruction, SourceReader, open_source,
                                 run_live)
from gpr3d.pipeline.replay import pace, replay_to_file, replay_to_tcp
from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model
from tests.io.makers import write_dzt

EPS = 6.0
DT = 12e-9 / 128


def _zigzag(n_lines=6, per=70, length=1.4, step=0.12):
    pos, yaw = [], []
    for k in range(n_lines):
        x = np.linspace(0.0, length, per)
        pos.append(np.c_[x if k % 2 == 0 else x[::-1], np.full(per, step * k), np.zeros(per)])
        yaw.append(np.full(per, 0.0 if k % 2 == 0 else np.pi))
    return np.concatenate(pos), quat_from_yaw(np.concatenate(yaw))


@pytest.fixture(scope="module")
def survey():
    pos, q = _zigzag()
    scene = ForwardScene(eps_r=EPS, pipes=[Pipe((0.6, -0.5, -0.22), (0.6, 1.5, -0.22), 0.02)])
    data = forward_model(scene, pos, q, offset_m=0.05, frequency_hz=800e6, n_samples=128, time_window_s=12e-9,
                         air_wave=1.0, ground_wave=0.5, noise=0.01)
    return Survey(data=data, dt_s=DT, offset_m=0.05, frequency_hz=800e6, eps_r=EPS, positions_xyz=pos,
                  orientations_quat_wxyz=q)


def _cfg(**kw):
    rc = ReconstructConfig(spacing_m=0.03, aperture_deg=45.0, aperture_m=kw.pop("aperture_m", None))
    return LiveConfig(reconstruct=rc, background_window=kw.pop("background_window", 32), detect=False,
                      until_idle_s=kw.pop("until_idle_s", 3.0), refresh_s=kw.pop("refresh_s", 0.2),
                      time_zero_traces=40, **kw)


def _batch_equals_live(survey, out):
    cfg = json.loads((out / "config.json").read_text())["config"]
    assert cfg["lattice"] and cfg["background_window"] and cfg["time_zero_s"] > 0
    assert cfg["background_trailing"] == json.loads((out / "live.json").read_text())["config"]["background_trailing"]
    batch = reconstruct(survey, ReconstructConfig(**cfg))
    vol = read_volume(out / "volume.h5")
    assert vol.grid == batch.grid
    ref = np.abs(batch.image).max()
    # the same float32 sums in another order (per batch and tile, per thread): each voxel sums at most a few
    # hundred terms of at most the peak, so the orders differ by a few hundred float32 roundings (6e-8 each) of
    # the peak at worst, on any CPU and thread count; measured 2e-7 to 2e-6. A wrong window, time zero or tile
    # offset moves voxels by tens of percent of the peak
    np.testing.assert_allclose(vol.arrays["image"], batch.image, rtol=0, atol=2e-5 * ref)
    got = json.loads((out / "targets.json").read_text())
    assert len(got) == len(batch.targets) >= 1
    return batch


def _serve(survey, rate, **kw):
    ports = []
    ready = threading.Event()
    th = threading.Thread(target=replay_to_tcp, args=(survey, 0), daemon=True,
                          kwargs=dict(rate=rate, on_listen=lambda p: (ports.append(p), ready.set()), **kw))
    th.start()
    assert ready.wait(10)
    return th, ports[0]


@pytest.mark.parametrize("trailing", [True, False])
def test_live_over_tcp_equals_the_batch_volume(survey, tmp_path, trailing):
    th, port = _serve(survey, 4000.0)
    summary = run_live(open_source(f"tcp://127.0.0.1:{port}"), tmp_path, _cfg(background_trailing=trailing),
                       log=None)
    th.join(10)
    assert summary.n_traces == survey.n_traces
    lat = summary.latency_s
    assert set(lat) == {"median", "p99", "max"} and 0 < lat["median"] <= lat["p99"] <= lat["max"]
    assert summary.line() == (f"{survey.n_traces} traces, {summary.traces_per_s:.0f} traces/s, "
                              f"lag {summary.lag_s:.2f} s")
    batch = _batch_equals_live(survey, tmp_path)
    # the pipe (along y at x = 0.6, top 0.22 m deep) found
    t = batch.targets[0]
    assert abs(np.mean([p[0] for p in t.points_xyz]) - 0.6) < 0.05 and abs(t.depth_m - 0.22) < 0.05
    status = json.loads((tmp_path / "live.json").read_text())
    assert status["n_traces_migrated"] == survey.n_traces and status["summary"]["n_traces"] == survey.n_traces


def test_live_with_an_aperture_radius_equals_the_batch_volume(survey, tmp_path):
    """A radius narrower than the cone below 0.12 m of depth (the 45 deg cone reaches about 0.7 m at the grid's
    bottom): live mode's tiles and reach follow it, and its volume is the batch one's with the same radius (the
    image without the radius differs from it by more than 5 % of its peak, far beyond the tolerance)."""
    th, port = _serve(survey, 4000.0)
    run_live(open_source(f"tcp://127.0.0.1:{port}"), tmp_path, _cfg(aperture_m=0.12), log=None)
    th.join(10)
    batch = _batch_equals_live(survey, tmp_path)
    assert batch.config["aperture_m"] == 0.12
    wide = reconstruct(survey, ReconstructConfig(**{**batch.config, "aperture_m": None}))
    assert np.abs(wide.image - batch.image).max() > 0.05 * np.abs(batch.image).max()


def test_tiles_written_out_and_read_back_keep_the_volume(survey, tmp_path):
    """Small tiles and a short window: the far end of each line leaves the cart's reach, goes to disk and is
    read back when the next line passes it."""
    header = StreamHeader(n_samples=survey.n_samples, dt_s=DT, frequency_hz=800e6, offset_m=0.05, eps_r=EPS)
    live = LiveReconstruction(header, _cfg(tile_voxels=4, background_window=8, min_batch=1), tmp_path)
    poses = np.c_[survey.positions_xyz, survey.orientations_quat_wxyz]
    reloaded = 0
    for a in range(0, survey.n_traces, 25):
        live.add(survey.data[a:a + 25], poses[a:a + 25])
        before = set(live.on_disk)
        live.step()
        reloaded += len(before & set(live.tiles))
    assert live.on_disk and reloaded > 0
    assert live.peak_tiles < len(live.on_disk | set(live.tiles))
    live.refresh()  # the preview, before the end: the pipe (along y at x = 0.6, 0.22 m deep) is in it
    lines = [t for t in live.targets if t.kind == "line"]
    assert any(abs(np.mean([p[0] for p in t.points_xyz]) - 0.6) < 0.05 and abs(t.depth_m - 0.22) < 0.05
               for t in lines), live.targets
    live.finish()
    _batch_equals_live(survey, tmp_path)


def test_traces_wait_for_a_batch_but_not_for_a_due_refresh(survey, tmp_path):
    """Migration in batches of ``min_batch`` traces or more (each batch costs a grid over its reach), at most
    ``max_batch`` at a time; a due refresh first migrates whatever waits, and a backlog is shown part by part."""
    header = StreamHeader(n_samples=survey.n_samples, dt_s=DT, frequency_hz=800e6, offset_m=0.05, eps_r=EPS)
    live = LiveReconstruction(header, _cfg(min_batch=50, max_batch=20, refresh_s=3600.0), tmp_path)
    poses = np.c_[survey.positions_xyz, survey.orientations_quat_wxyz]

    def feed(a, b):
        live.add(survey.data[a:b], poses[a:b])
        return live.step()

    # the first refresh is due at once: 20 traces migrated, shown, then the other 25 of the backlog (the next
    # refresh an hour away)
    assert feed(0, 45) == 45 and live.n_final == 45 and live.n_refreshed == 20 and len(live.latencies) == 1
    assert feed(45, 75) == 0 and live.n_final == 45  # 30 waiting: fewer than a batch
    assert feed(75, 95) == 50 and live.n_final == 95 and live.n_refreshed == 20  # 50: a batch, no refresh yet
    live.last_refresh -= 3600.0  # the refresh due: the 3 waiting traces migrated first, then all 98 shown
    assert feed(95, 98) == 3 and live.n_final == live.n_refreshed == 98 and len(live.latencies) == 2
    # a due refresh first takes in what came while the step worked (the reader's queue), and shows it too
    live.intake = lambda: live.add(survey.data[98:110], poses[98:110])
    assert live.step() == 0  # not due: nothing taken in, nothing migrated
    assert live.n_in == 98
    live.last_refresh -= 3600.0
    assert live.step() == 12 and live.n_in == live.n_final == live.n_refreshed == 110
    live.intake = None
    assert live.step(ended=True) == 0
    live.finish()
    _batch_equals_live(survey[:110], tmp_path)


def _dzt_of(survey, path):
    """``survey`` as a 32-bit DZT (header from the test maker, samples scaled to integers)."""
    write_dzt(path, n_traces=0, n_samples=survey.n_samples, bits=32, range_ns=survey.n_samples * DT * 1e9,
              eps_r=EPS, antennas=("800",))
    ints = np.round(survey.data / np.abs(survey.data).max() * 2e8).astype("<i4")
    with open(path, "ab") as f:
        f.write(ints.tobytes())
    return path


def _tum_of(survey, path):
    """``survey``'s poses as a TUM file (``t x y z qx qy qz qw``), a trace every 10 ms."""
    path.write_text("".join(f"{i * 0.01:.2f} " + " ".join(repr(float(v)) for v in (*p, *r[1:], r[0])) + "\n"
                            for i, (p, r) in enumerate(zip(survey.positions_xyz, survey.orientations_quat_wxyz))))
    return path


def test_a_growing_dzt_with_growing_poses_equals_the_batch_volume(survey, tmp_path):
    src = _dzt_of(survey, tmp_path / "rec.dzt")
    tum = _tum_of(survey, tmp_path / "rec.tum")
    q = survey.orientations_quat_wxyz
    grow, grow_tum = tmp_path / "live.dzt", tmp_path / "live.tum"
    th = threading.Thread(target=replay_to_file, args=(src, grow), daemon=True,
                          kwargs=dict(rate=3000.0, poses=tum, poses_out=grow_tum))
    th.start()
    out = tmp_path / "out"
    source = open_source(grow, poses=grow_tum, offset_m=0.05)
    summary = run_live(source, out, _cfg(until_idle_s=1.5), log=None)
    th.join(10)
    assert summary.n_traces == survey.n_traces
    assert source.header.frequency_hz == 800e6  # from the antenna's name in the DZT header
    rec = read_dzt(src)[0].replace(positions_xyz=survey.positions_xyz, orientations_quat_wxyz=q, offset_m=0.05,
                                   frequency_hz=800e6)
    _batch_equals_live(rec, out)


def _dt1_of(survey, stem):
    """``survey`` as a pulseEKKO DT1/HD pair (16-bit samples scaled from the survey's; 800 MHz, 5 cm apart)."""
    stem.with_suffix(".HD").write_text(
        f"1234\nData Collected with a test\n2026-12-05\nNUMBER OF TRACES   = {survey.n_traces}\n"
        f"NUMBER OF PTS/TRC  = {survey.n_samples}\nTOTAL TIME WINDOW  = {survey.n_samples * DT * 1e9!r}\n"
        "POSITION UNITS     = m\nNOMINAL FREQUENCY  = 800\nANTENNA SEPARATION = 0.05\n")
    ints = np.round(survey.data / np.abs(survey.data).max() * 3e4).astype("<i2")
    with open(stem.with_suffix(".DT1"), "wb") as f:
        for i, row in enumerate(ints):
            h = np.zeros(32, "<f4")
            h[0], h[1], h[2], h[5] = i + 1, 0.01 * i, survey.n_samples, 2
            f.write(h.tobytes() + row.tobytes())
    return stem.with_suffix(".DT1")


def test_a_growing_dt1_with_growing_poses_equals_the_batch_volume(survey, tmp_path):
    from gpr3d.io.dt1 import read_dt1

    src = _dt1_of(survey, tmp_path / "rec")
    tum = _tum_of(survey, tmp_path / "rec.tum")
    grow, grow_tum = tmp_path / "live" / "LINE.DT1", tmp_path / "live.tum"
    grow.parent.mkdir()
    th = threading.Thread(target=replay_to_file, args=(src, grow), daemon=True,
                          kwargs=dict(rate=3000.0, poses=tum, poses_out=grow_tum))
    th.start()
    out = tmp_path / "out"
    source = open_source(grow, poses=grow_tum)  # (the HD copied beside it first: its interval and antenna)
    cfg = _cfg(until_idle_s=1.5)
    cfg.reconstruct = replace(cfg.reconstruct, eps_r=EPS)  # (a DT1 names no permittivity: --eps-r)
    summary = run_live(source, out, cfg, log=None)
    th.join(10)
    assert summary.n_traces == survey.n_traces
    assert (source.header.frequency_hz, source.header.offset_m) == (800e6, 0.05)
    assert source.header.dt_s == pytest.approx(DT, rel=1e-12)
    rec = read_dt1(src)[0].replace(positions_xyz=survey.positions_xyz,
                                   orientations_quat_wxyz=survey.orientations_quat_wxyz)
    assert (rec.offset_m, rec.frequency_hz) == (0.05, 800e6)
    _batch_equals_live(rec, out)


def test_pace_hands_out_each_item_once_never_early():
    now = [0.0]
    slept = []

    def sleep(s):
        slept.append(s)
        now[0] += s

    got = []
    for a, b in pace(10, 4.0, clock=lambda: now[0], sleep=sleep):
        got.append((a, b, now[0]))
        now[0] += 0.6 if a == 3 else 0.0  # the consumer falls behind once
    assert [g[:2] for g in got][0] == (0, 1)
    assert [i for a, b, _ in got for i in range(a, b)] == list(range(10))
    for a, b, t in got:
        assert (b - 1) / 4.0 <= t + 1e-12  # the last item of each range was due
    assert any(b - a > 1 for a, b, _ in got)  # caught up in one range
    with pytest.raises(GPR3DError, match="replay rate must be a positive number"):
        next(pace(3, 0.0))


@pytest.mark.parametrize("kw, message", [
    (dict(aperture_deg=None), "live mode needs an aperture"),
    (dict(method="pseudo3d"), "live mode migrates by back projection"),
])
def test_live_refuses_settings_it_cannot_run(kw, message, tmp_path):
    header = StreamHeader(n_samples=64, dt_s=1e-10, eps_r=4.0)
    cfg = LiveConfig(reconstruct=ReconstructConfig(**{"aperture_deg": 45.0, **kw}))
    with pytest.raises(GPR3DError, match=message):
        LiveReconstruction(header, cfg, tmp_path)


def test_live_without_eps_r_anywhere_is_refused(tmp_path):
    with pytest.raises(GPR3DError, match="no eps_r: the stream's header gives none"):
        LiveReconstruction(StreamHeader(n_samples=64, dt_s=1e-10), LiveConfig(), tmp_path)


@pytest.mark.parametrize("source, kw, message", [
    ("tcp://host", {}, "expected tcp://HOST:PORT"),
    ("tcp://host:99999", {}, "expected tcp://HOST:PORT"),
    ("tcp://127.0.0.1:5600", {"poses": "p.tum"}, "--poses is for a growing file"),
    ("rec.sgy", {"poses": "p.tum"}, "rec.sgy: live mode reads growing DZT or DT1 files"),
    ("rec.dt1", {"poses": "p.tum", "channel": 1}, "rec.dt1: a DT1 file holds one channel"),
    ("rec.dzt", {"poses": "p.tum", "bag": {"dt_s": 1e-10}}, "rec.dzt: --dt are for a ROS bag"),
    ("rec.dt1", {"poses": "p.tum", "bag": {"dt_s": 1e-10, "speed": 2.0}}, "rec.dt1: --dt, --speed are for a ROS bag"),
    ("rec.dzt", {}, "live mode needs the antenna's poses"),
])
def test_wrong_sources_are_named(source, kw, message):
    with pytest.raises(GPR3DError, match=message):
        open_source(source, **kw)


def test_a_source_where_nothing_comes_ends_in_one_line(tmp_path):
    source = open_source(str(tmp_path / "never.dzt"), poses=tmp_path / "never.tum")
    with pytest.raises(GPR3DError, match="never.dzt: no traces arrived in 0.3 s"):
        run_live(source, tmp_path / "out", _cfg(until_idle_s=0.1, start_timeout_s=0.3), log=None)


def test_a_tcp_source_nobody_serves_ends_in_one_line(tmp_path):
    import socket

    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    source = open_source(f"tcp://127.0.0.1:{port}", connect_s=0.3)
    with pytest.raises(GPR3DError, match="no connection after 0.3 s"):
        run_live(source, tmp_path / "out", _cfg(), log=None)


class _Spans:
    """A detector stand-in: records the spans it is given; finds one box per span around its middle trace, its
    score rising with the span's start (a later window sees the hyperbola better)."""

    def __init__(self, traces=8, overlap=0.5):
        from types import SimpleNamespace

        self.window = SimpleNamespace(traces=traces, overlap=overlap)
        self.provenance = {"name": "stand-in"}
        self.spans = []
        self.shared = 0

    def share_cores(self):
        self.shared += 1

    def detect(self, survey, *, score_threshold, input_name=None):
        n = survey.n_traces
        self.spans.append((int(survey.data[0, 2]), n))  # (samples 0 and 1 are a DZT's counter and mark)
        mid = n // 2
        return {"targets": [{"box": [mid - 1.0, 1e-9, mid + 1.0, 2e-9], "score": 0.5 + float(survey.data[0, 0]) / 1e4,
                             "apex_trace": mid, "apex_time_s": 1.2e-9, "kind": "target", "kind_score": None}]}


def test_detection_runs_on_every_window_once_as_it_fills(tmp_path):
    header = StreamHeader(n_samples=16, dt_s=1e-10, eps_r=4.0)
    det = _Spans()
    live = LiveReconstruction(header, LiveConfig(reconstruct=ReconstructConfig(aperture_deg=45.0), time_zero_traces=4,
                                                 background_window=4, detect_thread=False), tmp_path, detector=det)
    data = np.tile(np.arange(30, dtype=np.float32)[:, None], (1, 16))  # sample 0 of a trace: its index
    poses = np.c_[np.linspace(0, 0.6, 30), np.zeros((30, 2)), np.tile([1, 0, 0, 0], (30, 1))]
    for a, b in ((0, 5), (5, 13), (13, 14), (14, 27)):
        live.add(data[a:b], poses[a:b])
        live._detect(False, 0)
    # windows of 8 traces every 4, each on its own: [0, 8) and [4, 12) once 13 traces are there, then [8, 16),
    # [12, 20), [16, 24) once 27 are
    assert det.spans == [(0, 8), (4, 8), (8, 8), (12, 8), (16, 8)]
    live.add(data[27:], poses[27:])
    # the window [20, 28) is full, but a refresh is due for traces ready and not yet shown: the detector waits
    # (the targets first)
    assert live.last_refresh is None and live._detect(False, 1) == 0 and len(det.spans) == 5
    assert live._detect(False, 0) == 1 and det.spans[5:] == [(20, 8)]
    assert live._detect(True, 30) == 1  # the end: one window over the last traces, [22, 30)
    assert det.spans[5:] == [(20, 8), (22, 8)]
    assert live._detect(True, 30) == 0  # nothing left
    assert len(det.spans) == 7
    # boxes in the stream's traces
    assert sorted((t["box"][0], t["apex_trace"]) for t in live.detections) == [
        (3.0, 4), (7.0, 8), (11.0, 12), (15.0, 16), (19.0, 20), (23.0, 24), (25.0, 26)]
    # a box of the same hyperbola from an overlapping window: the better one kept, once
    live._add_detection({"box": [15.2, 1e-9, 17.2, 2e-9], "score": 0.9, "apex_trace": 16})
    live._add_detection({"box": [24.9, 1e-9, 26.9, 2e-9], "score": 0.1, "apex_trace": 26})
    live._add_detection({"box": [40.0, 1e-9, 42.0, 2e-9], "score": 0.2, "apex_trace": 41})
    assert sorted((t["box"][0], t["score"]) for t in live.detections) == [
        (3.0, 0.5), (7.0, 0.5004), (11.0, 0.5008), (15.2, 0.9), (19.0, 0.5016), (23.0, 0.502), (25.0, 0.5022),
        (40.0, 0.2)]


def test_a_detector_behind_thins_its_windows_then_skips_ahead_and_yields_to_waiting_traces(tmp_path):
    header = StreamHeader(n_samples=16, dt_s=1e-10, eps_r=4.0)

    def live_with(n, backlog):
        det = _Spans()
        live = LiveReconstruction(header, LiveConfig(reconstruct=ReconstructConfig(aperture_deg=45.0),
                                                     time_zero_traces=4, background_window=4, detect_backlog=backlog,
                                                     detect_thread=False),
                                  tmp_path, detector=det)
        data = np.tile(np.arange(n, dtype=np.float32)[:, None], (1, 16))
        live.add(data, np.c_[np.linspace(0, 0.6, n), np.zeros((n, 2)), np.tile([1, 0, 0, 0], (n, 1))])
        return live, det

    # 30 traces waiting, at most 16 behind (twice the 8-trace window): without overlap while over 16 behind
    # ([0, 8) and [8, 16)), then every 4 again ([16, 24), [20, 28)); nothing skipped
    live, det = live_with(30, 16)
    assert live._detect(False, 0) == 4 and det.spans == [(0, 8), (8, 8), (16, 8), (20, 8)]
    assert (live.detect_thinned, live.detect_skipped) == (2, 0)
    assert live.raw_tail.first == 24 - 8  # (the traces before the last window's reach are gone)
    # 60 waiting, over twice 16 behind: skip to the newest 16 ([44, 60), on the windows' steps); 44 traces unseen
    live, det = live_with(60, 16)
    assert live._detect(False, 0) == 3 and det.spans == [(44, 8), (48, 8), (52, 8)]
    assert (live.detect_thinned, live.detect_skipped) == (0, 44)
    assert live._detect(True, 60) == 0  # (the last window ended at the last trace: none more at the end)
    # a refresh is due and traces wait in the reader: the detector waits for the next step (the targets first)
    live, det = live_with(30, 4096)
    live.waiting = lambda: True
    assert live.last_refresh is None and live._detect(False, 0) == 0 and det.spans == []
    live.waiting = lambda: False
    assert live._detect(False, 0) == 6 and det.spans[-1] == (20, 8) and live.detect_thinned == 0


class _Gated(_Spans):
    """A :class:`_Spans` whose windows wait for ``go`` (60 s at most), noting the thread each ran in; with
    ``broken``, the window starting at that trace raises."""

    def __init__(self, broken=None, **kw):
        import threading

        super().__init__(**kw)
        self.go = threading.Event()
        self.threads = set()
        self.broken = broken

    def detect(self, survey, **kw):
        import threading

        self.go.wait(60.0)  # (set by the test long before: the cap only keeps a broken test from hanging)
        self.threads.add(threading.get_ident())
        if int(survey.data[0, 2]) == self.broken:
            raise ValueError(f"window {self.broken} broke")
        return super().detect(survey, **kw)


def _thinning_live(tmp_path, det, thread, n=30):
    header = StreamHeader(n_samples=16, dt_s=1e-10, eps_r=4.0)
    live = LiveReconstruction(header, LiveConfig(reconstruct=ReconstructConfig(aperture_deg=45.0), time_zero_traces=4,
                                                 background_window=4, detect_backlog=16, detect_thread=thread),
                              tmp_path, detector=det)
    data = np.tile(np.arange(n, dtype=np.float32)[:, None], (1, 16))
    live.add(data, np.c_[np.linspace(0, 0.6, n), np.zeros((n, 2)), np.tile([1, 0, 0, 0], (n, 1))])
    return live


def test_the_detector_s_thread_runs_the_windows_beside_the_loop_and_keeps_what_taking_turns_keeps(tmp_path):
    import threading

    det = _Gated()
    live = _thinning_live(tmp_path / "thread", det, True)
    # 30 traces waiting, 16 behind at most: the first two windows (without overlap) go to the thread, which waits;
    # the loop goes on without them (in turn, this call would wait for the windows)
    assert live._detect(False, 0) == 2 and det.spans == [] and live.detections == []
    assert live._worker.in_flight == 2 and live.next_window == 16
    assert live._detect(False, 0) == 0  # (no more while two wait)
    det.go.set()
    # the end: what is left goes to the thread, and the call returns once every window is back
    assert live._detect(True, 30) == 3 and live._worker.in_flight == 0
    assert det.threads and threading.get_ident() not in det.threads and len(det.threads) == 1
    # the windows, the thinning and the detections of the detector taking turns with the loop
    turns = _Spans()
    other = _thinning_live(tmp_path / "turns", turns, False)
    assert other._detect(False, 0) == 4 and other._detect(True, 30) == 1
    assert det.spans == turns.spans == [(0, 8), (8, 8), (16, 8), (20, 8), (22, 8)]
    assert (live.detect_thinned, live.detect_skipped) == (other.detect_thinned, other.detect_skipped) == (2, 0)
    assert live.detections == other.detections and len(live.detections) == 5
    assert live.detect_s > 0.0
    live.close()
    assert not live._worker._thread.is_alive()


def test_what_the_detector_s_thread_raises_the_loop_raises(tmp_path):
    det = _Gated(broken=8)
    det.go.set()
    live = _thinning_live(tmp_path, det, True)
    with pytest.raises(ValueError, match="^window 8 broke$"):
        live._detect(True, 30)
    live.close()


@pytest.mark.parametrize("thread", [True, False])
def test_live_mode_asks_its_detector_to_share_the_cores_and_detects_every_window(survey, tmp_path, thread):
    det = _Spans(traces=64)
    cfg = _cfg(until_idle_s=2.5, detect_thread=thread)
    cfg.detect = True
    data = survey.data.copy()
    data[:, 2] = np.arange(survey.n_traces)  # (what _Spans reads a window's first trace by)
    ticks = iter(range(1000))
    summary = run_live(_Scripted(survey.replace(data=data), 0, 3), tmp_path, cfg, detector=det, log=None,
                       poll_s=0.0, clock=lambda: float(next(ticks)), reader_thread=False)
    assert det.shared == 1  # before the first window (the warm-up's)
    n = survey.n_traces  # windows every 32 traces, and one over the last 64 at the end
    assert [a for a, _ in det.spans[1:]] == [*range(0, n - 64 + 1, 32), n - 64] and summary.detect_skipped == 0
    found = json.loads((tmp_path / "detections.json").read_text())
    assert found["detector"] == "stand-in (live)" and len(found["targets"]) == summary.n_detections > 0


def test_a_run_whose_detector_fails_raises_it_and_leaves_no_detector_thread(survey, tmp_path):
    import threading

    det = _Gated(broken=32, traces=64)  # (the warm-up's window starts at 0: the survey's second window breaks)
    det.go.set()
    cfg = _cfg(until_idle_s=2.5)
    cfg.detect = True
    data = survey.data.copy()
    data[:, 2] = np.arange(survey.n_traces)
    ticks = iter(range(1000))
    with pytest.raises(ValueError, match="^window 32 broke$"):
        run_live(_Scripted(survey.replace(data=data), 0, 3), tmp_path, cfg, detector=det, log=None, poll_s=0.0,
                 clock=lambda: float(next(ticks)), reader_thread=False)
    assert not [t for t in threading.enumerate() if t.name == "gpr3d-live-detector"]



class _SlowSpans(_Spans):
    """A detector that takes 20 ms a window (a sleep: at least that long on any host, however loaded)."""

    def detect(self, survey, **kw):
        time.sleep(0.02)
        return super().detect(survey, **kw)


@pytest.mark.parametrize("detect", [True, False])
def test_the_summary_says_how_long_each_kind_of_work_took(survey, tmp_path, detect):
    det = _SlowSpans(traces=64)
    cfg = _cfg(until_idle_s=2.5)
    cfg.detect = detect
    data = survey.data.copy()
    data[:, 2] = np.arange(survey.n_traces)
    ticks = iter(range(1000))
    t = time.perf_counter()
    summary = run_live(_Scripted(survey.replace(data=data), 0, 3), tmp_path, cfg, detector=det if detect else None,
                       log=None, poll_s=0.0, clock=lambda: float(next(ticks)), reader_thread=False)
    real = time.perf_counter() - t
    b = summary.busy_s
    assert set(b) == {"migrate", "detect", "refresh"}
    # the windows live mode ran (the first span is the warm-up's, before the survey) took their sleeps at least;
    # without a detector, no time is put down to it
    windows = len(det.spans) - 1
    assert (windows > 5 and b["detect"] >= 0.02 * windows) if detect else (det.spans == [] and b["detect"] == 0.0)
    assert b["migrate"] > 0.0 and b["refresh"] > 0.0
    # parts of the run, not more than it; the detector's thread runs beside the rest, so its time overlaps theirs
    assert max(b.values()) <= real and b["migrate"] + b["refresh"] <= real
    assert json.loads((tmp_path / "live.json").read_text())["summary"]["busy_s"] == b

def test_the_window_buffer_keeps_rows_by_their_numbers():
    from gpr3d.pipeline.live import _Window

    rng = np.random.default_rng(5)
    buf, ref, first, peak = _Window(3), [], 0, 0
    for _ in range(400):  # appends of up to 700 rows (the buffer grows and compacts), drops from the front
        k = int(rng.integers(0, 700))
        rows = rng.normal(size=(k, 3)).astype(np.float32)
        buf.append(rows)
        ref.extend(rows)
        peak = max(peak, len(ref) - first)
        drop = first + int(rng.integers(0, len(ref) - first + 1))
        buf.drop_before(drop)
        first = max(first, drop)
        assert (buf.first, buf.end, len(buf)) == (first, len(ref), len(ref) - first)
        a = first + int(rng.integers(0, len(ref) - first + 1))
        np.testing.assert_array_equal(buf.rows(a, len(ref)), np.array(ref[a:], np.float32).reshape(-1, 3))
    # compacted: its size follows the most rows kept at once, not all rows ever appended
    assert len(buf._a) <= 2 * peak < len(ref) / 20
    buf.drop_before(0)  # (before the first kept: nothing)
    assert buf.first == first
    with pytest.raises(IndexError, match=f"rows {first - 1}\\.\\.{len(ref)} asked of rows {first}"):
        buf.rows(first - 1, len(ref))
    with pytest.raises(IndexError):
        buf.rows(first, len(ref) + 1)


class _Scripted:
    """A source that gives nothing for ``wait`` polls, then the survey in ``batches`` polls, then nothing (ended
    at poll ``end_at``); with ``came`` (a function of nothing), each batch says its traces came at ``came()`` (as a
    source that held them back for their poses does)."""

    def __init__(self, survey, wait, batches, *, end_at=None, came=None):
        self.header = None
        self.s, self.wait, self.batches, self.polls, self.ended = survey, wait, batches, 0, False
        self.cuts = np.linspace(0, survey.n_traces, batches + 1).astype(int)
        self.end_at, self.came = end_at, came

    def poll(self):
        k, self.polls = self.polls - self.wait, self.polls + 1
        self.ended = self.end_at is not None and self.polls >= self.end_at
        if k < 0:
            return None  # (not connected yet: no header)
        self.header = StreamHeader(n_samples=self.s.n_samples, dt_s=DT, frequency_hz=800e6, offset_m=0.05,
                                   eps_r=EPS)
        a, b = (self.cuts[k], self.cuts[k + 1]) if k < self.batches else (0, 0)
        poses = np.c_[self.s.positions_xyz[a:b], self.s.orientations_quat_wxyz[a:b]]
        if self.came is not None:
            return self.s.data[a:b], poses, np.zeros(b - a), np.full(b - a, self.came())
        return self.s.data[a:b], poses, np.zeros(b - a)

    def close(self):
        pass


def test_the_idle_clock_and_the_rate_start_at_the_first_trace(survey, tmp_path, monkeypatch):
    """A clock that ticks one second a call (each poll reads it, and each step that did some work once more):
    five polls find nothing, traces come at 6, 8 and 10 s, the step after the last ends at 11 s; with 2.5 s of
    idleness allowed the run ends at 13 s, and its final step reads 14 and 15 s. The lag: the work on the
    newest trace ended 1 s after it came, and the final step took 1 s (2 s); the rate counts from the first trace
    to the newest plus the lag (10 - 6 + 2 = 6 s): the idle wait is neither lag nor work."""
    ticks = iter(range(1000))
    summary = run_live(_Scripted(survey, 5, 3), tmp_path, _cfg(until_idle_s=2.5, start_timeout_s=5.5),
                       log=None, poll_s=0.0, clock=lambda: float(next(ticks)), reader_thread=False)
    assert summary.n_traces == survey.n_traces
    assert summary.lag_s == 2.0
    assert summary.wall_s == 6.0 and summary.traces_per_s == survey.n_traces / 6.0
    # work that goes on into the idle wait (a detector's backlog, say) is lag: two more steps work after the last
    # trace, ending at 13 and 15 s; the idle clock (from the newest trace) ends the run after the second, and the
    # final step reads 16 and 17 s: lag 15 - 10 + 1 s
    step, calls = LiveReconstruction.step, []

    def busy_step(self, *, ended=False):
        done = step(self, ended=ended)
        calls.append(self.n_in)
        return done or int(not ended and calls.count(survey.n_traces) in (2, 3))

    monkeypatch.setattr(LiveReconstruction, "step", busy_step)
    ticks = iter(range(1000))
    summary = run_live(_Scripted(survey, 5, 3), tmp_path / "w", _cfg(until_idle_s=2.5, start_timeout_s=5.5),
                       log=None, poll_s=0.0, clock=lambda: float(next(ticks)), reader_thread=False)
    assert summary.lag_s == 15.0 - 10.0 + 1.0 and summary.wall_s == 10.0 - 6.0 + 6.0
    monkeypatch.undo()
    # a stream that ends long after its last trace (sensor messages only, or nothing, came since): the wait for
    # its end is neither lag nor work either (the run ends at its end mark, at poll 12: 19 s)
    ticks = iter(range(1000))
    summary = run_live(_Scripted(survey, 5, 3, end_at=12), tmp_path / "e", _cfg(until_idle_s=None), log=None,
                       poll_s=0.0, clock=lambda: float(next(ticks)), reader_thread=False)
    assert summary.lag_s == 2.0 and summary.wall_s == 6.0
    # traces a source held back (for their poses) came before it gave them: the lag and the rate (and the latency,
    # on the real clock) count from when they came
    now = [0.0]

    def clock():
        now[0] = float(next(ticks))
        return now[0]

    ticks = iter(range(1000))
    summary = run_live(_Scripted(survey, 5, 3, came=lambda: now[0] + 0.5), tmp_path / "c",
                       _cfg(until_idle_s=2.5, start_timeout_s=5.5), log=None, poll_s=0.0, clock=clock,
                       reader_thread=False)
    # (the source is polled before the clock is read: the poll at 6 s sees now = 5, so its traces came at 5.5 s)
    assert summary.lag_s == (11.0 - 9.5) + 1.0 and summary.wall_s == 9.5 - 5.5 + 2.5
    # nothing at all within start_timeout_s: one line naming it
    ticks = iter(range(1000))
    with pytest.raises(GPR3DError, match="no traces arrived in 4.5 s"):
        run_live(_Scripted(survey, 5, 3), tmp_path / "b", _cfg(until_idle_s=2.5, start_timeout_s=4.5), log=None,
                 poll_s=0.0, clock=lambda: float(next(ticks)), reader_thread=False)


def test_a_dzt_whose_poses_never_come_is_named(survey, tmp_path):
    src = _dzt_of(survey, tmp_path / "rec.dzt")
    source = open_source(src, poses=tmp_path / "missing.tum")
    with pytest.raises(GPR3DError, match=f"{survey.n_traces} traces came, but no poses for them in .*missing.tum"):
        run_live(source, tmp_path / "out", _cfg(start_timeout_s=0.3), log=None)


@pytest.mark.parametrize("bad, message", [(np.nan, "trace 3: its pose is not finite"),
                                          (0.0, "trace 3: its pose is not finite or its quaternion zero")])
def test_a_pose_live_mode_cannot_use_is_named(tmp_path, bad, message):
    live = LiveReconstruction(StreamHeader(n_samples=16, dt_s=1e-10, eps_r=4.0),
                              LiveConfig(reconstruct=ReconstructConfig(aperture_deg=45.0)), tmp_path)
    poses = np.tile([0.0, 0, 0, 1, 0, 0, 0], (5, 1))
    poses[3, 3:] = bad
    with pytest.raises(InvalidDataError, match=message):
        live.add(np.zeros((5, 16), np.float32), poses)


class _Interrupted:
    """A source that gives the survey in batches of 50, then the user presses Ctrl-C."""

    def __init__(self, survey, stop_after):
        self.header = StreamHeader(n_samples=survey.n_samples, dt_s=DT, frequency_hz=800e6, offset_m=0.05,
                                   eps_r=EPS)
        self.s, self.stop_after, self.at, self.ended, self.closed = survey, stop_after, 0, False, False

    def poll(self):
        if self.at >= self.stop_after:
            raise KeyboardInterrupt
        a, self.at = self.at, self.at + 50
        poses = np.c_[self.s.positions_xyz[a:self.at], self.s.orientations_quat_wxyz[a:self.at]]
        return self.s.data[a:self.at], poses, np.zeros(len(poses))

    def close(self):
        self.closed = True


def test_ctrl_c_ends_the_survey_and_writes_what_came(survey, tmp_path):
    source = _Interrupted(survey, 300)
    lines = []
    summary = run_live(source, tmp_path, _cfg(), log=lines.append)
    assert source.closed and summary.n_traces == 300
    assert "interrupted: finishing with the 300 traces received" in lines
    _batch_equals_live(survey[:300], tmp_path)


def test_a_replay_that_cannot_listen_says_where(survey):
    import socket

    taken = socket.create_server(("127.0.0.1", 0))
    port = taken.getsockname()[1]
    try:
        with pytest.raises(GPR3DError, match=f"tcp://127.0.0.1:{port}: cannot listen there"):
            replay_to_tcp(survey, port, rate=100.0)
    finally:
        taken.close()


class _Timed:
    """Batches of 3 traces at 0, 0.15 and 0.3 s after the first poll, then the end (or a broken stream)."""

    def __init__(self, fail=False):
        self.header, self.ended, self.fail, self.t0, self.given, self.closed = None, False, fail, None, 0, False

    def poll(self):
        import time

        now = time.monotonic()
        self.t0 = self.t0 or now
        if self.given < 3 and now - self.t0 >= 0.15 * self.given:
            self.given += 1
            if self.fail and self.given == 3:
                raise GPR3DError("tcp://x:1: the stream broke")
            return np.full((3, 4), float(self.given), np.float32), np.zeros((3, 7)), np.zeros(3)
        self.ended = self.given == 3
        return None

    def close(self):
        self.closed = True


def test_the_reader_stamps_traces_when_they_come_not_when_they_are_taken():
    import time

    src = _Timed()
    reader = SourceReader(src, poll_s=0.002)
    # the main loop busy migrating for 0.6 s at least, and until the source has given everything: the batches wait
    assert reader._finished.wait(30)
    while time.monotonic() - src.t0 < 0.6:
        time.sleep(0.01)
    got = reader.take()
    assert [float(g[0][0][0, 0]) for g in got] == [1.0, 2.0, 3.0]
    at = np.array([a for _, a in got]) - src.t0
    # when each came (0, 0.15, 0.3 s), not when taken (0.6 s or later): the 0.1 s allowed is what a thread polling
    # every 2 ms may be late by on a busy machine, and still tells the two apart
    np.testing.assert_allclose(at, [0.0, 0.15, 0.3], atol=0.1)
    assert reader.ended and reader.take() == []
    reader.close()
    assert src.closed


def test_the_reader_hands_over_what_came_before_the_source_broke_then_its_error():
    import time

    reader = SourceReader(_Timed(fail=True), poll_s=0.002)
    assert reader._finished.wait(30)
    assert [float(g[0][0][0, 0]) for g in reader.take()] == [1.0, 2.0]
    assert not reader.ended
    with pytest.raises(GPR3DError, match="the stream broke"):
        reader.take()
    reader.close()


def test_a_refresh_is_due_a_period_after_the_last_one_started_longer_when_refreshes_cost_more(tmp_path):
    """The period: ``refresh_s`` from the start of the last refresh, or three times the median cost of the last
    five refreshes where that is longer (one slow refresh does not hold the next one back). (Periods of seconds,
    each check half a second or more from its edge: a test paused by a busy machine reads the same.)"""
    live = LiveReconstruction(StreamHeader(n_samples=16, dt_s=1e-10, eps_r=4.0), _cfg(refresh_s=2.0), tmp_path)
    assert live._refresh_due()  # none yet
    live.last_refresh = time.monotonic() - 2.5
    assert live._refresh_due()
    live.refresh_costs = [1.0, 1.0, 50.0, 1.0, 1.0]  # median 1: a period of 3 s
    assert not live._refresh_due()
    live.last_refresh -= 1.0  # 3.5 s ago
    assert live._refresh_due()
    live.refresh_costs = [2.0, 2.0, 0.01]  # median 2: 6 s
    assert not live._refresh_due()
    # refresh() records its cost (the last five) and its start
    live.refresh_costs = [90.0] * 5
    t = time.monotonic()
    live.refresh()
    assert len(live.refresh_costs) == 5 and live.refresh_costs[:4] == [90.0] * 4 and live.refresh_costs[4] < 90.0
    assert t <= live.last_refresh <= t + live.refresh_costs[4]


def test_live_mode_asks_glibc_to_keep_the_memory_it_frees(monkeypatch):
    import ctypes

    from gpr3d.pipeline import live as live_mod

    calls = []

    class _Libc:
        def mallopt(self, param, value):
            calls.append((param, value))
            return 1

    monkeypatch.setattr(ctypes, "CDLL", lambda name: _Libc())
    assert live_mod._keep_freed_memory()
    assert calls == [(-3, 32 << 20), (-1, (1 << 31) - 1)]  # M_MMAP_THRESHOLD 32 MB, M_TRIM_THRESHOLD: never

    def missing(name):
        raise OSError("no libc")

    monkeypatch.setattr(ctypes, "CDLL", missing)
    assert not live_mod._keep_freed_memory()


def test_a_refresh_looks_where_traces_came_and_keeps_the_targets_elsewhere(survey, tmp_path):
    """The regions: the tiles traces reached since the last refresh and their neighbours in memory, in groups
    that touch (corners too); a target found before outside them stays, one reaching into them (a line, also
    between its ends) is replaced by what the region shows now."""
    from gpr3d.migration.targets import Target3D

    header = StreamHeader(n_samples=survey.n_samples, dt_s=DT, frequency_hz=800e6, offset_m=0.05, eps_r=EPS)
    live = LiveReconstruction(header, _cfg(min_batch=1, refresh_s=3600.0), tmp_path)
    blank = [np.zeros(1), np.zeros(1)]
    live.tiles = {k: blank for k in [(0, 0), (1, 1), (3, 0), (5, 5), (5, 6), (9, 9)]}
    live.dirty = {(0, 0), (4, 0), (5, 5)}
    got = sorted((tuple(a), tuple(b)) for a, b in live._refresh_regions())
    # (0, 0) with (1, 1) at its corner; (3, 0) beside (4, 0), which is not in memory; (5, 5) with (5, 6); not (9, 9)
    assert got == [((0, 0), (1, 1)), ((3, 0), (3, 0)), ((5, 5), (5, 6))]
    live.dirty = set()
    assert live._refresh_regions() == []
    # the survey: a pipe along y at x = 0.6, 0.22 m deep
    live.tiles = {}
    poses = np.c_[survey.positions_xyz, survey.orientations_quat_wxyz]
    live.add(survey.data, poses)
    live.step(ended=True)
    assert live.dirty == set() and live.n_refreshed == survey.n_traces
    pipe = [t for t in live.targets if t.kind == "line" and abs(t.points_xyz[0][0] - 0.6) < 0.05]
    assert len(pipe) == 1
    far = Target3D("point", [[40.0, 40.0, 0.3]], 0.3, 1.0)  # in no region
    across = Target3D("line", [[-5.0, 0.5, 0.5], [5.0, 0.5, 0.5]], 0.5, 1.0)  # its ends outside, its middle in
    live.targets = [far, across]
    live.dirty = set(live.tiles)
    live.refresh()
    assert far in live.targets and across not in live.targets
    assert [t for t in live.targets if t.kind == "line" and abs(t.points_xyz[0][0] - 0.6) < 0.05]


def test_a_refresh_takes_the_preview_s_hough_settings_and_the_end_the_batch_s(survey, tmp_path, monkeypatch):
    import gpr3d.migration.reconstruct as rec

    calls = []
    real = rec.volume_targets

    def spy(*a, **kw):
        calls.append(kw)
        return real(*a, **kw)

    monkeypatch.setattr(rec, "volume_targets", spy)
    header = StreamHeader(n_samples=survey.n_samples, dt_s=DT, frequency_hz=800e6, offset_m=0.05, eps_r=EPS)
    live = LiveReconstruction(header, _cfg(min_batch=1, refresh_s=3600.0, preview_max_peaks=37,
                                           preview_angle_step_deg=1.5), tmp_path)
    live.add(survey.data, np.c_[survey.positions_xyz, survey.orientations_quat_wxyz])
    live.step(ended=True)
    assert calls and all(kw == {"angle_step_deg": 1.5, "max_peaks": 37} for kw in calls)
    calls.clear()
    live.finish()
    assert calls and all("max_peaks" not in kw and "angle_step_deg" not in kw for kw in calls)


def _bag_of(survey, path, *, ros1=False, pose_span=None):
    """``survey`` as a bag: ``/gpr/traces`` one trace a message, 10 ms apart from t = 50 s, and ``/odometry``
    the poses at the same stamps (``pose_span``: only those of these traces)."""
    pytest.importorskip("rosbags")
    from gpr3d.core.trajectory import Trajectory
    from gpr3d.io.rosbag import write_bag

    t = 50.0 + 0.01 * np.arange(survey.n_traces)
    keep = slice(None) if pose_span is None else slice(*pose_span)
    traj = Trajectory(t[keep], survey.positions_xyz[keep], survey.orientations_quat_wxyz[keep])
    write_bag(path, traces=(t, survey.data), trajectory=traj, ros1=ros1)
    return path


@pytest.mark.parametrize("ros1", [False, True])
def test_a_ros_bag_replayed_equals_the_batch_volume(survey, tmp_path, ros1):
    bag = _bag_of(survey, tmp_path / ("s.bag" if ros1 else "s2"), ros1=ros1)
    source = open_source(bag, offset_m=0.05, frequency_hz=800e6, bag={"dt_s": DT, "speed": None, "eps_r": EPS})
    assert isinstance(source, BagSource)
    summary = run_live(source, tmp_path / "out", _cfg(), log=None)
    assert summary.n_traces == survey.n_traces
    _batch_equals_live(survey, tmp_path / "out")


def test_a_bag_is_given_at_its_own_pace_and_traces_outside_the_poses_are_left_out(survey, tmp_path):
    bag = _bag_of(survey, tmp_path / "p", pose_span=(10, 60))  # poses from trace 10's stamp to trace 59's
    now = [0.0]
    src = BagSource(bag, dt_s=DT, speed=2.0, clock=lambda: now[0])
    got = []
    for step in range(40):  # 0.0051 s of clock a poll: 0.0102 s of bag at twice its pace, one trace a poll
        out = src.poll()
        got.append(len(out[0]))
        if len(out[0]):
            assert out[2][0] >= 50.0 + 0.01 * 10
        now[0] += 0.0051
    # the replay starts at the first trace's pose (trace 10's, the first pose after traces 0-9: those are left
    # out), then one trace a poll
    assert got[0] == 1 and src.skipped == 10 and all(g == 1 for g in got[1:])
    now[0] += 100.0
    rest = src.poll()
    assert len(rest[0]) == 50 - 40 and src.skipped == 10 + survey.n_traces - 60 and src.ended
    np.testing.assert_array_equal(rest[0], survey.data[50:60])
    np.testing.assert_allclose(rest[1][:, :3], survey.positions_xyz[50:60], atol=1e-9)
    src.close()


@pytest.mark.parametrize("kw, message", [
    (dict(dt_s=0.0), "a bag's traces carry no sample interval: give it"),
    (dict(dt_s=DT, speed=-1.0), "the replay speed must be a positive number, got -1.0"),
    (dict(dt_s=DT, samples_per_trace=1), "samples per trace must be a whole number of at least 2, got 1"),
    (dict(dt_s=DT, trace_topic="/radar"), "no topic '/radar'"),
    (dict(dt_s=DT, poses="p.tum", pose_topic="/odometry"), r"poses from a TUM file \(--poses\) or from the bag's "
                                                             "/odometry: give one"),
])
def test_bag_settings_that_cannot_run_are_named(survey, tmp_path, kw, message):
    bag = _bag_of(survey, tmp_path / "k")
    with pytest.raises(GPR3DError, match=message):
        BagSource(bag, **kw)
    with pytest.raises(GPR3DError, match="a bag's traces carry no sample interval"):
        open_source(bag)
    with pytest.raises(GPR3DError, match="--dt, --trace-topic are for a ROS bag"):
        open_source("tcp://127.0.0.1:5000", bag={"dt_s": DT, "trace_topic": "/g"})
    with pytest.raises(GPR3DError, match="--speed are for a ROS bag"):
        open_source(tmp_path / "rec.dzt", bag={"speed": 2.0})


class _Paced:
    """The survey in 10 batches, one every 0.05 s from the first poll, then the end of nothing more (idle)."""

    def __init__(self, survey):
        self.header = StreamHeader(n_samples=survey.n_samples, dt_s=DT, frequency_hz=800e6, offset_m=0.05,
                                   eps_r=EPS)
        self.s, self.t0, self.given, self.ended = survey, None, 0, False
        self.cuts = np.linspace(0, survey.n_traces, 11).astype(int)

    def poll(self):
        now = time.monotonic()
        self.t0 = self.t0 or now
        if self.given < 10 and now - self.t0 >= 0.05 * self.given:
            a, b = self.cuts[self.given], self.cuts[self.given + 1]
            self.given += 1
            return self.s.data[a:b], np.c_[self.s.positions_xyz[a:b], self.s.orientations_quat_wxyz[a:b]], np.zeros(b - a)
        return None

    def close(self):
        pass


def test_a_long_step_is_not_idleness_while_traces_wait_in_the_reader(survey, tmp_path, monkeypatch):
    """The first step takes 2 s while the other nine batches come (the last at 0.45 s): with 1 s of idleness
    allowed the run must not end after that step (the clock since the last batch *taken* says 2 s, but nine
    batches wait), and every trace is migrated. (A busy machine may delay a batch; 1 s of idleness leaves room.)"""
    slow = {"first": True}
    step = LiveReconstruction.step

    def slow_step(self, **kw):
        done = step(self, **kw)
        if slow.pop("first", False):
            time.sleep(2.0)  # (after the step's own refresh, which takes in what waits)
        return done

    monkeypatch.setattr(LiveReconstruction, "step", slow_step)
    summary = run_live(_Paced(survey), tmp_path, _cfg(until_idle_s=1.0), log=None)
    assert summary.n_traces == survey.n_traces


@pytest.fixture(scope="module")
def rig_run(tmp_path_factory):
    """A synthetic cart's run: its sensors' files (``imu.csv``, ``odometry.tum``: the camera's poses, lost frames
    left out, ``wheel.csv``, ``rig.json``, ``truth.tum``) and a Survey of traces every 0.04 s from 1.5 s (the pipe
    scene recorded along the antenna's true path; trace times on the IMU clock, no poses)."""
    from gpr3d.pipeline.poses import write_rig_recordings
    from gpr3d.pose.rig import RigConfig, simulate_rig

    run = simulate_rig(RigConfig(duration_s=16.0, vo_gap=(9.0, 0.5)), seed=4)
    folder = tmp_path_factory.mktemp("rigrun")
    write_rig_recordings(run, folder)
    from gpr3d.io.trajectory import read_tum

    truth = read_tum(folder / "truth.tum")
    t = np.arange(1.5, 15.5, 0.04)
    at = truth.at(t)
    p0 = at.positions_xyz.mean(axis=0)
    scene = ForwardScene(eps_r=EPS, pipes=[Pipe((p0[0] - 3, p0[1], -0.22), (p0[0] + 3, p0[1], -0.22), 0.02)])
    data = forward_model(scene, at.positions_xyz, at.orientations_quat_wxyz, offset_m=0.05, frequency_hz=800e6,
                         n_samples=128, time_window_s=12e-9, air_wave=1.0, ground_wave=0.5, noise=0.01)
    return folder, run, Survey(data=data, dt_s=DT, offset_m=0.05, frequency_hz=800e6, eps_r=EPS, timestamps_s=t)


@pytest.fixture(scope="module")
def fused_bag(rig_run):
    """The cart's run as a ROS 2 bag: ``/imu``, ``/odometry`` (the camera's poses) and ``/gpr/traces``, with its
    rig file beside it."""
    pytest.importorskip("rosbags")
    from gpr3d.io.rosbag import write_bag
    from gpr3d.io.trajectory import read_tum

    folder, run, survey = rig_run
    if not (folder / "run").exists():
        write_bag(folder / "run", imu=run.imu, trajectory=read_tum(folder / "odometry.tum"),
                  traces=(survey.timestamps_s, survey.data))
    return folder


def test_a_bag_s_poses_fused_as_the_replay_comes_are_the_batch_fusion_s(fused_bag, tmp_path):
    from gpr3d.pipeline.poses import fuse_recordings

    bag, rig = fused_bag / "run", fused_bag / "rig.json"
    ref = fuse_recordings(bag=bag, rig=rig, log=None).trajectory  # (the filter alone: no smoothing)
    # as fast as it reads: every trace, each with the batch fusion's pose at its stamp
    src = BagSource(bag, dt_s=DT, speed=None, fuse={"rig": rig})
    data, poses, times, _ = src.poll()
    assert src.ended and len(times) == 350 and src.skipped == 0
    want = ref.at(times)
    np.testing.assert_allclose(poses[:, :3], want.positions_xyz, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(poses[:, 3:] * want.orientations_quat_wxyz, axis=1)), 1.0, atol=1e-12)
    # at its own pace: a trace is given once the replay clock and the filter have both passed its stamp, and the
    # filter keeps up within the odometry's frame interval (15 Hz) and a poll
    now = [0.0]
    src = BagSource(bag, dt_s=DT, speed=1.0, fuse={"rig": rig, "still_s": 1.0}, clock=lambda: now[0])
    got, late = [], []
    while not src.ended:
        out = src.poll()  # (None until the first trace is given: no header yet)
        t = out[2] if out is not None else np.zeros(0)
        p = out[1] if out is not None else None
        bag_now = 1.5 + now[0]
        if len(t):  # (each trace came when the replay clock passed its stamp, before the filter let it go)
            np.testing.assert_allclose(out[3], t - 1.5, rtol=0, atol=1e-9)
        f = src.fused  # (fed nothing stamped after the replay's clock)
        assert (f.ni == 0 or f.imu.t_s[f.ni - 1] <= bag_now) and (f.nv == 0 or f.vo.t_s[f.nv - 1] <= bag_now)
        if len(t):
            assert t.max() <= min(bag_now, src.fused.until)
            np.testing.assert_allclose(p[:, :3], ref.at(t).positions_xyz, rtol=0, atol=1e-9)
            got.extend(t)
        nxt = src._next[0] if src._next is not None else None
        if nxt is not None and nxt <= bag_now:
            late.append((nxt, bag_now - nxt))  # a trace the clock has passed, waiting for the filter
        now[0] += 0.05
    assert len(got) == 350
    # (where odometry lost track, 9.0-9.5 s, the filter waits for the next frame: it cannot know none is coming)
    gap = np.array([w for t, w in late if 9.0 - 0.1 <= t <= 9.5 + 1 / 15])
    rest = np.array([w for t, w in late if not 9.0 - 0.1 <= t <= 9.5 + 1 / 15])
    assert rest.max() < 1 / 15 + 0.05 + 1e-9 and 0.3 < gap.max() < 0.5 + 1 / 15 + 0.1
    src.close()
    # fused poses with given ones: one line
    with pytest.raises(GPR3DError, match=r"poses fused from the IMU and odometry \(--fuse\) or given \(--pose-topic\)"):
        BagSource(bag, dt_s=DT, fuse={}, pose_topic="/odometry")


def test_live_on_a_fused_bag_equals_the_batch_volume_with_those_poses(fused_bag, tmp_path):
    from gpr3d.io.rosbag import iter_bag_traces

    bag = fused_bag / "run"
    source = open_source(bag, offset_m=0.05, frequency_hz=800e6,
                         bag={"dt_s": DT, "speed": None, "eps_r": EPS, "fuse": {"rig": fused_bag / "rig.json"}})
    summary = run_live(source, tmp_path / "out", _cfg(), log=None)
    assert summary.n_traces == 350
    from gpr3d.pipeline.poses import fuse_recordings

    stamps = np.array([t for t, _ in iter_bag_traces(bag)])
    traces = np.concatenate([tr for _, tr in iter_bag_traces(bag)])
    at = fuse_recordings(bag=bag, rig=fused_bag / "rig.json", log=None).trajectory.at(stamps)
    survey = Survey(data=traces, dt_s=DT, offset_m=0.05, frequency_hz=800e6, eps_r=EPS,
                    positions_xyz=at.positions_xyz, orientations_quat_wxyz=at.orientations_quat_wxyz)
    _batch_equals_live(survey, tmp_path / "out")


# -- poses fused from a TCP stream's sensor messages -----------------------------------------------------------------

class _FakeSocket:
    """Bytes a TCP source reads: what was put in since the last read, then 'nothing now'."""

    def __init__(self):
        self.pending = bytearray()
        self.closed = False

    def recv(self, n):
        if not self.pending:
            if self.closed:
                return b""
            raise BlockingIOError
        out = bytes(self.pending[:n])
        del self.pending[:n]
        return out

    def close(self):
        pass


def _messages(survey, sensors):
    """The stream's messages after its header, in time order: ``[(time, bytes), ...]`` (traces without poses)."""
    from gpr3d.io.stream import encode_camera_pose, encode_imu, encode_trace, encode_wheel

    out = [(t, encode_trace(i, t, np.full(7, np.nan), survey.data[i])) for i, t in enumerate(survey.timestamps_s)]
    out += [(r[0], encode_imu(r[0], r[1:4], r[4:7])) for r in sensors["imu"]]
    out += [(r[0], encode_camera_pose(r[0], r[1:8])) for r in sensors.get("odometry", ())]
    out += [(r[0], encode_wheel(r[0], r[1])) for r in sensors.get("wheel", ())]
    return sorted(out, key=lambda m: m[0])


def test_a_stream_s_poses_fused_as_its_sensor_messages_come_are_the_batch_fusion_s(rig_run):
    from gpr3d.io.stream import encode_header
    from gpr3d.pipeline.live import TCPSource
    from gpr3d.pipeline.poses import fuse_recordings
    from gpr3d.pipeline.replay import read_sensors

    folder, _, survey = rig_run
    files = {"imu": folder / "imu.csv", "odometry": folder / "odometry.tum", "wheel": folder / "wheel.csv"}
    sensors = read_sensors(**files)
    ref = fuse_recordings(**files, rig=folder / "rig.json", log=None).trajectory  # (no smoothing)
    header = StreamHeader(n_samples=128, dt_s=DT, sensors=("imu", "odometry", "wheel"))
    src = TCPSource("127.0.0.1", 1, fuse={"rig": folder / "rig.json"})
    src.sock = sock = _FakeSocket()
    sock.pending += encode_header(header)
    msgs = _messages(survey, sensors)
    got, waits, k = [], [], 0
    for now in np.arange(0.0, 16.2, 0.1):  # the messages stamped up to `now`, then a poll
        while k < len(msgs) and msgs[k][0] <= now:
            sock.pending += msgs[k][1]
            k += 1
        out = src.poll()
        if out is not None and len(out[2]):
            data, poses, times, came = out
            assert times.max() <= now and np.all(came <= time.monotonic())  # (nothing given before it happened)
            want = ref.at(times)
            np.testing.assert_allclose(poses[:, :3], want.positions_xyz, rtol=0, atol=1e-9)
            np.testing.assert_allclose(np.abs(np.sum(poses[:, 3:] * want.orientations_quat_wxyz, axis=1)), 1.0,
                                       atol=1e-12)
            np.testing.assert_array_equal(data, survey.data[len(got):len(got) + len(times)])
            got.extend(times)
        waits += [(t, now - t) for t in survey.timestamps_s[len(got):] if t <= now]  # (come, not yet given)
    sock.pending += b"END!"
    out = src.poll()
    got.extend(out[2])
    assert src.ended and src.skipped == 0
    np.testing.assert_array_equal(got, survey.timestamps_s)
    # a trace waits for the next camera frame (15 Hz) and the poll (0.1 s); where odometry lost track (9.0-9.5 s)
    # until the next frame after the gap
    gap = np.array([w for t, w in waits if 9.0 - 0.1 <= t <= 9.5 + 1 / 15])
    rest = np.array([w for t, w in waits if not 9.0 - 0.1 <= t <= 9.5 + 1 / 15])
    assert rest.max() < 1 / 15 + 0.1 + 1e-9 and 0.3 < gap.max() < 0.5 + 1 / 15 + 0.1


def test_live_over_tcp_with_poses_fused_from_the_stream_equals_the_batch_volume(rig_run, tmp_path):
    from gpr3d.pipeline.poses import fuse_recordings
    from gpr3d.pipeline.replay import read_sensors

    folder, _, survey = rig_run
    files = {"imu": folder / "imu.csv", "odometry": folder / "odometry.tum"}
    th, port = _serve(survey, 2500.0, sensors=read_sensors(**files))
    source = open_source(f"tcp://127.0.0.1:{port}", fuse={"rig": folder / "rig.json", "still_s": 1.0})
    summary = run_live(source, tmp_path / "out", _cfg(), log=None)
    th.join(10)
    assert summary.n_traces == survey.n_traces and source.skipped == 0
    at = fuse_recordings(**files, rig=folder / "rig.json", log=None).trajectory.at(survey.timestamps_s)
    posed = Survey(data=survey.data, dt_s=DT, offset_m=0.05, frequency_hz=800e6, eps_r=EPS,
                   positions_xyz=at.positions_xyz, orientations_quat_wxyz=at.orientations_quat_wxyz)
    _batch_equals_live(posed, tmp_path / "out")


def test_traces_outside_the_imu_s_span_are_left_out_and_counted(rig_run):
    from gpr3d.io.stream import encode_header
    from gpr3d.pipeline.live import TCPSource
    from gpr3d.pipeline.replay import read_sensors

    folder, _, survey = rig_run
    sensors = read_sensors(folder / "imu.csv")
    imu = sensors["imu"]
    sensors["imu"] = imu[(imu[:, 0] >= 0.0) & (imu[:, 0] <= 10.0)]  # (traces run 1.5 to 15.46 s)
    src = TCPSource("127.0.0.1", 1, fuse={})
    src.sock = sock = _FakeSocket()
    sock.pending += encode_header(StreamHeader(n_samples=128, dt_s=DT, sensors=("imu",)))
    sock.pending += b"".join(m for _, m in _messages(survey, sensors)) + b"END!"
    _, _, times, _ = src.poll()
    assert src.ended and times.max() <= 10.0 and len(times) + src.skipped == survey.n_traces
    assert len(times) == np.count_nonzero(survey.timestamps_s <= 10.0)


def _one_poll(header, *messages, fuse=None):
    from gpr3d.io.stream import encode_header
    from gpr3d.pipeline.live import TCPSource

    src = TCPSource("127.0.0.1", 1, fuse=fuse)
    src.sock = sock = _FakeSocket()
    sock.pending += encode_header(header) + b"".join(messages)
    return src.poll()


def test_fusion_a_stream_cannot_give_is_named_in_one_line(tmp_path):
    from gpr3d.io.stream import encode_imu, encode_trace

    plain = StreamHeader(n_samples=4, dt_s=DT)
    sensed = StreamHeader(n_samples=4, dt_s=DT, sensors=("imu",))
    unposed = encode_trace(0, 1.0, np.full(7, np.nan), np.zeros(4))
    with pytest.raises(GPR3DError, match=r"^tcp://127.0.0.1:1: --fuse needs IMU samples in the stream; its header "
                                         r"declares none \(sensors\)$"):
        _one_poll(plain, fuse={})
    with pytest.raises(GPR3DError, match=r"^tcp://127.0.0.1:1: trace 0 carries no pose .*: give --fuse"):
        _one_poll(sensed, unposed)
    with pytest.raises(GPR3DError, match=r"^tcp://127.0.0.1:1: the stream ended after 1 IMU sample\(s\): too few"):
        _one_poll(sensed, encode_imu(0.0, [0, 0, 9.8], [0, 0, 0]), unposed, b"END!", fuse={})
    with pytest.raises(GPR3DError, match=r"^tcp://127.0.0.1:1: trace 1: its time runs backwards"):
        _one_poll(sensed, unposed, encode_trace(1, 0.5, np.full(7, np.nan), np.zeros(4)), fuse={})
    imu_g = [encode_imu(0.01 * i, [0, 0, 1.0], [0, 0, 0]) for i in range(300)]  # (forces in g)
    with pytest.raises(GPR3DError, match=r"^tcp://127.0.0.1:1: IMU forces: median magnitude 1 is not in m/s\^2 "
                                         r"\(in g\? multiply by 9.80665\)$"):
        _one_poll(sensed, *imu_g, fuse={})
    with pytest.raises(GPR3DError, match=r"missing.json"):  # (the rig read before connecting)
        open_source("tcp://127.0.0.1:5600", fuse={"rig": tmp_path / "missing.json"})
    with pytest.raises(GPR3DError, match=r"^--imu-topic are for a ROS bag$"):
        open_source("tcp://127.0.0.1:5600", fuse={"imu_topic": "/imu"})
    with pytest.raises(GPR3DError, match=r"--fuse is for a ROS bag or a tcp:// stream carrying IMU samples"):
        open_source(tmp_path / "LINE.DZT", poses=tmp_path / "p.tum", fuse={})


def test_a_replay_with_sensors_sends_each_message_at_its_time_and_checks_its_inputs(rig_run):
    from gpr3d.io.stream import StreamDecoder
    from gpr3d.pipeline.replay import read_sensors

    folder, _, survey = rig_run
    sensors = read_sensors(folder / "imu.csv", folder / "odometry.tum", folder / "wheel.csv")
    th, port = _serve(survey, 2500.0, sensors=sensors)
    import socket as _socket
    import struct

    raw = bytearray()
    with _socket.create_connection(("127.0.0.1", port)) as s:
        while b := s.recv(1 << 16):
            raw += b
    th.join(10)
    dec = StreamDecoder()
    traces = dec.feed(bytes(raw))
    assert dec.ended and dec.header.sensors == ("imu", "odometry", "wheel")
    assert dec.header.imu_rate_hz == pytest.approx(1 / np.median(np.diff(sensors["imu"][:, 0])), rel=1e-12)
    np.testing.assert_array_equal([t.time_s for t in traces], survey.timestamps_s)
    for k, v in dec.take_sensors().items():  # (quaternions made unit once more: a few ulps on any CPU)
        np.testing.assert_allclose(v, sensors[k], rtol=0, atol=1e-14)
    # the messages, walked in the order sent: every kind's times interleaved in one time order
    sizes = {b"TRCE": 76 + 4 * 128, b"IMU_": 60, b"CAMP": 68, b"WHEL": 20}
    at = 12 + struct.unpack("<I", raw[8:12])[0]
    when = []
    while raw[at:at + 4] != b"END!":
        tag = bytes(raw[at:at + 4])
        when.append(struct.unpack_from("<d", raw, at + (12 if tag == b"TRCE" else 4))[0])
        at += sizes[tag]
    assert len(when) == survey.n_traces + sum(len(v) for v in sensors.values())
    assert np.all(np.diff(when) >= 0)
    with pytest.raises(GPR3DError, match="plays once"):
        replay_to_tcp(survey, 0, rate=100.0, loops=2, sensors=sensors)
    with pytest.raises(GPR3DError, match="must include the IMU"):
        replay_to_tcp(survey, 0, rate=100.0, sensors={"odometry": sensors["odometry"]})
    untimed = Survey(data=survey.data, dt_s=DT)
    with pytest.raises(GPR3DError, match="carry no increasing times"):
        replay_to_tcp(untimed, 0, rate=100.0, sensors=sensors)


@pytest.mark.parametrize("f_hz, want", [(800e6, 0.02), (250e6, 0.049), (None, 0.02)])
def test_live_sizes_its_voxels_by_the_stream_s_antenna_as_reconstruct_does(f_hz, want, tmp_path):
    """No spacing given: the stream header's frequency in the host sets the voxel, as reconstruct's default does
    for the same record (so that the final volume can equal the batch one): 800 MHz in eps_r 6, 2 cm (15.3 cm / 10 is finer);
    250 MHz, 49.0 cm / 10; none, 2 cm."""
    from gpr3d.migration.reconstruct import voxel_spacing_m

    header = StreamHeader(n_samples=128, dt_s=DT, frequency_hz=f_hz, offset_m=0.05, eps_r=EPS)
    live = LiveReconstruction(header, LiveConfig(reconstruct=ReconstructConfig(aperture_deg=45.0), detect=False),
                              tmp_path)
    assert live.rc.spacing_m == pytest.approx(want, abs=1e-12) == voxel_spacing_m(f_hz, EPS)[0]
    # a header's eps_r that is no permittivity is named as such, not as a voxel size made from it
    bad = StreamHeader(n_samples=128, dt_s=DT, frequency_hz=f_hz, offset_m=0.05, eps_r=float("nan"))
    with pytest.raises(GPR3DError, match=r"^eps_r must be a finite number, got nan$"):
        LiveReconstruction(bad, LiveConfig(reconstruct=ReconstructConfig(aperture_deg=45.0), detect=False), tmp_path)


def test_a_growing_dt1_takes_its_antenna_from_the_hd_unless_an_offset_is_given(tmp_path):
    from tests.io.makers import write_dt1

    rec = write_dt1(tmp_path / "line", n_traces=4, n_points=20, window_ns=40.0, units="cm", freq=250.0, sep=40.0)
    _tum_of(Survey(data=np.zeros((4, 20), np.float32), dt_s=DT, positions_xyz=np.zeros((4, 3)),
                   orientations_quat_wxyz=np.tile([1.0, 0, 0, 0], (4, 1))), tmp_path / "line.tum")
    for offset, want in ((None, 0.4), (0.1, 0.1), (0.0, 0.0)):
        source = open_source(rec, poses=tmp_path / "line.tum", offset_m=offset)
        data, poses, times = source.poll()
        h = source.header
        assert (h.offset_m, h.frequency_hz, h.n_samples, len(data)) == (pytest.approx(want), 250e6, 20, 4)
        assert h.dt_s == pytest.approx(2e-9) and h.eps_r is None  # (a DT1 names no permittivity: --eps-r)


def test_replay_to_file_refuses_what_it_cannot_grow(tmp_path):
    from gpr3d.core.errors import FormatError
    from tests.io.makers import write_dt1

    src = write_dt1(tmp_path / "line", n_traces=3, n_points=20)
    with pytest.raises(GPR3DError, match=r"^--to .*out\.dzt: a DT1 recording grows into a \.DT1 file$"):
        replay_to_file(src, tmp_path / "out.dzt", rate=10.0)
    (tmp_path / "x.rd3").write_bytes(b"\0" * 300)
    with pytest.raises(FormatError, match="replaying into a file takes a DZT or DT1 recording"):
        replay_to_file(tmp_path / "x.rd3", tmp_path / "y.rd3", rate=10.0)
    (tmp_path / "short.DT1").write_bytes(b"\0" * 100)
    with pytest.raises(FormatError, match="shorter than one trace header: not a pulseEKKO DT1"):
        replay_to_file(tmp_path / "short.DT1", tmp_path / "o.DT1", rate=10.0)
    assert not (tmp_path / "out.dzt").exists() and not (tmp_path / "o.DT1").exists()


def test_the_warm_up_runs_the_box_refiner_once_before_any_trace():
    """The warm-up's detector run reports no boxes (score threshold 1), and only reported boxes are refined: so
    the refiner's network is run on its own, two blank crops, or the first window with targets pays its start."""
    from gpr3d.detection.refine import CROP
    from gpr3d.pipeline import live as L

    calls = []

    class Refiner:
        def predict_crops(self, crops):
            calls.append(("refine", crops.shape, float(np.abs(crops).max())))
            return np.zeros((len(crops), 4))

    class Detector:
        window = type("W", (), {"traces": 32})()
        refiner = Refiner()

        def share_cores(self):
            calls.append(("share",))

        def detect(self, survey, score_threshold):
            calls.append(("detect", survey.n_traces, score_threshold))

    L._warm_up(L.LiveConfig(), Detector())
    assert calls == [("share",), ("detect", 32, 1.0), ("refine", (2, 3, CROP, CROP), 0.0)]
    calls.clear()
    Detector.refiner = None  # no refiner: nothing more
    L._warm_up(L.LiveConfig(), Detector())
    assert calls == [("share",), ("detect", 32, 1.0)]
    calls.clear()
    L._warm_up(L.LiveConfig(detect=False), Detector())  # detection off: the detector is not run
    assert calls == []
    del Detector.refiner  # a detector of the caller's own, without a refiner attribute at all: none
    L._warm_up(L.LiveConfig(), Detector())
    assert calls == [("share",), ("detect", 32, 1.0)]
