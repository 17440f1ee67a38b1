"""One profile migrated in 2D: every method focuses point diffractors where they are (the synthetic B-scan's
travel times are exact, independent of the migration code)."""

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.migration.profile import migrate_profile
from gpr3d.simulation.synthetic import point_targets_bscan

TARGETS = [(0.4, 0.25), (0.8, 0.4)]


@pytest.fixture(scope="module")
def bscan():
    s = point_targets_bscan(TARGETS, eps_r=6.0, offset_m=0.0, direct_wave=0.0, n_traces=121, trace_step_m=0.01)
    return s.replace(t0_s=2e-9)


@pytest.mark.parametrize("method, tol_x, tol_z", [("kirchhoff", 0.02, 0.02), ("backprojection", 0.02, 0.02),
                                                  ("stolt", 0.02, 0.02), ("rtm", 0.03, 0.03)])
def test_each_method_focuses_the_diffractors_where_they_are(bscan, method, tol_x, tol_z):
    prof = migrate_profile(bscan, eps_r=6.0, method=method, max_depth_m=0.6)
    env = np.abs(prof.image)
    for x, z in TARGETS:
        near = (np.abs(prof.along_m - x) < 0.1)[:, None] & (np.abs(prof.depth_m - z) < 0.1)[None, :]
        i, k = np.unravel_index(int(np.argmax(np.where(near, env, 0))), env.shape)
        assert abs(prof.along_m[i] - x) <= tol_x and abs(prof.depth_m[k] - z) <= tol_z, (method, x, z, i, k)
    # focused: the peak stands far above the image's typical level
    assert env.max() > 10 * np.median(env)


def test_trace_spacing_stands_in_for_positions_and_bad_settings_are_refused(bscan):
    bare = bscan.replace(positions_xyz=None, orientations_quat_wxyz=None)
    with pytest.raises(InvalidDataError, match="give the trace spacing"):
        migrate_profile(bare, eps_r=6.0)
    a = migrate_profile(bare, eps_r=6.0, trace_spacing_m=0.01, max_depth_m=0.6)
    b = migrate_profile(bscan, eps_r=6.0, max_depth_m=0.6)
    np.testing.assert_allclose(a.image, b.image, atol=1e-5 * np.abs(b.image).max())
    with pytest.raises(InvalidDataError, match="method must be one of"):
        migrate_profile(bscan, eps_r=6.0, method="phase-shift")
    with pytest.raises(InvalidDataError, match="eps_r must be"):
        migrate_profile(bscan, eps_r=0.5)
