# Copyright 2026 epp_ros developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""The one Levenberg–Marquardt loop: known minima, its stopping rules, its hooks."""
from epp_ros.core.solvers import levenberg_marquardt, levenberg_marquardt_batch, marquardt_step
import numpy as np
from scipy.optimize import least_squares


def rosenbrock(x):
    """Return Rosenbrock's residuals (2,) and Jacobian (2, 2): minimum 0 at (1, 1)."""
    return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]]), \
        np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])


def evaluate(x):
    residuals, jacobian = rosenbrock(x)
    return 0.5 * float(residuals @ residuals), (residuals, jacobian)


def normal_equations(x, state):
    residuals, jacobian = state
    return jacobian.T @ jacobian, jacobian.T @ residuals


def test_it_finds_rosenbrocks_minimum_from_the_classic_start():
    fit = levenberg_marquardt(np.array([-1.2, 1.0]), evaluate, normal_equations,
                              max_iter=200, tol=1e-12, stall=0.0)
    assert fit.converged
    np.testing.assert_allclose(fit.x, [1.0, 1.0], atol=1e-8)
    assert fit.cost < 1e-16
    np.testing.assert_array_equal(fit.state[0], rosenbrock(fit.x)[0])


def test_it_agrees_with_scipy_on_a_range_fit():
    rng = np.random.default_rng(3)
    anchors = rng.uniform(-10.0, 10.0, (6, 3))
    truth = np.array([1.0, 2.0, 3.0])
    ranges = np.linalg.norm(anchors - truth, axis=1) + rng.normal(0.0, 0.05, 6)

    def residuals(x):
        return np.linalg.norm(anchors - x, axis=1) - ranges

    def state(x):
        r = residuals(x)
        return 0.5 * float(r @ r), (r, (x - anchors) / (r + ranges)[:, None])

    ours = levenberg_marquardt(np.zeros(3), state, normal_equations, max_iter=100, tol=1e-12,
                               stall=0.0)
    theirs = least_squares(residuals, np.zeros(3), method='lm', xtol=1e-15, ftol=1e-15)
    np.testing.assert_allclose(ours.x, theirs.x, atol=1e-9)


def test_a_start_at_the_minimum_stops_at_once_and_stays():
    start = np.array([1.0, 1.0])
    fit = levenberg_marquardt(start, evaluate, normal_equations, max_iter=50, tol=0.0)
    assert fit.converged and fit.iterations == 1
    np.testing.assert_array_equal(fit.x, start)


def test_running_out_of_iterations_is_not_convergence():
    fit = levenberg_marquardt(np.array([-1.2, 1.0]), evaluate, normal_equations, max_iter=2,
                              tol=0.0, stall=0.0)
    assert not fit.converged and fit.iterations == 2
    assert fit.cost < evaluate(np.array([-1.2, 1.0]))[0]       # each step lowered the cost
    none = levenberg_marquardt(np.array([-1.2, 1.0]), evaluate, normal_equations, max_iter=0,
                               tol=0.0)
    assert not none.converged and none.iterations == 0


def test_refine_is_applied_after_each_accepted_step():
    calls = []

    def refine(x, cost, state):
        calls.append(x.copy())
        return x, cost, state

    fit = levenberg_marquardt(np.array([-1.2, 1.0]), evaluate, normal_equations, max_iter=200,
                              tol=1e-12, refine=refine)
    assert fit.converged and len(calls) >= fit.iterations - 1 >= 1
    np.testing.assert_array_equal(calls[-1], fit.x)


def test_the_callers_own_test_stops_the_fit_at_the_first_step_it_passes():
    costs = []

    def done(x, cost, state):
        costs.append(cost)
        return cost < 1.0                      # far above the minimum (0): stalls do not stop

    fit = levenberg_marquardt(np.array([-1.2, 1.0]), evaluate, normal_equations, max_iter=200,
                              tol=0.0, stall=0.0, done=done)
    assert fit.converged and fit.cost == costs[-1] < 1.0 <= min(costs[:-1], default=1.0)
    assert fit.iterations >= len(costs)


def test_the_ridge_holds_still_a_parameter_no_residual_sees():
    def unseen(x):
        r = np.array([x[0] - 2.0])
        return 0.5 * float(r @ r), (r, np.array([[1.0, 0.0]]))

    fit = levenberg_marquardt(np.array([0.0, 5.0]), unseen, normal_equations, max_iter=20,
                              tol=1e-12, step=marquardt_step(ridge=1e-9))
    np.testing.assert_allclose(fit.x, [2.0, 5.0], atol=1e-9)


def test_the_batch_finds_each_problems_minimum_by_the_same_schedule():
    """Side by side, each problem reaches its own minimum; a start at one stays there."""
    rng = np.random.default_rng(5)
    anchors = rng.uniform(-10.0, 10.0, (6, 3))
    truths = rng.uniform(-3.0, 3.0, (4, 3))
    ranges = np.linalg.norm(anchors - truths[:, None], axis=2) + rng.normal(0.0, 0.05, (4, 6))

    def batch_state(x):
        offset = x[:, None, :] - anchors
        distance = np.linalg.norm(offset, axis=2)
        r = distance - ranges
        return 0.5 * np.sum(r ** 2, axis=1), (r, offset / distance[..., None])

    def batch_normal(x, state):
        r, jacobian = state
        return (np.einsum('bji,bjk->bik', jacobian, jacobian),
                np.einsum('bji,bj->bi', jacobian, r))

    starts = np.zeros((4, 3))
    x, cost = levenberg_marquardt_batch(starts, batch_state, batch_normal, rounds=30)
    for b in range(4):
        one = least_squares(lambda y: np.linalg.norm(anchors - y, axis=1) - ranges[b],
                            starts[b], method='lm', xtol=1e-15, ftol=1e-15)
        np.testing.assert_allclose(x[b], one.x, atol=1e-8)
        assert abs(cost[b] - one.cost) <= 1e-12
    again, cost_again = levenberg_marquardt_batch(x, batch_state, batch_normal, rounds=5)
    np.testing.assert_allclose(again, x, atol=1e-12)
    assert np.all(cost_again <= cost)


def test_a_batch_problem_that_cannot_improve_keeps_its_start():
    """A problem whose every step raises the cost (a NaN cost, too) keeps its start."""
    def batch_state(x):
        cost = np.where(np.arange(len(x)) == 0, np.sum((x - 1.0) ** 2, axis=1), np.nan)
        return cost, (x,)

    def batch_normal(x, state):
        return np.broadcast_to(2.0 * np.eye(2), (len(x), 2, 2)), 2.0 * (x - 1.0)

    x, cost = levenberg_marquardt_batch(np.zeros((2, 2)), batch_state, batch_normal, rounds=3)
    np.testing.assert_allclose(x[0], [1.0, 1.0], atol=1e-6)
    np.testing.assert_array_equal(x[1], [0.0, 0.0])
