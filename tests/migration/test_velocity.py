"""Migration velocity analysis: the eps_r that focuses a random-motion survey's 3D image is the true one, where a
hyperbola read along oblique crossings comes out low."""

import numpy as np
import pytest

from gpr3d.core.errors import InvalidDataError
from gpr3d.core.survey import Survey
from gpr3d.migration.velocity import focus_eps, image_entropy
from gpr3d.simulation.forward import ForwardScene, Pipe, forward_model
from gpr3d.simulation.paths import random_walk


@pytest.mark.parametrize("eps", [5.0, 12.0])
def test_focus_finds_the_host_permittivity_on_oblique_crossings(eps):
    scene = ForwardScene(eps_r=eps, pipes=[Pipe((0.1, 0.3, -0.35), (1.1, 0.9, -0.35), 0.03),
                                           Pipe((0.3, 1.1, -0.25), (1.0, 0.1, -0.25), 0.02)])
    traj = random_walk(1500, area=((0.0, 1.2), (0.0, 1.2)), step_m=0.01, seed=3)
    f, ns, win = 800e6, 256, 16e-9 * np.sqrt(eps / 5.0)
    data = forward_model(scene, traj.positions_xyz, traj.orientations_quat_wxyz, offset_m=0.05, frequency_hz=f,
                         n_samples=ns, time_window_s=win, air_wave=1.0, ground_wave=0.3)
    s = Survey(data=data, dt_s=win / ns, positions_xyz=traj.positions_xyz,
               orientations_quat_wxyz=traj.orientations_quat_wxyz, offset_m=0.05, frequency_hz=f)
    grid = np.linspace(np.sqrt(3.0), np.sqrt(20.0), 9) ** 2
    r = focus_eps(s, eps_grid=grid, spacing_m=0.03, max_depth_m=0.5)
    assert not r["at_edge"]
    assert r["eps_r"] == pytest.approx(eps, rel=0.12), r
    ent = np.array(r["entropy"])
    assert ent[np.argmin(np.abs(grid - eps))] < ent[0] and ent[np.argmin(np.abs(grid - eps))] < ent[-1]


def test_entropy_is_lower_for_a_focused_image_and_inputs_are_checked():
    sharp = np.zeros((20, 20))
    sharp[10, 10] = 1.0
    blurred = np.exp(-((np.arange(20)[:, None] - 10) ** 2 + (np.arange(20)[None] - 10) ** 2) / 20.0)
    assert image_entropy(sharp) == pytest.approx(0.0) and image_entropy(blurred) > 2.0
    with pytest.raises(InvalidDataError, match="three increasing"):
        focus_eps(None, eps_grid=[4.0, 9.0])
