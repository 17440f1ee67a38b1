"""Training windows and record sources by hand: where random_window places its window (a scripted generator),
the mirror of image and boxes, the seeded dataset, and the sources' cycling and errors."""

import numpy as np
import pytest

from gpr3d.core.errors import GPR3DError
from gpr3d.core.survey import Survey
from gpr3d.detection.data import MixedSource, PackedSource, RecordsSource, collate, random_window
from gpr3d.detection.windows import WindowConfig, make_window, prepare, record_scale, rows_interval, window_targets

CFG = WindowConfig(traces=16, rows=32)


class Scripted:
    """A generator whose random(), integers() and uniform() answer from lists (and record their arguments)."""

    def __init__(self, randoms=(), integers=(), uniforms=()):
        self.randoms, self.integers_, self.uniforms = list(randoms), list(integers), list(uniforms)
        self.calls = []

    def random(self):
        self.calls.append(("random",))
        return self.randoms.pop(0)

    def integers(self, *args):
        self.calls.append(("integers", *args))
        return self.integers_.pop(0)

    def uniform(self, *args):
        self.calls.append(("uniform", *args))
        return self.uniforms.pop(0)


def _record(n=60):
    rng = np.random.default_rng(2)
    s = Survey(data=rng.normal(size=(n, 64)).astype(np.float32), dt_s=1e-10, frequency_hz=1e9)
    labels = {"labels": [
        {"box": [20.0, 1e-9, 30.0, 3e-9], "apex_trace": 25.0, "apex_time_s": 1.5e-9, "visible": True},
        {"box": [40.0, 2e-9, 50.0, 4e-9], "apex_trace": 45.0, "apex_time_s": 2.5e-9, "visible": False},
        {"box": [3.0, 2e-9, 9.0, 4e-9], "apex_trace": 6.0, "apex_time_s": 2.5e-9}]}  # visible by default
    return s, labels


def _expected(s, labels, start):
    proc = prepare(s, CFG)
    win = make_window(proc, start, CFG, rows_interval(s, CFG), record_scale(proc))
    return win.image, window_targets(labels["labels"], win)


def test_a_window_over_a_visible_apex_placed_by_the_draws():
    s, labels = _record()
    # bias draw 0.3 < 0.8: over an apex; integers -> the first visible one (apex 25); uniform 0.25 of the window
    # before it: start round(25 - 0.25 x 16) = 21; then no flip (0.9 >= 0.5)
    rng = Scripted(randoms=[0.3, 0.9], integers=[0], uniforms=[0.25])
    image, boxes = random_window(s, labels, CFG, rng)
    assert rng.calls == [("random",), ("integers", 2), ("uniform", 0.1, 0.9), ("random",)]  # two visible labels
    want_img, want_boxes = _expected(s, labels, 21)
    np.testing.assert_array_equal(image, want_img)
    np.testing.assert_array_equal(boxes, want_boxes)
    assert image.dtype == np.float32 and boxes.dtype == np.float32 and image.flags["C_CONTIGUOUS"]
    # the second visible label (apex 6), its start clipped at 0: round(6 - 0.5 x 16) = -2 -> 0
    rng = Scripted(randoms=[0.1, 0.7], integers=[1], uniforms=[0.5])
    image, _ = random_window(s, labels, CFG, rng)
    np.testing.assert_array_equal(image, _expected(s, labels, 0)[0])
    # and at the other end: at most n - traces = 44
    far = dict(labels, labels=[dict(labels["labels"][0], apex_trace=59.0)])
    image, _ = random_window(s, far, CFG, Scripted(randoms=[0.1, 0.7], integers=[0], uniforms=[0.1]))
    np.testing.assert_array_equal(image, _expected(s, far, 44)[0])


def test_a_window_anywhere_when_the_bias_draw_says_so_or_nothing_is_visible():
    s, labels = _record()
    rng = Scripted(randoms=[0.8, 0.9], integers=[37])  # 0.8 is not below the bias 0.8
    image, _ = random_window(s, labels, CFG, rng)
    assert rng.calls[1] == ("integers", 0, 45)  # any start 0..44
    np.testing.assert_array_equal(image, _expected(s, labels, 37)[0])
    hidden = {"labels": [dict(labels["labels"][1])]}  # only an invisible label: no apex draw at all
    rng = Scripted(randoms=[0.9], integers=[5])
    image, boxes = random_window(s, hidden, CFG, rng, flip=False)
    assert rng.calls == [("integers", 0, 45)]
    np.testing.assert_array_equal(image, _expected(s, hidden, 5)[0])
    rng = Scripted(randoms=[0.5, 0.9], integers=[4])  # target_bias 0.4: 0.5 places it anywhere
    random_window(s, labels, CFG, rng, target_bias=0.4)
    assert rng.calls[1] == ("integers", 0, 45)


