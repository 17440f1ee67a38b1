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
    # a mark on the first sample's distance was passed already too; two samples make a record
    np.testing.assert_allclose(wheel_trigger_times(t, d + 0.2, 0.2), [0.8, 3.3, 3.7])
    np.testing.assert_allclose(wheel_trigger_times([0.0, 2.0], [0.0, 1.0], 0.25), [0.5, 1.0, 1.5, 2.0])
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


def test_time_offset_to_a_fraction_of_its_grid_step_with_a_gyro_bias():
    """Built by hand: the camera turns in bursts about z (sin^2 pulses, still in between), the gyro reads the rate
    plus a bias of 0.02 rad/s, and the camera's clock runs 3.37 ms behind the IMU's (not on the 0.5 ms search grid).
    The bias comes from the still frames, the offset to 0.1 ms from the parabola through the cost's three grid
    points round its minimum; a clean run has no edge, its frames all kept, its turn in degrees."""
    from types import SimpleNamespace

    from gpr3d.pose.imu import so3_exp

    t_imu = np.arange(0.0, 40.0, 0.002)

    def rate(t):  # 1.5 s of turning (a sin^2 pulse of 1.2 rad/s peak), then 1.5 s still
        ph = np.mod(t, 3.0)
        return np.where(ph < 1.5, 1.2 * np.sin(np.pi * ph / 1.5) ** 2, 0.0)

    def angle(t):  # its integral
        ph = np.mod(t, 3.0)
        full = 1.2 * 0.75
        inside = np.where(ph < 1.5, 1.2 * (ph / 2 - 1.5 / (4 * np.pi) * np.sin(2 * np.pi * ph / 1.5)), full)
        return np.floor(t / 3.0) * full + inside

    offset = 0.00337
    gyro = np.c_[np.zeros_like(t_imu), np.zeros_like(t_imu), rate(t_imu) + 0.02]
    imu = SimpleNamespace(t_s=t_imu, gyro=gyro)
    t_cam = np.arange(0.5, 39.5, 1 / 15)
    # frame k's camera stamp is t_cam[k]; the IMU time of that frame is t_cam[k] + offset
    R = np.stack([np.eye(3)] + [so3_exp([0.0, 0.0, angle(t_cam[k] + offset) - angle(t_cam[k - 1] + offset)])
                                for k in range(1, t_cam.size)])
    vo = SimpleNamespace(t_s=t_cam, R=R, valid=np.r_[False, np.ones(t_cam.size - 1, bool)])
    est = estimate_time_offset(imu, vo)
    assert est["offset_s"] == pytest.approx(offset, abs=1e-4)
    assert not est["at_search_edge"] and est["frames"] == t_cam.size - 1
    assert est["turn_deg"] == pytest.approx(np.degrees(angle(t_cam[-1] + offset) - angle(t_cam[0] + offset)), rel=1e-3)
    assert est["sharpness"] > 1.0
    # searched no further than asked: an offset beyond max_offset_s lands on the grid's edge
    far = estimate_time_offset(imu, vo, max_offset_s=0.002, step_s=0.0005)
    assert far["at_search_edge"] and far["offset_s"] == pytest.approx(0.002, abs=1e-9)


def _bursts(t_cam, t_imu, offset, *, bias=0.02, period=0.5, turning=0.35, peak=2.0):
    """IMU and odometry of a camera turning about z in sin^2 bursts (``turning`` s of each ``period``, still the
    rest), the gyro reading the rate plus ``bias``; the camera's clock ``offset`` behind the IMU's."""
    from types import SimpleNamespace

    from gpr3d.pose.imu import so3_exp

    def angle(t):
        ph = np.mod(t, period)
        inside = np.where(ph < turning, peak * (ph / 2 - turning / (4 * np.pi) * np.sin(2 * np.pi * ph / turning)),
                          peak * turning / 2)
        return np.floor(t / period) * peak * turning / 2 + inside

    ph = np.mod(t_imu, period)
    rate = np.where(ph < turning, peak * np.sin(np.pi * ph / turning) ** 2, 0.0)
    imu = SimpleNamespace(t_s=t_imu, gyro=np.c_[0 * t_imu, 0 * t_imu, rate + bias])
    R = np.stack([np.eye(3)] + [so3_exp([0.0, 0.0, angle(t_cam[k] + offset) - angle(t_cam[k - 1] + offset)])
                                for k in range(1, t_cam.size)])
    return imu, SimpleNamespace(t_s=t_cam, R=R, valid=np.r_[False, np.ones(t_cam.size - 1, bool)])


def test_time_offset_frames_are_those_whose_interval_the_search_keeps_on_the_imu_record():
    """Binary-exact times: IMU 0 .. 2 s, frames every 1/16 s from 0, a search of +-1/8 s. Frame k (k >= 1) spans
    stamps (k - 1) / 16 .. k / 16 and is used when both ends, moved by up to 1/8 s, stay on the IMU record:
    k = 3 .. 30, 28 frames, the ends included. The camera turns 70 % of the time, so the gyro bias can only come
    from the still frames."""
    t_imu = np.arange(2049) / 1024
    imu, vo = _bursts(np.arange(32) / 16, t_imu, 0.0041)
    est = estimate_time_offset(imu, vo, max_offset_s=0.125, step_s=1 / 1024)
    assert est["frames"] == 28 and est["offset_s"] == pytest.approx(0.0041, abs=2e-4)
    imu, vo = _bursts(np.arange(13) / 16, t_imu, 0.0041)  # frames 3 .. 12: ten, enough
    assert estimate_time_offset(imu, vo, max_offset_s=0.125, step_s=1 / 1024)["frames"] == 10
    imu, vo = _bursts(np.arange(12) / 16, t_imu, 0.0041)
    with pytest.raises(InvalidDataError) as err:
        estimate_time_offset(imu, vo, max_offset_s=0.125, step_s=1 / 1024)
    assert str(err.value) == "too few odometry frames (9) overlap the IMU record to estimate an offset"
    with pytest.raises(InvalidDataError) as err:
        estimate_time_offset(imu, vo, max_offset_s=0.125, step_s=0.125)
    assert str(err.value) == "max_offset_s and step_s must be positive, step_s the smaller; got 0.125, 0.125"
