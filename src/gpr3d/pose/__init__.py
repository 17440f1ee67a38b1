"""Antenna poses for random-motion surveys: IMU and visual odometry fused by an error-state EKF.

* :mod:`gpr3d.pose.imu` - IMU samples, noise figures and SE(3)/SO(3) helpers;
* :mod:`gpr3d.pose.rig` - a synthetic cart rig (random motion with turns and stops, IMU, visual
  odometry with noise, outliers and gaps, exact truth) to test and measure the filter;
* :mod:`gpr3d.pose.eskf` - the 15-state error-state EKF with stochastic cloning for relative
  visual-odometry poses, zero-velocity updates, gravity alignment and outlier gating;
* :mod:`gpr3d.pose.metrics` - APE / RPE through evo, and NEES;
* :mod:`gpr3d.pose.sync` - survey-wheel trace times; poses at trace times come from
  :meth:`gpr3d.core.trajectory.Trajectory.at` (linear / SLERP, with the radar's latency).

Depends on :mod:`gpr3d.core` only (the :class:`~gpr3d.core.trajectory.Trajectory` type lives there).
"""

from gpr3d.pose.eskf import EskfConfig, FusionResult, fuse
from gpr3d.pose.imu import ImuNoise, ImuSamples, RelativePoses

__all__ = ["EskfConfig", "FusionResult", "fuse", "ImuNoise", "ImuSamples", "RelativePoses"]
