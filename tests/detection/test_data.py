"""Training record sources: packed datasets with per-file hold-outs, mixed sources."""

import numpy as np
import pytest

from gpr3d.core.errors import GPR3DError


@pytest.fixture(scope="module")
def packed(tmp_path_factory):
    pytest.importorskip("distributed")
    from gpr3d.simulation.dataset import SimulateConfig, build_dataset
    from gpr3d.simulation.packed import pack_dataset

    d = tmp_path_factory.mktemp("packed")
    build_dataset(SimulateConfig(out=str(d / "ds"), n=3, engine="forward", workers=1), progress=False,
                  log=lambda *_: None)
    pack_dataset(d / "ds", d / "p.h5")
    return d / "p.h5"


def test_packed_source_concatenates_files_with_their_own_holdouts(packed):
    from gpr3d.detection.data import PackedSource
    from gpr3d.io.packed import PackedDataset

    ds = PackedDataset(packed)
    src = PackedSource([f"{packed}:1", f"{packed}:0"], holdout=60)  # the suffixes override the default 60
    assert src.n == 2 + 3
    want = [0, 1, 0, 1, 2, 0]  # file one keeps records 0-1, file two all three, then round again
    for i, k in enumerate(want):
        np.testing.assert_array_equal(src(i)[0].data, ds[k][0].data)
        assert src(i)[1] == ds[k][1]
    assert PackedSource(str(packed), holdout=2).n == 1
    with pytest.raises(GPR3DError, match="none left after holding out 3"):
        PackedSource(f"{packed}:3")


def test_mixed_source_draws_a_seeded_share():
    from gpr3d.detection.data import MixedSource

    src = MixedSource(lambda i: "first", lambda i: "second", 0.25)
    got = [src(i) for i in range(2000)]
    assert got == [src(i) for i in range(2000)]  # the same index always draws the same source
    assert 0.2 < got.count("second") / 2000 < 0.3
