"""Antenna poses for a recording: an IMU, visual odometry (camera poses, or RGB-D frames registered here) and a
survey wheel fused by the error-state EKF, with loops closed where RGB-D frames revisit a place."""

from __future__ import annotations

from dataclasses import dataclass

from gpr3d.core.errors import GPR3DError

__all__ = ["FusedPoses", "fuse_recordings", "poses_at_traces", "write_rig_recordings"]


@dataclass
class FusedPoses:
    """What :func:`fuse_recordings` gives back.

    Attributes
    ----------
    result : FusionResult
        The filter's :class:`~gpr3d.pose.eskf.FusionResult` (frames, covariances, counts).
    trajectory : Trajectory
        The antenna's :class:`~gpr3d.core.trajectory.Trajectory`.
    source : str
        The IMU file or bag it came from.
    """

    result: object  #: the filter's :class:`~gpr3d.pose.eskf.FusionResult` (frames, covariances, counts)
    trajectory: object  #: the antenna's :class:`~gpr3d.core.trajectory.Trajectory`
    source: str  #: the IMU file or bag it came from


def fuse_recordings(*, imu=None, bag=None, odometry=None, wheel=None, rig=None, imu_topic=None, odometry_topic=None,
                    colour_topic=None, depth_topic=None, camera_info_topic=None, keyframe_m: float = 0.1,
                    odometry_sigma=(0.03, 0.01, 0.0005), still_s: float = 1.0, flat_ground_m: float | None = None,
                    smooth: bool = False, estimate_offset: bool = False, loops: bool = False,
                    log=print) -> FusedPoses:
    """Fuse a cart's recordings into the antenna's trajectory.

    Parameters
    ----------
    imu : str or Path, optional
        IMU samples (CSV: t, ax, ay, az, gx, gy, gz in s, m/s^2, rad/s); or give ``bag``.
    bag : str or Path, optional
        A ROS 1 ``.bag`` or ROS 2 bag folder holding the IMU and the odometry (poses, or RGB-D frames).
    odometry : str or Path, optional
        Camera poses (TUM, EuRoC or CSV) beside ``imu``.
    wheel : str or Path, optional
        Survey-wheel distances (CSV: t, distance).
    rig : str or Path, optional
        The rig file (JSON: ``imu_T_camera``, ``imu_T_antenna``, ``camera_time_offset_s``).
    imu_topic, odometry_topic, colour_topic, depth_topic, camera_info_topic : str, optional
        The bag's topics (default: the only one of each kind).
    keyframe_m : float
        RGB-D odometry: distance between keyframes (0: frame to frame).
    odometry_sigma : (float, float, float)
        Camera-pose odometry's noise: rotation (deg), translation (fraction of the step), translation floor (m).
    still_s : float
        Seconds the cart stands at the start (the filter's initial alignment).
    flat_ground_m : float, optional
        Hold the IMU at its start height within this (m).
    smooth : bool
        Run the RTS smoother after the filter.
    estimate_offset : bool
        Estimate the camera-IMU time offset from the turns first.
    loops : bool
        Register revisited RGB-D frames and close the loops (needs ``colour_topic``, ``depth_topic``).
    log : callable
        Progress lines.

    Returns
    -------
    FusedPoses

    Raises
    ------
    GPR3DError
        Files that cannot be read, an offset beyond the search, an offset asked for without odometry.
    """
    from gpr3d.io.inertial import read_imu_csv, read_rig, read_wheel_csv, relative_from_camera_poses
    from gpr3d.io.trajectory import read_trajectory

    intr = None
    rig = read_rig(rig) if rig else {}
    vo = None
    source = imu or bag
    if bag:
        from gpr3d.io.rosbag import bag_topics, iter_bag_rgbd, read_bag_camera_info, read_bag_imu, read_bag_trajectory

        imu = read_bag_imu(bag, imu_topic)
        if colour_topic:
            from gpr3d.pose.vo import OdometryConfig, require_open3d, rgbd_odometry

            require_open3d()
            intr = read_bag_camera_info(bag, camera_info_topic)
            vo, rep = rgbd_odometry(iter_bag_rgbd(bag, colour_topic, depth_topic), intr,
                                    OdometryConfig(keyframe_m=keyframe_m))
            lost = ", ".join(f"{k} {v}" for k, v in rep["lost"].items()) or "none"
            log(f"RGB-D odometry: {rep['registered']} of {rep['frames'] - 1} frames registered to "
                f"{rep['keyframes']} keyframes (lost: {lost}), {rep['s_per_frame'] * 1e3:.0f} ms a frame")
        elif odometry_topic or any(m in ("geometry_msgs/msg/PoseStamped", "nav_msgs/msg/Odometry",
                                         "geometry_msgs/msg/PoseWithCovarianceStamped")
                                   for _, m, _ in bag_topics(bag)):
            vo = relative_from_camera_poses(read_bag_trajectory(bag, odometry_topic),
                                            rot_sigma_deg=odometry_sigma[0], trans_frac=odometry_sigma[1], trans_floor_m=odometry_sigma[2])
    else:
        imu = read_imu_csv(imu)
        if odometry:
            vo = relative_from_camera_poses(read_trajectory(odometry), rot_sigma_deg=odometry_sigma[0],
                                            trans_frac=odometry_sigma[1], trans_floor_m=odometry_sigma[2])
    wheel = read_wheel_csv(wheel) if wheel else None
    from gpr3d.pose.eskf import EskfConfig, fuse

    if estimate_offset:
        if vo is None:
            raise GPR3DError("--estimate-offset needs odometry (--odometry, or odometry in the bag)")
        from gpr3d.pose.sync import estimate_time_offset

        off = estimate_time_offset(imu, vo)
        if off["at_search_edge"]:
            raise GPR3DError(f"the camera-IMU offset lies beyond +-0.2 s (search edge {off['offset_s']:+.3f} s): "
                             "check the two clocks")
        log(f"camera-IMU time offset estimated: {off['offset_s'] * 1e3:+.1f} ms from {off['frames']} frames "
            f"({off['turn_deg']:.0f} deg of turns)" + (f"; the rig file says {rig['camera_time_offset_s'] * 1e3:+.1f} ms"
                                                          if "camera_time_offset_s" in rig else ""))
        rig["camera_time_offset_s"] = off["offset_s"]
    cfg = EskfConfig(init_still_s=still_s, flat_ground_sigma_m=flat_ground_m, **rig)
    res = fuse(imu, vo, cfg, wheel=wheel, smooth=smooth)
    if loops:
        import numpy as np

        from gpr3d.pose.graph import close_loops
        from gpr3d.pose.vo import loop_candidates, rgbd_loop_closures

        pairs = loop_candidates(res)
        # the fusion's frames are odometry's frames inside the IMU record: find each one's place in the bag
        vo_idx = np.searchsorted(vo.t_s + cfg.camera_time_offset_s, res.frame_t_s - 1e-9)
        need = {int(vo_idx[k]) for pair in pairs for k in pair}
        kept = {k: (c, d) for k, (_, c, d) in enumerate(iter_bag_rgbd(bag, colour_topic, depth_topic))
                if k in need}
        closures, lrep = rgbd_loop_closures(lambda k: kept[int(vo_idx[k])], res, intr, cfg.imu_T_camera,
                                            candidates=pairs)
        grep_ = {}
        res = close_loops(res, closures, report=grep_)
        log(f"loop closures: {lrep['closures']} registered of {lrep['candidates']} revisits; "
            f"{grep_.get('used', 0)} used, {grep_.get('gated', 0)} + {grep_.get('rejected', 0)} left out as wrong")
    return FusedPoses(result=res, trajectory=res.antenna_trajectory(), source=str(source))


