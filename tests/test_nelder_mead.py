"""gnssacc.prepare.nelder_mead against scipy's Nelder-Mead: the same points asked for in the same
order (so the same best point), whatever is told ahead."""

import numpy as np
import pytest
from scipy.optimize import minimize

from gnssacc.prepare.nelder_mead import nelder_mead


def _rosen(x):
    return float(np.sum(100.0 * (x[1:] - x[:-1] ** 2) ** 2 + (1.0 - x[:-1]) ** 2))


def _bumpy(x):
    return float(np.sum(x**2) + 0.3 * np.sum(np.cos(5.0 * x)) + (1e300 if x[0] > 1.7 else 0.0))


def _quad_ties(x):
    return float(np.round(np.sum((x - 0.3) ** 2), 1))  # plateaus: ties in the simplex's order


@pytest.mark.parametrize("fun", [_rosen, _bumpy, _quad_ties])
@pytest.mark.parametrize("n, maxfev", [(2, 40), (4, 3), (4, 7), (7, 60), (7, 200)])
def test_same_points_as_scipy(fun, n, maxfev):
    rng = np.random.default_rng(n * 1000 + maxfev)
    x0 = rng.normal(0.0, 0.7, n)
    simplex = x0 + np.vstack([np.zeros(n), 0.5 * np.eye(n)])
    theirs, mine, told = [], [], []

    def logged(log):
        return lambda x: log.append(np.array(x)) or fun(x)

    opts = {"maxfev": maxfev, "initial_simplex": simplex, "xatol": 0.02, "fatol": 0.5}
    minimize(logged(theirs), x0, method="Nelder-Mead", options=opts)
    nelder_mead(logged(mine), simplex, maxfev, 0.02, 0.5, ahead=told.extend, width=3)
    assert len(mine) == len(theirs) <= maxfev
    for a, b in zip(mine, theirs, strict=True):
        np.testing.assert_array_equal(a, b)
    # what is told ahead are points the search may need: here most of them were asked for
    asked = {a.tobytes() for a in mine}
    assert sum(t.tobytes() in asked for t in told) >= 0.5 * len(mine)
