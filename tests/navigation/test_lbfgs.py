"""The one L-BFGS (navigation/optimisers/lbfgs.py): driven from Python by its
reverse-communication contract, with each planner's rules, on a convex quadratic and on
Rosenbrock's function."""

import numpy as np
import pytest
from scipy.optimize import minimize, rosen, rosen_der

from ft_sitl.navigation.optimisers import lbfgs
from ft_sitl.navigation.optimisers.fast import FastParams
from ft_sitl.navigation.planners.pgo import PgoParams

EGO_RULES = lbfgs.LbfgsRules(memory=16, stop=lbfgs.StopRule.GRADIENT, tolerance=1e-9,
                             max_iterations=1000, step_min=1e-20, step_max=1e20)
RULES = {
    "ego": EGO_RULES,
    "fast": FastParams(max_evaluations=3000, xtol_rel=1e-12).lbfgs_rules(),
    "pgo": PgoParams(max_evaluations=3000, xtol_rel=1e-12).lbfgs_rules(),
}


def solve(rules, fun, x0):
    """Run the solver to its stop; returns (state, stop code, the points evaluated)."""
    st = rules.start(x0)
    seen = []
    while True:
        code = lbfgs.advance(st)
        if code == lbfgs.EVALUATE:
            f, g = fun(st.xn.copy())
            seen.append((f, st.xn.copy()))
            st.reals[lbfgs.F_TRIAL] = f
            st.gn[:] = g
        elif code != lbfgs.ITERATED:
            return st, code, seen


def quadratic(seed=3, n=12):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(n, n))
    h = a @ a.T + n * np.eye(n)
    b = rng.normal(size=n)
    return (lambda x: (0.5 * x @ h @ x - b @ x, h @ x - b)), np.linalg.solve(h, b)


@pytest.mark.parametrize("name", sorted(RULES))
def test_each_planners_rules_reach_the_minimum_of_a_convex_quadratic(name):
    fun, x_star = quadratic()
    st, code, seen = solve(RULES[name], fun, np.zeros_like(x_star))
    assert code >= 0
    result = st.best if RULES[name].keep_best else st.x
    np.testing.assert_allclose(result, x_star, atol=1e-6)
    assert st.ints[lbfgs.EVALUATIONS] == len(seen)
    assert lbfgs.advance(st) == code  # a stopped solve stays stopped


@pytest.mark.parametrize("name", sorted(RULES))
def test_rosenbrock_matches_scipys_minimum(name):
    x0 = np.array([-1.2, 1.0, -0.5, 0.8])
    st, _, _ = solve(RULES[name], lambda x: (rosen(x), rosen_der(x)), x0)
    ref = minimize(rosen, x0, jac=rosen_der, method="L-BFGS-B").x
    result = st.best if RULES[name].keep_best else st.x
    np.testing.assert_allclose(result, ref, atol=1e-4)


def test_keep_best_ends_at_the_lowest_cost_evaluated_within_the_evaluation_cap():
    fun, _ = quadratic(seed=5)
    rules = FastParams(max_evaluations=7).lbfgs_rules()
    st, code, seen = solve(rules, fun, np.ones(12))
    assert code == lbfgs.MAX_EVALUATIONS and len(seen) == 7
    f_best, x_best = min(seen, key=lambda s: s[0])
    assert st.reals[lbfgs.F_BEST] == f_best
    np.testing.assert_array_equal(st.best, x_best)


def test_a_failed_line_search_leaves_the_point_where_it_was():
    # a cost that never decreases along any direction: every trial fails Armijo
    x0 = np.array([1.0, -2.0])
    st, code, seen = solve(EGO_RULES, lambda x: (float(x @ x) if np.array_equal(x, x0)
                                                  else 1e9, 2.0 * x), x0)
    assert code == lbfgs.LINE_SEARCH
    np.testing.assert_array_equal(st.x, x0)
    assert len(seen) == 1 + 40  # the start and EGO's 40 trials


def test_the_row_and_blas_dot_products_agree_to_round_off():
    fun, _ = quadratic(seed=9, n=40)
    rows = lbfgs.LbfgsRules(memory=10, stop=lbfgs.StopRule.VARIABLES, tolerance=1e-10,
                            max_evaluations=60, keep_best=True)
    blas = lbfgs.LbfgsRules(memory=10, stop=lbfgs.StopRule.VARIABLES, tolerance=1e-10,
                            max_evaluations=60, keep_best=True, blas_dot=True)
    a, _, _ = solve(rows, fun, np.ones(40))
    b, _, _ = solve(blas, fun, np.ones(40))
    np.testing.assert_allclose(a.best, b.best, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("kwargs", [
    {"memory": 0}, {"tolerance": 0.0}, {"max_evaluations": True}, {"step_min": 2.0},
    {"stop": 1},
])
def test_rules_are_checked(kwargs):
    args = {"memory": 5, "stop": lbfgs.StopRule.STEP, "tolerance": 1e-5, **kwargs}
    with pytest.raises((ValueError, TypeError)):
        lbfgs.LbfgsRules(**args)
