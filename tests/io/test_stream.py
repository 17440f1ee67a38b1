"""The live trace stream (gpr3d.io.stream): the bytes it writes decode to the same traces however they are cut
into pieces; each way of breaking the format gets its own one-line error; growing DZT, DT1 and TUM files give each
trace once, as the batch readers read them."""

import struct

import numpy as np
import pytest

from gpr3d.core.errors import FormatError
from gpr3d.io.dt1 import read_dt1
from gpr3d.io.dzt import read_dzt
from gpr3d.io.stream import (
    END,
    GrowingDT1,
    GrowingDZT,
    GrowingTUM,
    StreamDecoder,
    StreamHeader,
    encode_camera_pose,
    encode_header,
    encode_imu,
    encode_trace,
    encode_wheel,
)
from tests.io.makers import write_dt1, write_dzt

HEADER = StreamHeader(n_samples=5, dt_s=1e-10, frequency_hz=1e9, offset_m=0.05, eps_r=6.0, name="t")


def _traces(n=4, seed=0):
    rng = np.random.default_rng(seed)
    poses = np.c_[rng.normal(size=(n, 3)), np.tile([np.cos(0.3), 0, 0, np.sin(0.3)], (n, 1))]
    return poses, rng.normal(size=(n, 5)).astype(np.float32)


def _stream(poses, samples, *, end=True):
    b = encode_header(HEADER)
    for i, (p, s) in enumerate(zip(poses, samples)):
        b += encode_trace(i, 0.5 * i, p, s)
    return b + (END if end else b"")


@pytest.mark.parametrize("piece", [1, 7, 1000])
def test_the_stream_decodes_to_its_traces_in_any_pieces(piece):
    poses, samples = _traces()
    raw = _stream(poses, samples)
    dec = StreamDecoder()
    got = []
    for i in range(0, len(raw), piece):
        got += dec.feed(raw[i:i + piece])
    assert dec.header == HEADER and dec.ended
    assert [t.index for t in got] == [0, 1, 2, 3]
    assert [t.time_s for t in got] == [0.0, 0.5, 1.0, 1.5]
    np.testing.assert_array_equal(np.stack([t.pose for t in got]), poses)
    np.testing.assert_array_equal(np.stack([t.samples for t in got]), samples)


def test_the_trace_layout_is_the_documented_one():
    b = encode_trace(3, 2.5, [1, 2, 3, 1, 0, 0, 0], np.array([0.5, -1.0], np.float32))
    assert b[:4] == b"TRCE"
    assert struct.unpack("<Qd7d", b[4:76]) == (3, 2.5, 1.0, 2.0, 3.0, 1.0, 0.0, 0.0, 0.0)
    assert np.frombuffer(b[76:], "<f4").tolist() == [0.5, -1.0]
    h = encode_header(StreamHeader(n_samples=2, dt_s=1e-9))
    assert h[:8] == b"GPR3DTR1" and struct.unpack("<I", h[8:12])[0] == len(h) - 12


def _header(body):
    return b"GPR3DTR1" + struct.pack("<I", len(body)) + body


def _bad_pose(p):
    q = p.copy()
    q[0, 3:] = [1, 1, 0, 0]
    return q


@pytest.mark.parametrize("make, message", [
    (lambda p, s: b"GPR3DXX1" + _stream(p, s)[8:], "does not open with GPR3DTR1"),
    (lambda p, s: b"NOPE", "does not open with GPR3DTR1"),
    (lambda p, s: encode_header(HEADER) + encode_trace(1, 0, p[0], s[0]), "trace index 1 where 0 was due"),
    (lambda p, s: encode_header(HEADER) + encode_trace(0, 0, _bad_pose(p)[0], s[0]), "not a unit quaternion"),
    (lambda p, s: encode_header(HEADER) + encode_trace(0, 0, p[0], np.full(5, np.nan)), "non-finite samples"),
    (lambda p, s: encode_header(HEADER) + encode_trace(0, float("inf"), p[0], s[0]), "pose or time is not finite"),
    (lambda p, s: encode_header(HEADER) + b"XXXX", "expected TRCE or END!"),
    (lambda p, s: _stream(p, s) + b"TRCE", "bytes after the end mark"),
    (lambda p, s: _header(b'{"dt_s":1}'), "header lacks 'n_samples'"),
    (lambda p, s: _header(b'{"n_samples":1,"dt_s":1e-9}'), "n_samples must be"),
    (lambda p, s: _header(b'{"n_samples":4,"dt_s":-1e-9}'), "dt_s must be"),
    (lambda p, s: _header(b'{"n_samples":4,"dt_s":1e-9,"eps_r":0.5}'), "eps_r must be"),
    (lambda p, s: _header(b"{x}"), "header is not JSON"),
])
def test_a_broken_stream_is_named_in_one_line(make, message):
    poses, samples = _traces()
    with pytest.raises(FormatError, match=message):
        StreamDecoder().feed(make(poses, samples))


