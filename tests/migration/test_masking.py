import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.migration.masking import box_mask, check_boxes

DT = 0.1e-9  # 200 samples: a 20 ns window


def test_box_mask_is_one_inside_and_tapers_to_zero():
    m = box_mask(50, 200, DT, [[10, 5e-9, 20, 8e-9]], taper_traces=3)
    assert m[15, 65] == 1.0 and m[10, 50] == 1.0 and m[20, 80] == 1.0
    assert 0 < m[8, 65] < 1 and m[5, 65] == 0 and m[30, 65] == 0
    assert 0 < m[15, 48] < 1 and m[15, 40] == 0
    assert np.all(np.diff(m[10:21, 65]) == 0)


@pytest.mark.parametrize("box, words", [
    ([1, 2e-9, 3], "must be 4 numbers"),
    ([1, "x", 3, 4e-9], "must be 4 numbers"),
    ([1, float("nan"), 3, 4e-9], "not finite"),
    ([5, 2e-9, 3, 4e-9], "empty"),
    ([1, 4e-9, 3, 2e-9], "empty"),
    ([1, 5.0, 3, 9.0], "in seconds"),  # nanoseconds given as seconds: far past the 20 ns window
    ([60, 1e-9, 70, 2e-9], "outside the data"),
])
def test_bad_boxes_get_a_one_line_error_naming_the_box(box, words):
    with pytest.raises(InvalidDataError, match=words) as e:
        check_boxes([[0, 0.0, 1, 1e-9], box], 50, 200 * DT)
    assert "box 1" in str(e.value) and "\n" not in str(e.value)


# ---------------------------------------------------------------- the taper and the boxes by hand

from gpr3d.migration.masking import image_envelope, masked_migration, signal_to_clutter  # noqa: E402


def test_the_taper_is_a_half_cosine_by_hand():
    """A box over traces 10..20 with a 4-trace taper: trace 8 (2 out) is 0.5 (1 + cos(pi/2)) = 0.5, trace 9 is
    0.5 (1 + cos(pi/4)) = 0.854, trace 6 (4 out) and beyond 0; in time the default taper is 3 samples."""
    m = box_mask(40, 100, DT, [[10, 3e-9, 20, 5e-9]], taper_traces=4)
    col = m[:, 40].astype(float)
    assert col[8] == pytest.approx(0.5, abs=1e-6) and col[9] == pytest.approx(0.5 * (1 + np.cos(np.pi / 4)), abs=1e-6)
    assert col[7] == pytest.approx(0.5 * (1 + np.cos(3 * np.pi / 4)), abs=1e-6)
    assert col[6] == 0 and col[5] == 0 and col[22] == pytest.approx(0.5, abs=1e-6) and col[24] == 0
    row = m[15].astype(float)  # samples 30..50 inside; 3-sample taper
    assert row[30] == 1 and row[50] == 1 and row[29] == pytest.approx(0.5 * (1 + np.cos(np.pi / 3)), abs=1e-6)
    assert row[28] == pytest.approx(0.5 * (1 + np.cos(2 * np.pi / 3)), abs=1e-6) and row[27] == 0
    assert row[51] == pytest.approx(0.5 * (1 + np.cos(np.pi / 3)), abs=1e-6) and row[53] == 0
    assert m.dtype == np.float32


def test_a_taper_in_seconds_and_no_taper():
    m = box_mask(10, 100, DT, [[2, 3e-9, 4, 5e-9]], taper_traces=0, taper_s=0.5e-9)  # 5 samples
    assert m[1, 40] == 0 and m[2, 40] == 1 and m[4, 40] == 1 and m[5, 40] == 0
    assert m[3, 25] == 0 and m[3, 26] == pytest.approx(0.5 * (1 + np.cos(4 * np.pi / 5)), abs=1e-6)
    # fractional box edges: the taper counts from the edge itself
    m = box_mask(10, 100, DT, [[2.5, 3e-9, 4, 5e-9]], taper_traces=1)
    assert m[2, 40] == pytest.approx(0.5 * (1 + np.cos(np.pi / 2)), abs=1e-6) and m[3, 40] == 1


def test_overlapping_boxes_take_the_larger_weight():
    m = box_mask(30, 100, DT, [[5, 2e-9, 10, 4e-9], [9, 3e-9, 15, 6e-9]], taper_traces=2)
    assert m.max() == 1.0
    assert m[12, 35] == 1 and m[7, 25] == 1 and m[11, 25] == pytest.approx(0.5, abs=1e-6)  # box 1, a trace out