def test_a_short_record_starts_at_zero():
    s, labels = _record(n=10)  # shorter than a window: the only start is 0
    rng = Scripted(randoms=[0.9, 0.9], integers=[0])
    image, _ = random_window(s, {"labels": []}, CFG, rng)
    assert rng.calls[0] == ("integers", 0, 1)
    np.testing.assert_array_equal(image, _expected(s, {"labels": []}, 0)[0])


def test_the_mirror_flips_image_and_boxes_together():
    s, labels = _record()
    rng = Scripted(randoms=[0.3, 0.2], integers=[0], uniforms=[0.5])  # 0.2 < 0.5: mirrored
    image, boxes = random_window(s, labels, CFG, rng)
    want_img, want_boxes = _expected(s, labels, 17)  # start round(25 - 8): the box (traces 20-30) wholly inside
    np.testing.assert_array_equal(image, want_img[:, :, ::-1])
    assert len(want_boxes) == 1 and 0 < want_boxes[0, 0] < want_boxes[0, 2] < 16
    np.testing.assert_allclose(boxes, np.stack([16 - want_boxes[:, 2], want_boxes[:, 1], 16 - want_boxes[:, 0],
                                                want_boxes[:, 3]], axis=1), rtol=0, atol=0)
    assert image.flags["C_CONTIGUOUS"]
    rng = Scripted(randoms=[0.3, 0.2], integers=[0], uniforms=[0.5])
    image, _ = random_window(s, labels, CFG, rng, flip=False)  # no flip: no draw for it either
    np.testing.assert_array_equal(image, want_img)
    assert len(rng.calls) == 3


def test_an_empty_window_keeps_a_4_column_box_array_when_mirrored():
    s, _ = _record()
    image, boxes = random_window(s, {"labels": []}, CFG, Scripted(randoms=[0.1], integers=[3]))
    assert boxes.shape == (0, 4) and boxes.dtype == np.float32


def test_the_window_dataset_gives_item_i_the_same_window_every_time():
    torch = pytest.importorskip("torch")
    from gpr3d.detection.data import WindowDataset

    s, labels = _record()
    ds = WindowDataset(lambda i: (s, labels), 5, CFG, seed=3)
    assert len(ds) == 5 and ds.cfg is CFG
    a_img, a_t = ds[2]
    b_img, b_t = ds[2]
    assert torch.equal(a_img, b_img) and torch.equal(a_t["boxes"], b_t["boxes"])
    rng = np.random.default_rng(np.random.SeedSequence([3, 2, 77]))
    img, boxes = random_window(s, labels, CFG, rng)
    np.testing.assert_array_equal(a_img.numpy(), img)
    np.testing.assert_array_equal(a_t["boxes"].numpy(), boxes)
    assert a_t["labels"].dtype == torch.int64 and a_t["labels"].tolist() == [1] * len(boxes)
    other = WindowDataset(lambda i: (s, labels), 5, CFG, seed=4)
    assert any(not torch.equal(ds[i][0], other[i][0]) for i in range(5))  # the seed moves the windows
    assert WindowDataset(lambda i: (s, labels), 2).cfg == WindowConfig()
    assert collate([(1, "a"), (2, "b")]) == ([1, 2], ["a", "b"])


def test_records_source_cycles_and_refuses_nothing_to_learn():
    recs = [("s0", {"labels": [{"box": [0, 0, 1, 1]}]}), ("s1", {"labels": []}),
            ("s2", {"labels": [{"box": [0, 0, 1, 1]}, {"box": [1, 1, 2, 2]}]})]
    src = RecordsSource(iter(recs))  # any iterable
    assert src.n_boxes == 3 and [src(i)[0] for i in range(7)] == ["s0", "s1", "s2", "s0", "s1", "s2", "s0"]
    with pytest.raises(GPR3DError, match="^no labelled records to train on$"):
        RecordsSource([])
    with pytest.raises(GPR3DError, match="^the labelled records hold no boxes: nothing to learn from$"):
        RecordsSource([("s", {"labels": []})])


def test_mixed_source_by_its_seeded_draw():
    src = MixedSource(lambda i: ("first", i), lambda i: ("second", i), 0.3)
    for i in range(50):
        u = np.random.default_rng(np.random.SeedSequence([i, 0x313])).random()
        assert src(i) == (("second", i) if u < 0.3 else ("first", i))
    assert all(MixedSource(lambda i: 1, lambda i: 2, 0.0)(i) == 1 for i in range(20))
    assert all(MixedSource(lambda i: 1, lambda i: 2, 1.0)(i) == 2 for i in range(20))


