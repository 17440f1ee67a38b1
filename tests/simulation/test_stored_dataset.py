"""The gprMax dataset stored in the repository (datasets/gprmax400.h5)."""

import json
from pathlib import Path

import numpy as np
import pytest

from gpr3d.simulation.labels import label_scene
from gpr3d.simulation.packed import PackedDataset
from gpr3d.simulation.sampler import sample_scene

PACK = Path(__file__).resolve().parents[2] / "datasets" / "gprmax400.h5"


@pytest.fixture(scope="module")
def ds():
    if not PACK.exists():
        pytest.skip("datasets/gprmax400.h5 not present")
    return PackedDataset(PACK)


def test_it_holds_400_gprmax_samples_with_their_manifest(ds):
    assert len(ds) == 400 and list(ds.index) == list(range(400))
    assert ds.manifest["n_samples"] == 400 and ds.config["config"]["engine"] == "gprmax"
    assert "gpr3d simulate --engine gprmax --n 400 --seed 0" in ds.regenerate
    assert ds.shape[1:] == (32, 512)


@pytest.mark.parametrize("i", [0, 57, 123, 399])
def test_samples_are_the_sampler_scenes_with_consistent_labels(ds, i):
    s, lab = ds[i]
    assert np.all(np.isfinite(s.data)) and np.abs(s.data).max() > 0
    stored = ds.scene(i)
    fresh = sample_scene(0, i)
    for key in ("medium", "targets", "stones"):  # the runner only snaps steps to the grid
        assert json.loads(stored.to_json())[key] == json.loads(fresh.to_json())[key]
    # labels follow from the scene: recompute them on the original time axis
    again = label_scene(stored, lab["n_samples"], lab["dt_s"])
    assert [round(a["apex_time_s"], 15) for a in again] == [round(b["apex_time_s"], 15) for b in lab["labels"]]
    assert lab["simulation"]["gprmax_version"] == "4.0.1"