def test_box_edges_on_the_data_edges_are_accepted():
    assert check_boxes([[0, 0.0, 49, 20e-9], [49, 20e-9, 49, 21e-9], [-5, -1e-9, 0, 0.0 + 1e-12]], 50, 20e-9) == [
        (0.0, 0.0, 49.0, 20e-9), (49.0, 20e-9, 49.0, 21e-9), (-5.0, -1e-9, 0.0, 1e-12)]
    with pytest.raises(InvalidDataError, match="box 0 .* lies outside the data \\(50 traces, 20 ns\\)"):
        check_boxes([[50, 1e-9, 60, 2e-9]], 50, 20e-9)
    with pytest.raises(InvalidDataError, match="lies outside"):
        check_boxes([[1, 1e-9, 3, 2e-9], [1, 21e-9, 3, 22e-9]], 50, 20e-9)
    with pytest.raises(InvalidDataError, match="lies outside"):
        check_boxes([[-9, 1e-9, -1, 2e-9]], 50, 20e-9)
    with pytest.raises(InvalidDataError, match="lies outside"):
        check_boxes([[1, -3e-9, 3, -1e-9]], 50, 20e-9)


def test_masked_migration_is_the_adjoint_of_each_part():
    class Double:  # an 'operator' whose adjoint doubles its input: the parts are exactly twice the masked data
        def adjoint(self, d):
            return 2 * d

    data = np.arange(12, dtype=np.float64).reshape(3, 4)
    mask = np.array([[1, 0, 0.5, 1]] * 3, np.float32)
    sig, noise = masked_migration(Double(), data, mask)
    np.testing.assert_array_equal(sig, 2 * data * mask)
    np.testing.assert_array_equal(noise, 2 * data * (1 - mask))
    assert sig.dtype == np.float32


def test_the_envelope_of_a_modulated_column_is_its_gaussian():
    z = np.arange(256)
    g = np.exp(-0.5 * ((z - 128) / 12.0) ** 2)
    col = g * np.cos(2 * np.pi * z / 8.0)
    img = np.broadcast_to(col, (3, 2, 256)).astype(np.float32)
    env = image_envelope(img, chunk_voxels=600)  # one column of x per slab
    np.testing.assert_allclose(env[:, :, 64:192], np.broadcast_to(g[64:192], (3, 2, 128)), atol=2e-3)
    assert env.dtype == np.float32


def test_signal_to_clutter_by_hand():
    env = np.array([4.0, 4.0, 1.0, 1.0, 1.0, 1.0])
    tm = np.array([True, True, False, False, False, False])
    assert signal_to_clutter(env, tm) == pytest.approx(20 * np.log10(4.0))
    env2 = np.array([6.0, 2.0, 3.0, 4.0])  # mean 4 on targets, RMS 3.5355 elsewhere
    assert signal_to_clutter(env2, np.array([True, True, False, False])) == pytest.approx(
        20 * np.log10(4.0 / np.sqrt(12.5)))
    assert signal_to_clutter(np.array([1.0, 0.0]), np.array([True, False])) == float("inf")


def test_defaults_and_edges_of_the_boxes():
    m = box_mask(20, 100, DT, [[5, 3e-9, 10, 5e-9]])  # the default taper: 3 traces, 3 samples
    assert m[4, 40] == pytest.approx(0.5 * (1 + np.cos(np.pi / 3)), abs=1e-6) and m[2, 40] == 0
    assert m[7, 29] == pytest.approx(0.5 * (1 + np.cos(np.pi / 3)), abs=1e-6)
    with pytest.raises(InvalidDataError, match="lies outside the data"):
        box_mask(20, 100, DT, [[1, 11e-9, 3, 12e-9]])  # past the 10 ns record
    with pytest.raises(InvalidDataError, match="is empty or not finite"):
        check_boxes([[1, 2e-9, 3, 2e-9]], 20, 10e-9)  # no time span
    assert check_boxes([[1, -2e-9, 3, 0.0]], 20, 10e-9) == [(1.0, -2e-9, 3.0, 0.0)]  # ends at the first sample
    with pytest.raises(InvalidDataError) as e:
        check_boxes([[30, 1e-9, 40, 2e-9]], 20, 10e-9)
    assert str(e.value) == ("box 0 [30, 1e-09, 40, 2e-09] lies outside the data (20 traces, 10 ns): are its times in "
                            "seconds?")


def test_the_envelope_of_float64_input_is_float32():
    z = np.arange(64)
    img = np.broadcast_to(np.cos(2 * np.pi * z / 8.0), (2, 3, 64)).astype(np.float64)
    env = image_envelope(img)
    assert env.dtype == np.float32
    # (a cosine cut off at both ends: its envelope ripples by a few hundredths away from them)
    np.testing.assert_allclose(env[:, :, 16:48], 1.0, atol=0.03)
    np.testing.assert_allclose(image_envelope(img, chunk_voxels=1), env)  # one x column per slab


