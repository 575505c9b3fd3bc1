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

"""
The one Levenberg–Marquardt loop: the chain's fit, the tracker's update, the batch fit, the survey.

Each caller owns its cost and its normal equations (robust IRLS weights, priors, a ground
penalty, a block-arrow structure); the loop owns the damping schedule and when to stop, so
that every fit in the package stops by the same rules:

- a step is taken only if it does not raise the cost; the damping grows ×4 until one does,
  and gives up past 1e10 (no step lowers the cost: a minimum);
- after a step the damping shrinks ÷3, down to ``damping_floor``;
- the fit has converged when no step lowers the cost, when the cost fell by at most
  ``stall`` of itself, or when no parameter moved by more than ``tol``.

:func:`levenberg_marquardt_batch` runs the same schedule on many small problems side by
side, a fixed number of trial steps each (the integrity checks' solution separation).
"""
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ['LevenbergMarquardtResult', 'levenberg_marquardt', 'levenberg_marquardt_batch',
           'marquardt_step']

#: Damping at the start, its growth on a rejected step and its fall after an accepted one.
INITIAL_DAMPING = 1e-6
GROWTH = 4.0
FALL = 3.0
#: Beyond this damping the step is too short to matter: the start is a minimum.
MAX_DAMPING = 1e10
#: Converged when an accepted step lowered the cost by at most this fraction of it.
STALL = 1e-6
#: The damping falls no lower after accepted steps.
DAMPING_FLOOR = 1e-9
#: Added to the damped diagonal: a parameter no residual sees is held, not stepped by rounding.
RIDGE = 1e-9


@dataclass(frozen=True)
class LevenbergMarquardtResult:
    """
    Where Levenberg–Marquardt stopped.

    Attributes
    ----------
    x : ndarray
        The parameters at the lowest cost found.
    cost : float
        The cost there.
    state : object
        What the caller's ``evaluate`` returned with that cost (residuals, weights, ...).
    iterations : int
        Normal equations built and solved (an accepted or the final rejected step each).
    converged : bool
        False when ``max_iter`` ran out first.

    """

    x: np.ndarray
    cost: float
    state: Any
    iterations: int
    converged: bool


def marquardt_step(ridge=RIDGE):
    """
    Return Marquardt's damped step for normal equations given as ``(normal, gradient)``.

    The damping scales the diagonal, plus ``ridge``: a parameter no residual sees (zero on
    the diagonal) is then held still instead of stepped by rounding. ``ridge=0`` keeps
    directions that only a weak prior resolves free to move.
    """
    def step(normal_equations, damping):
        normal, gradient = normal_equations
        return -np.linalg.solve(normal + damping * np.diag(np.diag(normal) + ridge), gradient)
    return step


def levenberg_marquardt(x, evaluate, normal_equations, *, max_iter, tol, step=None, stall=STALL,
                        damping_floor=DAMPING_FLOOR, refine=None, done=None):
    """
    Minimise a cost by Levenberg–Marquardt from ``x``.

    Parameters
    ----------
    x : ndarray, shape (n,)
        The start.
    evaluate : callable
        ``evaluate(x) -> (cost, state)``; ``state`` is what ``normal_equations`` needs.
    normal_equations : callable
        ``normal_equations(x, state)``: whatever ``step`` takes (by default the pair
        ``(normal (n, n), gradient (n,))``).
    max_iter : int
        Iterations at most.
    tol : float
        Converged when no parameter moved by more than this (in ``x``'s units).
    step : callable, optional
        ``step(normal_equations, damping) -> dx (n,)``; by default :func:`marquardt_step`.
    stall : float
        Converged when an accepted step lowered the cost by at most this fraction of it.
    damping_floor : float
        The damping falls no lower.
    refine : callable, optional
        ``refine(x, cost, state) -> (x, cost, state)`` after each accepted step: a move
        the caller knows to be good (it must not raise the cost).
    done : callable, optional
        ``done(x, cost, state) -> bool`` after each accepted step: converged by the
        caller's own test (a KKT residual, say), checked before ``stall`` and ``tol``.

    Returns
    -------
    LevenbergMarquardtResult

    """
    step = marquardt_step() if step is None else step
    cost, state = evaluate(x)
    damping = INITIAL_DAMPING
    for iteration in range(1, max_iter + 1):
        system = normal_equations(x, state)
        while True:
            dx = step(system, damping)
            trial = x + dx
            trial_cost, trial_state = evaluate(trial)
            if trial_cost <= cost or damping > MAX_DAMPING:
                break
            damping *= GROWTH
        if trial_cost > cost:               # no step lowers the cost: a minimum
            return LevenbergMarquardtResult(x, cost, state, iteration, True)
        stalled = cost - trial_cost <= stall * max(abs(trial_cost), 1e-300)
        x, cost, state = trial, trial_cost, trial_state
        if refine is not None:
            x, cost, state = refine(x, cost, state)
        damping = max(damping / FALL, damping_floor)
        if done is not None and done(x, cost, state):
            return LevenbergMarquardtResult(x, cost, state, iteration, True)
        if stalled or np.max(np.abs(dx), initial=0.0) <= tol:
            return LevenbergMarquardtResult(x, cost, state, iteration, True)
    return LevenbergMarquardtResult(x, cost, state, max_iter, False)


def levenberg_marquardt_batch(x, evaluate, normal_equations, *, rounds, ridge=RIDGE,
                              damping_floor=DAMPING_FLOOR):
    """
    Minimise many costs of the same size side by side, ``rounds`` trial steps each.

    The schedule is :func:`levenberg_marquardt`'s, one trial step per problem and round: a
    step that does not raise a problem's cost is taken and its damping falls ÷3, else it
    grows ×4 and the next round tries again. One array operation serves every problem, so
    a few dozen small fits cost about what one does in a Python loop.

    Parameters
    ----------
    x : ndarray, shape (b, n)
        The starts, one row per problem.
    evaluate : callable
        ``evaluate(x (b, n)) -> (cost (b,), state)``; ``state`` is a tuple of arrays whose
        first axis is the problem.
    normal_equations : callable
        ``normal_equations(x, state) -> (normal (b, n, n), gradient (b, n))``.
    rounds : int
        Trial steps per problem.
    ridge : float
        Added to the damped diagonal, as in :func:`marquardt_step`.
    damping_floor : float
        The damping falls no lower.

    Returns
    -------
    x : ndarray, shape (b, n)
        Each problem's parameters at the lowest cost found.
    cost : ndarray, shape (b,)
        Those costs.

    """
    x = np.array(x, dtype=float)
    cost, state = evaluate(x)
    damping = np.full(cost.shape, INITIAL_DAMPING)
    eye = np.eye(x.shape[1])
    for _ in range(rounds):
        normal, gradient = normal_equations(x, state)
        diagonal = np.diagonal(normal, axis1=1, axis2=2) + ridge
        damped = normal + damping[:, None, None] * diagonal[:, :, None] * eye
        trial = x - np.linalg.solve(damped, gradient[..., None])[..., 0]
        trial_cost, trial_state = evaluate(trial)
        better = trial_cost <= cost         # NaN costs are never better
        x = np.where(better[:, None], trial, x)
        cost = np.where(better, trial_cost, cost)
        state = tuple(np.where(better.reshape((-1,) + (1,) * (new.ndim - 1)), new, old)
                      for new, old in zip(trial_state, state))
        damping = np.where(better, np.maximum(damping / FALL, damping_floor),
                           np.minimum(damping * GROWTH, MAX_DAMPING))
    return x, cost
