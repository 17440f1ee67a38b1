"""IMU samples and odometry's relative poses: checks on input, and chaining motions against keyframes."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.inertial import RelativePoses


def _poses(n, seed=0):
    rng = np.random.default_rng(seed)
    R = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.05, (n, 3)), 0)).as_matrix()
    p = np.cumsum(rng.normal(0, 0.03, (n, 3)), 0)
    return R, p


def _relative(R, p, ref):
    n = len(p)
    Rr, pr = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3))
    for k in range(1, n):
        j = ref[k]
        Rr[k] = R[j].T @ R[k]
        pr[k] = R[j].T @ (p[k] - p[j])
    return Rr, pr


def test_chained_motions_from_keyframes_rebuild_the_poses():
    """Motions each taken from a keyframe (switching every third frame) chain back to the absolute poses (relative
    to the first), where reading them as frame-to-frame motions would not."""
    n = 12
    R, p = _poses(n)
    ref = np.array([-1, 0, 0, 0, 3, 3, 3, 6, 6, 6, 9, 9])
    Rr, pr = _relative(R, p, ref)
    vo = RelativePoses(np.arange(n) / 15, Rr, pr, np.tile(np.eye(6) * 1e-6, (n, 1, 1)), None, ref)
    assert vo.keyframes
    Rc, pc = vo.chained()
    want_p = np.einsum("ji,nj->ni", R[0], p - p[0])
    np.testing.assert_allclose(pc, want_p, atol=1e-12)
    np.testing.assert_allclose(Rc, np.einsum("ji,njk->nik", R[0], R), atol=1e-12)
    Rf, pf = RelativePoses(np.arange(n) / 15, Rr, pr, np.tile(np.eye(6) * 1e-6, (n, 1, 1))).chained()
    assert not RelativePoses(np.arange(n) / 15, Rr, pr, np.tile(np.eye(6), (n, 1, 1))).keyframes
    assert np.abs(pf - want_p).max() > 0.01


def test_a_failed_frame_holds_the_pose_and_the_next_keyframe_restarts_from_it():
    n = 6
    R, p = _poses(n, seed=1)
    ref = np.array([-1, 0, 1, 2, 2, 4])
    Rr, pr = _relative(R, p, ref)
    valid = np.array([False, True, True, False, True, True])
    _, pc = RelativePoses(np.arange(n) / 15, Rr, pr, np.tile(np.eye(6), (n, 1, 1)), valid, ref).chained()
    rel = np.einsum("ji,nj->ni", R[0], p - p[0])
    np.testing.assert_allclose(pc[3], pc[2])  # frame 3 lost: the pose of frame 2 held
    np.testing.assert_allclose(pc[4], rel[4], atol=1e-12)  # frame 4 is measured from keyframe 2, still known
    np.testing.assert_allclose(pc[:3], rel[:3], atol=1e-12)


@pytest.mark.parametrize("ref, msg", [
    ([-1, 0, 0, 1, 3], "frame 3 refers to frame 1"),  # neither the previous frame nor its reference
    ([-1, 0, 2, 2, 3], "frame 2 refers to frame 2"),  # itself
    ([-1, 0, 1, 2], "expected 5 whole frame indices"),
    ([-1, 0, 0.5, 1, 3], "whole frame indices"),
])
def test_bad_keyframe_references_give_one_line(ref, msg):
    n = 5
    with pytest.raises(InvalidDataError, match=msg):
        RelativePoses(np.arange(n) / 15, np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3)),
                      np.tile(np.eye(6), (n, 1, 1)), None, ref)
