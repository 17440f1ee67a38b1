"""Antenna poses for random-motion surveys: IMU and visual odometry fused by an error-state EKF.

* :mod:`gpr3d.pose.imu` - IMU samples, noise figures and SE(3)/SO(3) helpers;
* :mod:`gpr3d.pose.rig` - a synthetic cart rig (random motion with turns and stops, IMU, visual
  odometry with noise, outliers and gaps, exact truth) to test and measure the filter;
* :mod:`gpr3d.pose.eskf` - the 15-state error-state EKF with stochastic cloning for relative
  visual-odometry poses, zero-velocity updates, gravity alignment and outlier gating, and its RTS smoother;
* :mod:`gpr3d.pose.render` - RGB-D frames of a textured site with boxes, rendered from any camera pose;
* :mod:`gpr3d.pose.vo` - Open3D RGB-D odometry with failure reasons and a calibrated covariance, and loop
  closures from revisited frames (Open3D is an optional extra);
* :mod:`gpr3d.pose.graph` - a robust planar pose graph that closes loops on a fused trajectory;
* :mod:`gpr3d.pose.metrics` - APE / RPE through evo, and NEES;
* :mod:`gpr3d.pose.sync` - survey-wheel trace times, the camera-IMU time offset from the data; poses at
  trace times come from
  :meth:`gpr3d.core.trajectory.Trajectory.at` (linear / SLERP, with the radar's latency).

Depends on :mod:`gpr3d.core` only (the :class:`~gpr3d.core.trajectory.Trajectory` type lives there).
"""

from gpr3d.pose.eskf import EskfConfig, FusionResult, fuse
from gpr3d.pose.imu import ImuNoise, ImuSamples, RelativePoses

__all__ = ["EskfConfig", "FusionResult", "fuse", "ImuNoise", "ImuSamples", "RelativePoses"]
