"""Trajectory errors through evo (APE and RPE after SE(3) alignment) and the filter's consistency (NEES)."""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from gpr3d.core.deps import require
from gpr3d.core.errors import InvalidDataError
from gpr3d.core.trajectory import Trajectory
from gpr3d.pose.imu import so3_log

__all__ = ["ape", "rpe", "nees", "nees_bounds", "aligned_positions"]


def _evo_traj(traj: Trajectory):
    require("evo")
    from evo.core import trajectory as tr

    return tr.PoseTrajectory3D(positions_xyz=np.asarray(traj.positions_xyz, float),
                               orientations_quat_wxyz=np.asarray(traj.orientations_quat_wxyz, float),
                               timestamps=np.asarray(traj.timestamps_s, float))


def _pair(est: Trajectory, ref: Trajectory, align: bool):
    require("evo")
    from evo.core import sync

    try:
        r, e = sync.associate_trajectories(_evo_traj(ref), _evo_traj(est), max_diff=1e-3)
    except sync.SyncException:
        raise InvalidDataError("the two trajectories share no timestamps (within 1 ms): are they on one clock?") from None
    if align:
        e.align(r, correct_scale=False)
    return r, e


def ape(est: Trajectory, ref: Trajectory, *, align: bool = True) -> dict:
    """Absolute position error of ``est`` against ``ref`` (matched by time), after an SE(3) alignment (Umeyama).

    Returns ``rmse``, ``mean``, ``max`` (m) and ``n`` poses.
    """
    require("evo")
    from evo.core import metrics

    r, e = _pair(est, ref, align)
    m = metrics.APE(metrics.PoseRelation.translation_part)
    m.process_data((r, e))
    st = m.get_all_statistics()
    return {"rmse": float(st["rmse"]), "mean": float(st["mean"]), "max": float(st["max"]), "n": int(r.num_poses)}


def aligned_positions(est: Trajectory, ref: Trajectory) -> np.ndarray:
    """``est``'s positions at the poses matched with ``ref``, after the SE(3) alignment of :func:`ape` (to plot)."""
    _, e = _pair(est, ref, True)
    return np.asarray(e.positions_xyz)


def rpe(est: Trajectory, ref: Trajectory, *, delta_m: float = 1.0) -> dict:
    """Relative position error over ``delta_m`` metres of path (evo's RPE; drift, free of any alignment)."""
    require("evo")
    from evo.core import metrics, units

    r, e = _pair(est, ref, False)
    m = metrics.RPE(metrics.PoseRelation.translation_part, delta=delta_m, delta_unit=units.Unit.meters,
                    all_pairs=False)
    m.process_data((r, e))
    st = m.get_all_statistics()
    return {"rmse": float(st["rmse"]), "mean": float(st["mean"]), "max": float(st["max"]), "delta_m": delta_m}


def nees(R_est, p_est, cov, R_true, p_true) -> np.ndarray:
    """Normalised estimation error squared of poses: ``e^T P^-1 e`` with ``e = (Log(R_est^T R_true), p_true - p_est)``.

    ``cov`` (n, 6, 6) in that order (rotation first, right perturbation); a consistent filter's NEES
    follows a chi-square distribution with 6 degrees of freedom.
    """
    R_est, R_true = np.asarray(R_est), np.asarray(R_true)
    out = np.empty(len(R_est))
    for k in range(len(R_est)):
        e = np.concatenate([so3_log(R_est[k].T @ R_true[k]), np.asarray(p_true[k]) - np.asarray(p_est[k])])
        out[k] = e @ np.linalg.solve(cov[k], e)
    return out


def nees_bounds(n_runs: int, dof: int = 6, prob: float = 0.95) -> tuple[float, float]:
    """Two-sided ``prob`` bounds of the NEES averaged over ``n_runs`` independent runs."""
    lo, hi = chi2.ppf([(1 - prob) / 2, (1 + prob) / 2], dof * n_runs)
    return float(lo / n_runs), float(hi / n_runs)