def test_packed_source_holdouts_by_file(tmp_path):
    from tests.io.test_packed import write_packed

    from gpr3d.io.packed import PackedDataset

    p = tmp_path / "p.h5"
    write_packed(p)  # three records
    ds = PackedDataset(p)
    src = PackedSource([f"{p}:1", str(p)], holdout=0)
    assert src.n == 2 + 3
    for i, k in enumerate([0, 1, 0, 1, 2, 0, 1]):
        assert src(i)[1] == ds[k][1]
    assert PackedSource(p, holdout=1).n == 2 and PackedSource(str(p)).n == 3  # a path, a string
    with pytest.raises(GPR3DError, match=r"p.h5: 3 records; none left after holding out 3$"):
        PackedSource(str(p), holdout=3)
    with pytest.raises(GPR3DError, match="none left after holding out 5"):
        PackedSource([str(p), f"{p}:5"])


def test_a_flip_draw_of_exactly_one_half_does_not_mirror():
    s, labels = _record()
    image, _ = random_window(s, labels, CFG, Scripted(randoms=[0.3, 0.5], integers=[0], uniforms=[0.5]))
    np.testing.assert_array_equal(image, _expected(s, labels, 17)[0])


def test_the_dataset_s_defaults_and_its_flip_switch():
    pytest.importorskip("torch")
    from gpr3d.detection.data import WindowDataset

    s, labels = _record()
    seen = []

    def source(i):
        seen.append(i)
        return s, labels

    ds = WindowDataset(source, 40, CFG)
    assert ds.seed == 0 and ds.flip is True
    ds[np.int64(3)]
    assert seen == [3] and type(seen[0]) is int
    # item i: the generator of (seed, i, 77); with flip=False the same draws but no mirror
    plain = WindowDataset(source, 40, CFG, flip=False)
    flipped = [i for i in range(40) if not np.array_equal(ds[i][0].numpy(), plain[i][0].numpy())]
    assert 5 < len(flipped) < 35  # about half mirrored


def test_packed_source_names_with_colons_and_a_holdout_of_all_but_one(tmp_path):
    from tests.io.test_packed import write_packed

    d = tmp_path / "a:b"
    d.mkdir()
    p = d / "p.h5"
    write_packed(p)
    assert PackedSource(str(p)).n == 3  # the colon in the folder is not a hold-out
    assert PackedSource(f"{p}:2").n == 1  # one left is enough
    with pytest.raises(GPR3DError, match=r"p.h5: 3 records; none left after holding out 3$"):
        PackedSource(f"{p}:3")
    with pytest.raises(Exception):
        PackedSource(f"{p}:x")  # not a count: the whole name is a path, which does not exist


def test_mixed_source_at_its_fraction_exactly():
    i = 0
    u = np.random.default_rng(np.random.SeedSequence([i, 0x313])).random()
    assert MixedSource(lambda k: "first", lambda k: "second", u)(i) == "first"  # u < fraction: strictly


def test_nested_mixes_with_their_own_salt_draw_apart_and_the_default_draw_stays():
    # the draw of the default salt is the one every stored training run made: (i, 0x313)
    for i in range(30):
        u = np.random.default_rng(np.random.SeedSequence([i, 0x313])).random()
        assert MixedSource(lambda k: "a", lambda k: "b", 0.5)(i) == ("b" if u < 0.5 else "a")
    inner_own = MixedSource(lambda k: "synthetic", lambda k: "packed", 0.5, salt=0x314)
    outer = MixedSource(lambda k: "synthetic", lambda k: "real", 0.75)
    # the fault a shared salt made: the inner mix saw only indices with the outer draw u >= 0.75, never u < 0.5
    same = [outer(i) if outer(i) == "real" else MixedSource(lambda k: "synthetic", lambda k: "packed", 0.5)(i)
            for i in range(4000)]
    own = [MixedSource(inner_own, lambda k: "real", 0.75)(i) for i in range(4000)]
    assert same.count("packed") == 0
    assert abs(own.count("real") / 4000 - 0.75) < 0.03 and abs(own.count("packed") / 4000 - 0.125) < 0.02


def test_a_nested_mix_with_the_outer_salt_is_refused():
    inner = MixedSource(lambda k: "synthetic", lambda k: "packed", 0.5)
    with pytest.raises(ValueError) as err:
        MixedSource(inner, lambda k: "real", 0.75)
    assert str(err.value) == ("a mix nested in another needs a salt of its own (both 0x313): it would never pick its "
                              "second source")
    with pytest.raises(ValueError, match="both 0x7"):  # the clash beside another nested mix
        MixedSource(MixedSource(lambda k: 0, lambda k: 1, 0.5, salt=7), MixedSource(lambda k: 2, lambda k: 3, 0.5, salt=9),
                    0.5, salt=7)
    with pytest.raises(ValueError, match="a salt of its own"):  # however deep, on either side
        MixedSource(lambda k: "real", MixedSource(lambda k: 0, MixedSource(lambda k: 1, lambda k: 2, 0.5, salt=7),
                                                 0.5, salt=9), 0.5, salt=7)
    MixedSource(MixedSource(lambda k: 0, lambda k: 1, 0.5, salt=9), lambda k: 2, 0.5)  # salts apart: fine
