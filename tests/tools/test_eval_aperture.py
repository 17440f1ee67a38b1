"""benchmarks/eval_aperture.py: its radii in metres or in centre wavelengths in the host, and its one-line refusals
before any scene is simulated."""

import math
from types import SimpleNamespace

import pytest

from tests.tools._script import load_script, refusal


def test_radii_in_metres_and_in_wavelengths():
    mod = load_script("benchmarks/eval_aperture.py")
    assert mod.parse_radius("1m") == (1.0, "m") and mod.parse_radius("0.5m") == (0.5, "m")
    assert mod.parse_radius("5wl") == (5.0, "wl")
    for bad in ("1", "0m", "-2wl", "wl", "1 cm"):
        with pytest.raises(ValueError):
            mod.parse_radius(bad)
    # 500 MHz in eps_r 9: a wavelength of c / 3 / 5e8 = 0.19986 m
    s = SimpleNamespace(eps_r=9.0, frequency_hz=5e8)
    assert mod.radius_m(5.0, "wl", s) == pytest.approx(5 * 299792458.0 / math.sqrt(9.0) / 5e8, rel=1e-12)
    assert mod.radius_m(0.8, "m", s) == 0.8


@pytest.mark.parametrize("args, says", [
    (("--radii", "1"), "--radii positive numbers ending in 'm' or 'wl'"),
    (("--radii", "1m,0wl"), "--radii positive numbers ending in 'm' or 'wl'"),
    (("--seeds", "a-b"), "--seeds takes A-B or A,B,..."),
])
def test_a_wrong_setting_is_one_line_naming_it(args, says):
    assert says in refusal("eval_aperture.py", *args)