def test_a_stream_closed_inside_a_trace_is_an_error_and_at_a_trace_boundary_an_end():
    poses, samples = _traces()
    raw = _stream(poses, samples, end=False)
    dec = StreamDecoder()
    assert len(dec.feed(raw[:-3])) == 3
    with pytest.raises(FormatError, match="ends inside a trace"):
        dec.close()
    dec = StreamDecoder()
    assert len(dec.feed(raw)) == 4
    dec.close()
    assert dec.ended


def test_a_growing_dzt_gives_each_trace_once_as_the_reader_reads_it(tmp_path):
    whole = write_dzt(tmp_path / "whole.dzt", n_traces=9, n_samples=16)
    ref = read_dzt(whole)[0].data
    raw = whole.read_bytes()
    grow = tmp_path / "grow.dzt"
    g = GrowingDZT(grow)
    assert g.poll().shape[0] == 0  # no file yet
    grow.write_bytes(raw[:600])  # half a header
    assert g.poll().shape[0] == 0 and g.header is None
    tb = 16 * 2
    got = []
    for cut in (1024, 1024 + tb // 2, 1024 + 3 * tb, 1024 + 3 * tb + 1, 1024 + 8 * tb, len(raw)):
        grow.write_bytes(raw[:cut])
        got.append(g.poll())
    assert [len(x) for x in got] == [0, 0, 3, 0, 5, 1]
    np.testing.assert_array_equal(np.concatenate(got), ref)
    assert g.dt_s == pytest.approx(20e-9 / 16)
    grow.write_bytes(raw[:1024 + 2 * tb])
    with pytest.raises(FormatError, match="shrank"):
        g.poll()


@pytest.mark.parametrize("bits", [16, 32])
def test_a_growing_dt1_gives_each_trace_once_as_the_batch_reader_reads_it(tmp_path, bits):
    whole = write_dt1(tmp_path / "whole", n_traces=9, n_points=20, window_ns=50.0, units="cm", freq=500.0, sep=14.0,
                      bits=bits)
    ref = read_dt1(whole)[0]
    raw = whole.read_bytes()
    grow = tmp_path / "grow.DT1"
    (tmp_path / "grow.HD").write_bytes((tmp_path / "whole.HD").read_bytes())
    g = GrowingDT1(grow)
    assert g.poll().shape[0] == 0 and g.header is None  # no file yet
    tb = 128 + 20 * bits // 8
    got = []
    for cut in (100, tb - 1, tb, tb + 5, 4 * tb, 4 * tb + tb // 2, 8 * tb, len(raw)):
        grow.write_bytes(raw[:cut])
        got.append(g.poll())
    assert [len(x) for x in got] == [0, 0, 1, 0, 3, 0, 4, 1]
    np.testing.assert_array_equal(np.concatenate([x for x in got if len(x)]), ref.data)
    assert g.dt_s == ref.dt_s == pytest.approx(50e-9 / 20)
    # the HD's antenna: 500 MHz, 14 cm apart (its positions are in cm)
    assert (g.header["frequency_hz"], g.header["separation_m"]) == (ref.frequency_hz, ref.offset_m) == (500e6, 0.14)
    grow.write_bytes(raw[:2 * tb])
    with pytest.raises(FormatError, match=r"shrank while being read \(2 whole traces, 9 read\)"):
        g.poll()


def test_a_growing_dt1_without_its_hd_takes_the_interval_given_or_names_what_is_missing(tmp_path):
    whole = write_dt1(tmp_path / "whole", n_traces=3, n_points=20)
    grow = tmp_path / "grow.dt1"
    grow.write_bytes(whole.read_bytes())
    with pytest.raises(FormatError) as err:
        GrowingDT1(grow).poll()
    assert str(err.value) == "grow.dt1: no HD header beside it to give the sample interval: give it (--dt, in ns)"
    g = GrowingDT1(grow, dt_s=2e-10)
    np.testing.assert_array_equal(g.poll(), read_dt1(whole)[0].data)
    assert g.dt_s == 2e-10 and g.header["frequency_hz"] is None and g.header["separation_m"] is None


@pytest.mark.parametrize("case, message", [
    ("points", "grow.DT1: first trace header says 0.5 points a trace: not a pulseEKKO DT1, or corrupt"),
    ("hd", "grow.DT1: first trace header says 20 points, grow.HD says 25: mismatched files"),
    ("later", "grow.DT1: trace 2 header says 21 points, the first says 20: corrupt"),
])
def test_a_growing_dt1_that_cannot_be_right_is_named(tmp_path, case, message):
    whole = write_dt1(tmp_path / "whole", n_traces=4, n_points=20, bad_trace=2 if case == "later" else None)
    raw = bytearray(whole.read_bytes())
    hd = (tmp_path / "whole.HD").read_text()
    if case == "points":
        raw[8:12] = np.float32(0.5).tobytes()
    if case == "hd":
        hd = hd.replace("NUMBER OF PTS/TRC  = 20", "NUMBER OF PTS/TRC  = 25")
    (tmp_path / "grow.HD").write_text(hd)
    (tmp_path / "grow.DT1").write_bytes(bytes(raw))
    with pytest.raises(FormatError) as err:
        GrowingDT1(tmp_path / "grow.DT1").poll()
    assert str(err.value) == message


def test_a_growing_tum_gives_whole_lines_only(tmp_path):
    p = tmp_path / "poses.tum"
    t = GrowingTUM(p)
    assert t.poll().shape == (0, 8)
    p.write_text("# t x y z qx qy qz qw\n0 1 2 3 0 0 0 2\n0.1 1.5 2 3 0 0 0 1")
    got = t.poll()
    np.testing.assert_array_equal(got, [[0, 1, 2, 3, 1, 0, 0, 0]])  # the quaternion as w x y z, normalised
    with open(p, "a") as f:
        f.write(".5\n0.2 9 9 9 0 0 1 0\n")
    np.testing.assert_allclose(t.poll(), [[0.1, 1.5, 2, 3, 1, 0, 0, 0], [0.2, 9, 9, 9, 0, 0, 0, 1]])
    with open(p, "a") as f:
        f.write("0.1 0 0 0 0 0 0 1\n")
    with pytest.raises(FormatError, match="timestamps run backwards at pose 3"):
        t.poll()


@pytest.mark.parametrize("line, message", [("0 1 2 3 0 0 0\n", "expected 8 finite numbers"),
                                           ("0 1 2 x 0 0 0 1\n", "not numbers"),
                                           ("0 1 2 3 0 0 0 0\n", "a zero quaternion")])
def test_a_bad_pose_line_is_named(tmp_path, line, message):
    p = tmp_path / "poses.tum"
    p.write_text(line)
    with pytest.raises(FormatError, match=message):
        GrowingTUM(p).poll()


# -- sensor messages beside the traces ---------------------------------------------------------------------------

SENSED = StreamHeader(n_samples=5, dt_s=1e-10, sensors=("imu", "odometry", "wheel"), imu_rate_hz=200.0)


def _sensor_stream(n=4):
    """A stream of traces without poses, IMU samples, camera poses and wheel readings interleaved; with the
    rows each kind should decode to."""
    poses, samples = _traces(n)
    rng = np.random.default_rng(1)
    imu = np.c_[0.1 * np.arange(2 * n), rng.normal(size=(2 * n, 6)) + [0, 0, 9.8, 0, 0, 0]]
    q = rng.normal(size=(n, 4))
    cam = np.c_[0.2 * np.arange(n) + 0.05, rng.normal(size=(n, 3)), q / np.linalg.norm(q, axis=1, keepdims=True)]
    wheel = np.c_[0.2 * np.arange(n) + 0.01, np.cumsum(rng.uniform(0, 0.1, n))]
    b = encode_header(SENSED)
    for i in range(n):
        b += encode_imu(imu[2 * i, 0], imu[2 * i, 1:4], imu[2 * i, 4:]) + encode_wheel(*wheel[i])
        b += encode_trace(i, 0.2 * i, np.full(7, np.nan), samples[i])
        b += encode_camera_pose(cam[i, 0], cam[i, 1:]) + encode_imu(imu[2 * i + 1, 0], imu[2 * i + 1, 1:4],
                                                                    imu[2 * i + 1, 4:])
    return b + END, {"imu": imu, "odometry": cam, "wheel": wheel}, samples


@pytest.mark.parametrize("piece", [1, 13, 10000])
def test_sensor_messages_decode_by_kind_beside_traces_without_poses(piece):
    raw, want, samples = _sensor_stream()
    dec = StreamDecoder()
    traces, got = [], {k: [] for k in want}
    for i in range(0, len(raw), piece):
        traces += dec.feed(raw[i:i + piece])
        if dec.header is not None:
            for k, v in dec.take_sensors().items():
                got[k].append(v)
    assert dec.header == SENSED and dec.ended
    assert dec.header.to_dict()["sensors"] == ["imu", "odometry", "wheel"]
    for k in want:  # (the camera's unit quaternions divided by their norm once more: 1 +- a few ulps on any CPU)
        np.testing.assert_allclose(np.concatenate(got[k]), want[k], rtol=0, atol=1e-14)
    assert dec.take_sensors() == {"imu": pytest.approx(np.zeros((0, 7))), "odometry": pytest.approx(np.zeros((0, 8))),
                                  "wheel": pytest.approx(np.zeros((0, 2)))}
    np.testing.assert_array_equal(np.stack([t.samples for t in traces]), samples)
    assert all(np.isnan(t.pose).all() for t in traces) and [t.time_s for t in traces] == [0.0, 0.2, 0.4, 0.6000000000000001]


def test_the_sensor_layouts_are_the_documented_ones():
    assert struct.unpack("<4s7d", encode_imu(1.5, [1, 2, 3], [4, 5, 6])) == (b"IMU_", 1.5, 1, 2, 3, 4, 5, 6)
    assert struct.unpack("<4s8d", encode_camera_pose(2.5, [1, 2, 3, 1, 0, 0, 0])) == (b"CAMP", 2.5, 1, 2, 3, 1, 0, 0, 0)
    assert struct.unpack("<4s2d", encode_wheel(3.5, 0.25)) == (b"WHEL", 3.5, 0.25)


def _sensed(*parts, header=SENSED):
    return encode_header(header) + b"".join(parts)


@pytest.mark.parametrize("make, message", [
    (lambda: _sensed(encode_wheel(1, 0), header=StreamHeader(n_samples=5, dt_s=1e-10, sensors=("imu",))),
     r"wheel reading 0: a WHEL message the header's sensors \(\['imu'\]\) do not declare"),
    (lambda: _sensed(encode_imu(0, [0, 0, 9.8], [0, 0, 0]), header=HEADER), "IMU sample 0: a IMU_ message"),
    (lambda: _sensed(encode_imu(0, [0, 0, np.nan], [0, 0, 0])), "IMU sample 0: not finite"),
    (lambda: _sensed(encode_imu(1, [0, 0, 9.8], [0, 0, 0]), encode_imu(1, [0, 0, 9.8], [0, 0, 0])),
     r"IMU sample 1: its time 1 s is not after the one before \(1 s\)"),
    (lambda: _sensed(encode_camera_pose(0, [0, 0, 0, 1, 1, 0, 0])), "camera pose 0: its orientation is not a unit"),
    (lambda: _sensed(encode_trace(0, 0, [np.nan] * 7, np.zeros(5)), header=HEADER), "trace 0: its pose or time is not"),
    (lambda: _sensed(encode_trace(0, 0, [np.nan, 0, 0, 1, 0, 0, 0], np.zeros(5))), "trace 0: its pose or time is not"),
    (lambda: _header(b'{"n_samples":4,"dt_s":1e-9,"sensors":["odometry"]}'), r"lack 'imu'"),
    (lambda: _header(b'{"n_samples":4,"dt_s":1e-9,"sensors":["imu","imu"]}'), "distinct names out of imu, odometry"),
    (lambda: _header(b'{"n_samples":4,"dt_s":1e-9,"sensors":"imu"}'), "header sensors must be a list"),
    (lambda: _header(b'{"n_samples":4,"dt_s":1e-9,"sensors":["imu"],"imu_rate_hz":0}'), "imu_rate_hz must be"),
])
def test_a_broken_sensor_message_is_named_in_one_line(make, message):
    with pytest.raises(FormatError, match=message):
        StreamDecoder().feed(make())


def test_a_camera_pose_s_quaternion_is_made_unit():
    dec = StreamDecoder()
    dec.feed(_sensed(encode_camera_pose(0, [0, 0, 0, 1.0005, 0, 0, 0])))
    np.testing.assert_array_equal(dec.take_sensors()["odometry"], [[0, 0, 0, 0, 1, 0, 0, 0]])


def test_real_pulseekko_lines_grown_trace_by_trace_are_what_the_batch_reader_reads(tmp_path):
    """Two real pulseEKKO recordings (50 MHz and 100 MHz, 16-bit) grown in uneven pieces with their HD beside them."""
    from tests.conftest import real_file

    for rel in ("gprpy_sns_50MHz/XLINE00.DT1", "gpro_sns_100MHz_grid/XLINE15.DT1"):
        src = real_file(rel)
        ref = read_dt1(src)[0]
        raw = src.read_bytes()
        grow = tmp_path / f"{src.parent.name}.DT1"
        grow.with_suffix(".HD").write_bytes(src.with_suffix(".HD").read_bytes())
        g, got = GrowingDT1(grow), []
        for cut in np.linspace(0, len(raw), 7).astype(int)[1:]:
            grow.write_bytes(raw[:cut])
            got.append(g.poll())
        np.testing.assert_array_equal(np.concatenate([x for x in got if len(x)]), ref.data)
        assert g.dt_s == ref.dt_s and g.header["frequency_hz"] == ref.frequency_hz
        assert g.header["separation_m"] == ref.offset_m and ref.offset_m > 0


def test_a_growing_dt1_s_interval_given_and_its_hd_must_agree_and_its_units_be_known(tmp_path):
    whole = write_dt1(tmp_path / "grow", n_traces=3, n_points=20, window_ns=50.0)  # 2.5 ns a sample
    g = GrowingDT1(whole, dt_s=2.5e-9)  # (the same as the HD's: taken)
    assert len(g.poll()) == 3 and g.dt_s == pytest.approx(2.5e-9)
    with pytest.raises(FormatError) as err:
        GrowingDT1(whole, dt_s=1e-10).poll()
    assert str(err.value) == ("grow.DT1: --dt 0.1 ns disagrees with grow.HD's 2.5 ns (TOTAL TIME WINDOW / NUMBER OF "
                              "PTS/TRC): drop --dt")
    hd = tmp_path / "grow.HD"
    hd.write_text(hd.read_text().replace("POSITION UNITS     = m", "POSITION UNITS     = furlongs"))
    with pytest.raises(FormatError) as err:
        GrowingDT1(whole).poll()
    assert str(err.value) == "grow.HD: unknown POSITION UNITS 'furlongs'"


def test_dt1_layout_reads_the_first_trace_header_once_it_is_all_there(tmp_path):
    from gpr3d.io.stream import dt1_layout

    whole = write_dt1(tmp_path / "w", n_traces=2, n_points=30, bits=32)
    p = tmp_path / "g.DT1"
    assert dt1_layout(p) is None  # no file yet
    p.write_bytes(whole.read_bytes()[:127])
    assert dt1_layout(p) is None  # a header cut short
    p.write_bytes(whole.read_bytes()[:128])
    assert dt1_layout(p) == (30, 4)
