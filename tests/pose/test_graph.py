"""Loop closures on the fused trajectory: drift measured by revisits is taken out, wrong closures are not obeyed."""

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.pose.eskf import fuse
from gpr3d.pose.graph import GraphConfig, LoopClosure, close_loops, revisits
from gpr3d.pose.metrics import ape
from gpr3d.pose.rig import RigConfig, simulate_rig


@pytest.fixture(scope="module")
def patch_run():
    """A cart wandering over a 3 m x 3 m patch for 120 s: it crosses its own path many times."""
    rig = RigConfig(duration_s=120, area=((0.0, 3.0), (0.0, 3.0)), turn_rate_rad_s=1.0, stops=2,
                    vo_trans_frac=0.03, vo_trans_floor_m=1e-3)  # a noisier odometry: more drift to take out
    run = simulate_rig(rig, seed=5)
    res = fuse(run.imu, run.vo, run.filter_config(flat_ground_sigma_m=0.01), smooth=True)
    return run, res


GCFG = GraphConfig(trans_frac=0.03, trans_floor_m=1e-3)  # the rig's odometry noise, as a user sets it


def test_loop_closures_take_out_the_drift(patch_run):
    run, res = patch_run
    truth = run.truth_trajectory()
    closures = run.loop_closures(res.frame_t_s)
    assert len(closures) > 20
    before = ape(res.antenna_trajectory(), truth)["rmse"]
    closed = close_loops(res, closures, GCFG)
    after = ape(closed.antenna_trajectory(), truth)["rmse"]
    assert after < 0.6 * before, (before, after)
    # roll, pitch and height are left as the fusion had them; the start stays where it was
    assert np.allclose(closed.p[:, 2], res.p[:, 2]) and np.allclose(closed.p[0], res.p[0], atol=1e-6)
    tilt = lambda R: R[:, 2, :]  # noqa: E731  the body axes' vertical components: unchanged by a turn about z
    assert np.allclose(tilt(closed.R), tilt(res.R), atol=1e-9)
    assert np.allclose(np.linalg.norm(closed.v, axis=1), np.linalg.norm(res.v, axis=1))


def test_wrong_closures_are_not_obeyed(patch_run):
    """A fifth of the closures off by 0.2-1 m and 5-20 deg: they are found (gated against the drift the odometry
    can explain, or left past 5 sigmas by the solution) and the result is as good as without them."""
    run, res = patch_run
    truth = run.truth_trajectory()
    good = close_loops(res, run.loop_closures(res.frame_t_s), GCFG)
    mixed = run.loop_closures(res.frame_t_s, outlier_rate=0.2, seed=1)
    g = run.truth(res.frame_t_s)
    wrong = sum(np.linalg.norm(c.p - g["R"][c.i].T @ (g["p"][c.j] - g["p"][c.i])) > 0.1 for c in mixed)
    assert wrong >= 5
    report = {}
    bad = close_loops(res, mixed, GCFG, report=report)
    assert report["gated"] + report["rejected"] >= wrong and report["used"] >= 0.9 * (len(mixed) - wrong)
    a0 = ape(res.antenna_trajectory(), truth)["rmse"]
    a_good, a_bad = ape(good.antenna_trajectory(), truth)["rmse"], ape(bad.antenna_trajectory(), truth)["rmse"]
    assert a_bad < 0.6 * a0 and a_bad < 1.3 * a_good, (a0, a_good, a_bad)


def test_no_closures_change_nothing_and_bad_ones_give_one_line(patch_run):
    run, res = patch_run
    assert close_loops(res, []) is res
    with pytest.raises(InvalidDataError, match="outside"):
        close_loops(res, [LoopClosure(0, res.frame_p.shape[0] + 5, np.eye(3), np.zeros(3))])
    with pytest.raises(InvalidDataError, match="keyframe_every"):
        GraphConfig(keyframe_every=0)
    with pytest.raises(InvalidDataError, match="radius_m"):
        revisits(res.frame_t_s, res.frame_p, res.frame_R, radius_m=-1.0)
