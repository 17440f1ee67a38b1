"""Survey-wheel triggering and poses at trace times against hand cases."""

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.poses import quat_from_yaw, yaw_from_quat
from gpr3d.core.trajectory import Trajectory
from gpr3d.pose.rig import RigConfig, simulate_rig
from gpr3d.pose.sync import estimate_time_offset, trajectory_triggers, wheel_trigger_times


def test_wheel_fires_every_spacing_and_not_while_still():
    # 0.5 m/s for 4 s, still for 2 s, 0.25 m/s for 4 s
    t = np.linspace(0, 10, 10001)
    d = np.where(t < 4, 0.5 * t, np.where(t < 6, 2.0, 2.0 + 0.25 * (t - 6)))
    trig = wheel_trigger_times(t, d, 0.1)
    assert trig.size == 30  # 2 m + 1 m of travel
    assert np.allclose(trig[:20], 0.2 * np.arange(1, 21), atol=1e-6)  # 0.1 m / 0.5 m/s
    assert np.allclose(trig[20:], 6.0 + 0.4 * np.arange(1, 11), atol=1e-6)  # 0.1 m / 0.25 m/s after the stop
    assert not np.any((trig > 4.0 + 1e-9) & (trig < 6.0))
    with pytest.raises(InvalidDataError, match="decreases"):
        wheel_trigger_times(t, d.max() - d, 0.1)
    with pytest.raises(InvalidDataError, match="positive distance"):
        wheel_trigger_times(t, d, 0.0)


def test_poses_at_trace_times_interpolate_and_shift_by_latency():
    t = np.linspace(0.0, 10.0, 11)
    yaw = 0.1 * t  # turning at 0.1 rad/s while moving 1 m/s along x
    traj = Trajectory(t, np.c_[t, np.zeros_like(t), np.zeros_like(t)], quat_from_yaw(yaw))
    at = traj.at([2.5, 7.25])
    assert np.allclose(at.positions_xyz[:, 0], [2.5, 7.25]) and np.allclose(yaw_from_quat(at.orientations_quat_wxyz),
                                                                            [0.25, 0.725])
    late = traj.at([2.5], latency_s=0.5)  # the radar's clock half a second behind
    assert late.timestamps_s[0] == 2.5 and late.positions_xyz[0, 0] == pytest.approx(3.0)
    with pytest.raises(InvalidDataError, match="1 of 2 times fall outside"):
        traj.at([5.0, 10.5])
    assert np.allclose(traj.path_length_m(), t)


def test_rig_path_triggers_match_its_distance():
    run = simulate_rig(RigConfig(duration_s=30, area=((0, 3), (0, 3)), turn_rate_rad_s=1.0), seed=3)
    traj = run.truth_trajectory()
    trig = trajectory_triggers(traj, 0.02)
    s = np.interp(trig, traj.timestamps_s, traj.path_length_m())  # the antenna's path (its lever arm swings on turns)
    assert trig.size == int(traj.path_length_m()[-1] / 0.02 + 1e-9)
    assert np.allclose(np.diff(s), 0.02, atol=1e-6) and s[0] == pytest.approx(0.02)
    g = run.truth(run.imu.t_s)
    assert g["p"][:, 0].min() > -0.5 and g["p"][:, 0].max() < 3.5  # it stays over its patch


@pytest.mark.parametrize("offset", [0.023, -0.04])
def test_camera_imu_time_offset_is_found_from_the_turns(offset):
    """The rig's camera runs ``offset`` behind the IMU (with odometry's gross errors in the data): the offset
    comes back within 2 ms (a frame lasts 67 ms); a run with its sign flipped, or the angles compared a frame
    apart, would miss by tens of ms."""
    run = simulate_rig(RigConfig(duration_s=60, camera_time_offset_s=offset), seed=3)
    est = estimate_time_offset(run.imu, run.vo)
    assert abs(est["offset_s"] - offset) < 0.002 and not est["at_search_edge"]
    assert est["frames"] > 800 and est["turn_deg"] > 100


def test_time_offset_needs_overlapping_frames():
    run = simulate_rig(RigConfig(duration_s=20), seed=1)
    with pytest.raises(InvalidDataError, match="too few odometry frames"):
        estimate_time_offset(run.imu, run.vo, max_offset_s=10.5)
    with pytest.raises(InvalidDataError, match="positive"):
        estimate_time_offset(run.imu, run.vo, step_s=0.0)


def test_wheel_trigger_edges_and_messages_in_full():
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    d = np.array([0.0, 0.25, 0.25, 0.25, 0.75])  # still from 1 s to 3 s, then 0.5 m in a second
    # marks at 0.2, 0.4, 0.6 m: the two after the stop are timed from when the wheel moves on (3 s), not from
    # when it stopped
    np.testing.assert_allclose(wheel_trigger_times(t, d, 0.2), [0.8, 3.3, 3.7])
    np.testing.assert_allclose(wheel_trigger_times(t, d, 0.25), [1.0, 3.5, 4.0])
    # the stop: a mark at the stop's distance fires when the wheel gets there (1 s), not when it leaves (3 s)
    np.testing.assert_allclose(wheel_trigger_times(t, d, 0.125, start_m=0.0)[:2], [0.5, 1.0])
    np.testing.assert_allclose(wheel_trigger_times(t, d, 0.2, start_m=0.1), [3.1, 3.5, 3.9])  # 0.3, 0.5, 0.7 m
    # a record that begins 0.3 m along: the marks at 0.2 m and before were passed already; 0.4 m fires
    np.testing.assert_allclose(wheel_trigger_times(t, d + 0.3, 0.2), [0.4, 3.1, 3.5, 3.9])
    # a wheel count that jitters back by less than a nanometre is still forward
    assert wheel_trigger_times(t, d - np.r_[0, 0, 5e-10, 0, 0], 0.25).size == 3
    for args, words in [
        ((t, d[:4], 0.2), "times and distances must be two arrays of one length >= 2, got 5 and 4"),
        ((t[:1], d[:1], 0.2), "times and distances must be two arrays of one length >= 2, got 1 and 1"),
        ((t, np.r_[d[:4], np.nan], 0.2), "times or distances hold NaN/inf"),
        ((np.r_[t[:4], np.inf], d, 0.2), "times or distances hold NaN/inf"),
        ((np.r_[0.0, 1.0, 1.0, 3.0, 4.0], d, 0.2), "times must increase"),
        ((t, np.r_[d[:4], 0.2], 0.2), "distance decreases: pass the wheel's forward count (it must not go down)"),
        ((t, d, -0.1), "trace spacing must be a positive distance in metres, got -0.1"),
        ((t, d, float("nan")), "trace spacing must be a positive distance in metres, got nan"),
    ]:
        with pytest.raises(InvalidDataError, match="^" + words.replace("(", r"\(").replace(")", r"\)") + "$"):
            wheel_trigger_times(*args)