def poses_at_traces(trajectory, survey, *, source: str = "the survey"):
    """A trajectory's poses at a recording's trace times: one pose per trace, in trace order (positions
    interpolated linearly, orientations by slerp), as ``gpr3d reconstruct --poses`` takes them.

    Parameters
    ----------
    trajectory : Trajectory
        Poses on the clock of the survey's trace times (the fused antenna trajectory).
    survey : Survey
        The recording whose ``timestamps_s`` the poses are wanted at.
    source : str
        The survey's name in a message.

    Returns
    -------
    Trajectory
        ``survey.n_traces`` poses at the trace times.

    Raises
    ------
    GPR3DError
        A survey without trace times, or traces outside the trajectory's time span.
    """
    from gpr3d.core.trajectory import Trajectory
    from gpr3d.io.trajectory import attach_poses

    if survey.timestamps_s is None:
        raise GPR3DError(f"{source}: its traces have no times to place the poses at")
    try:
        s = attach_poses(survey, trajectory, by="time")
    except GPR3DError as exc:
        raise GPR3DError(f"{source}: {exc}") from None
    return Trajectory(s.timestamps_s, s.positions_xyz, s.orientations_quat_wxyz)


def write_rig_recordings(run, folder) -> list:
    """Write what a cart's sensors recorded in a run of the synthetic rig, in the files :func:`fuse_recordings`
    (and ``gpr3d pose fuse``, ``gpr3d run --imu``) read: ``imu.csv``, ``odometry.tum`` (the camera's poses, the
    frames whose motion was lost left out), ``wheel.csv``, ``rig.json`` (mounts and camera latency) and
    ``truth.tum`` (the antenna's true poses, to compare).

    Parameters
    ----------
    run : RigRun
        What :func:`gpr3d.pose.rig.simulate_rig` gave back.
    folder : str or Path
        Where the files go (each written atomically; the folder is made where missing).

    Returns
    -------
    list of str
        The names of the files written.
    """
    from pathlib import Path

    from scipy.spatial.transform import Rotation

    from gpr3d.core.trajectory import Trajectory
    from gpr3d.io.inertial import write_imu_csv, write_rig, write_wheel_csv
    from gpr3d.io.trajectory import write_tum

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cfg = run.config
    keep = run.vo.valid.copy()  # frames whose motion from the one before is known; lost ones are left out
    keep[0] = True
    Rc, pc = run.vo.chained()
    cam = Trajectory(run.vo.t_s[keep], pc[keep], Rotation.from_matrix(Rc[keep]).as_quat()[:, [3, 0, 1, 2]])
    write_imu_csv(run.imu, folder / "imu.csv")
    write_tum(cam, folder / "odometry.tum")
    write_wheel_csv(*run.wheel(), folder / "wheel.csv")
    write_tum(run.truth_trajectory(), folder / "truth.tum")
    write_rig(folder / "rig.json", imu_T_camera=cfg.imu_T_camera, imu_T_antenna=cfg.imu_T_antenna,
              camera_time_offset_s=cfg.camera_time_offset_s)
    return ["imu.csv", "odometry.tum", "wheel.csv", "truth.tum", "rig.json"]