def test_the_bottom_of_a_column_does_not_wrap_onto_its_top():
    from scipy.signal import hilbert

    rng = np.random.default_rng(8)
    z = np.arange(120)
    col = np.cos(2 * np.pi * z / 9.0) * np.exp(-(((z - 30) / 6.0) ** 2))  # a target at 30
    img = np.broadcast_to(col, (2, 2, 120)).astype(np.float32).copy()
    img[:, :, 80:] += rng.standard_normal((2, 2, 40)).astype(np.float32)  # noise as strong deep down
    alone = np.abs(hilbert(col[:60], N=1024))[:10]  # the top's envelope with nothing below the target
    padded = image_envelope(img)[0, 0, :10]
    wrapped = np.abs(hilbert(img[0, 0]))[:10]  # the transform without zeros: the bottom wraps onto the top
    assert np.abs(padded - alone).max() < 0.05 < 0.5 < np.abs(wrapped - alone).max()


def test_no_clutter_is_an_infinite_ratio():
    assert signal_to_clutter(np.array([2.0, 0.0, 0.0]), np.array([True, False, False])) == float("inf")


def test_the_envelope_in_slabs_of_a_wide_image():
    rng = np.random.default_rng(3)
    img = rng.standard_normal((5, 70, 16)).astype(np.float32)  # more y columns than depths
    from scipy.signal import hilbert

    # each column followed by zeros to 2 x 16 = 32 samples (no wrap of its bottom onto its top), as scipy pads to N
    want = np.abs(hilbert(img, N=32, axis=2))[:, :, :16]
    np.testing.assert_allclose(image_envelope(img, chunk_voxels=2000), want, atol=1e-5)
    assert np.abs(np.abs(hilbert(img, axis=2)) - want).max() > 0.05  # (the unpadded transform differs)


@pytest.mark.parametrize("taper_traces, taper_s", [(3.0, None), (0.0, 0.35e-9), (7.5, 1e-9)])
def test_many_boxes_give_the_largest_weight_of_each_whole_window(taper_traces, taper_s):
    """A hundred boxes, some over the data's edges, some overlapping: the mask equals, bit for bit, the largest of
    each box's own window (its trace taper times its time taper over the whole record, by hand here), however
    little of the record each box's taper reaches."""
    rng = np.random.default_rng(5)
    n, ns, dt = 700, 160, 0.1e-9
    boxes = []
    for _ in range(100):
        i0, t0 = rng.uniform(-4, n - 1), rng.uniform(0, ns * dt * 0.95)
        boxes.append([i0, t0, i0 + rng.uniform(0, 60), t0 + rng.uniform(0.05e-9, 3e-9)])
    boxes += [[0, 0.0, 2, 0.3e-9], [n - 1, 15.5e-9, n - 1, ns * dt]]  # corners: one trace, to the record's end

    def taper(m, lo, hi, width):
        i = np.arange(m, dtype=float)
        d = np.maximum(lo - i, 0) + np.maximum(i - hi, 0)
        if width <= 0:
            return (d == 0).astype(float)
        return 0.5 * (1 + np.cos(np.pi * np.minimum(d / width, 1.0)))

    tw = taper_s / dt if taper_s else 3.0
    want = np.zeros((n, ns))
    for i0, t0, i1, t1 in boxes:
        want = np.maximum(want, np.outer(taper(n, i0, i1, taper_traces), taper(ns, t0 / dt, t1 / dt, tw)))
    got = box_mask(n, ns, dt, boxes, taper_traces=taper_traces, taper_s=taper_s)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, want.astype(np.float32))
    assert 0.05 < (got > 0).mean() < 0.9 and got[0, 0] == 1.0 and got[-1, -1] == 1.0


def test_each_box_costs_its_own_window_not_the_record(monkeypatch):
    """The product of a box's tapers is formed only over the traces and samples where both are non-zero (a
    hundred boxes over a whole record took seconds); a box whose window holds one sample, or none, still counts
    (or adds nothing)."""
    n, ns, dt = 300, 120, 0.1e-9
    shapes = []
    outer = np.outer
    monkeypatch.setattr(np, "outer", lambda a, b: shapes.append((len(a), len(b))) or outer(a, b))
    m = box_mask(n, ns, dt, [[100, 5e-9, 110, 6e-9]], taper_traces=3.0, taper_s=0.25e-9)
    # traces 98..112 (3 beyond 100 and 110 the half-cosine is 0), samples 48..62 (2.5 samples of taper)
    assert shapes == [(15, 15)] and np.array_equal(np.flatnonzero(m.any(axis=1)), np.arange(98, 113))
    shapes.clear()
    tiny = 1e-15  # (a taper of 1e-5 samples: the box's own samples only)
    m = box_mask(n, ns, dt, [[10, 1.0e-9, 12, 1.05e-9], [50, 2.02e-9, 52, 2.08e-9]], taper_traces=0.0,
                 taper_s=tiny)
    assert shapes == [(3, 1)]  # the second box holds no whole sample
    assert m.sum() == 3.0 and m[10:13, 10].tolist() == [1.0, 1.0, 1.0]
