"""The Theil-Sen fit that line targets take their depth from, against scipy.stats.theilslopes (its reference)."""

import numpy as np
import pytest
from scipy import stats

from gpr3d.migration.targets import theil_sen


@pytest.mark.parametrize("seed", range(5))
def test_theil_sen_equals_scipys_on_noisy_lines_with_ties_and_outliers(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 300))
    x = np.round(rng.uniform(0, 3, n), 2)  # 2 cm steps: ties in x, as columns along a line have
    y = 0.6 + 0.05 * x + rng.normal(0, 0.01, n)
    y[rng.uniform(size=n) < 0.2] -= 0.3  # a crossing target's columns, shallower
    want = stats.theilslopes(y, x)
    k, m = theil_sen(x, y)
    assert k == pytest.approx(want.slope, rel=1e-12, abs=1e-14)
    assert m == pytest.approx(want.intercept, rel=1e-12, abs=1e-14)


def test_theil_sen_by_hand_and_degenerate():
    # slopes between (0, 0), (1, 2), (2, 2): 2, 1, 0 -> median 1; intercept median(y) - 1 * median(x) = 2 - 1 = 1
    assert theil_sen([0.0, 1.0, 2.0], [0.0, 2.0, 2.0]) == (1.0, 1.0)
    with pytest.raises(ValueError, match="two points with different x"):
        theil_sen([1.0, 1.0], [0.0, 2.0])
