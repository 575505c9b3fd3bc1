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
Levenberg–Marquardt for a block-arrow least squares: per-frame angles and shared parameters.

Each frame's residuals depend on its own angles (a few) and on the shared parameters (a few
dozen) only, so the normal equations are block-arrow shaped: a block U per frame, its
coupling W to the shared parameters, and the shared block V. The angles are eliminated
frame by frame (a Schur complement, as in bundle adjustment), which leaves a small dense
system in the shared parameters; the frames' steps follow from it. ``core.calibrate`` is
the user: the frames of a recording, the anchors and range offsets shared.
"""
from epp_ros.core.solvers.levenberg_marquardt import levenberg_marquardt
import numpy as np

__all__ = ['normal_equations', 'eliminate', 'damped_step', 'least_squares']


def normal_equations(angle, shared, slope, weights, shared_gradient=0.0,
                     shared_information=0.0):
    """
    Return the block-arrow normal equations: U (n, a, a), W (n, a, q), V, g_a, g_q.

    The gradient and information of the terms of the shared parameters alone (anchor-anchor
    ranges, priors) add to ``g_q`` and ``V``.
    """
    weighted = np.swapaxes(angle * weights[..., None], 1, 2)        # (n, a, l)
    blocks = weighted @ angle
    coupling = weighted @ shared
    flat = shared.reshape(-1, shared.shape[-1])
    shared_block = (flat * weights.reshape(-1, 1)).T @ flat
    return (blocks, coupling, shared_block + shared_information,
            (np.swapaxes(angle, 1, 2) @ slope[..., None])[..., 0],
            flat.T @ slope.ravel() + shared_gradient)


def eliminate(blocks, coupling, shared_block, pseudo=False):
    """
    Return the shared parameters' information with the angles eliminated, and U^-1.

    ``pseudo``: U's pseudo-inverse, for a frame whose angles the ranges do not all
    determine (a silent tag, few links); exact, as such angle changes move no range.
    """
    inverse = np.linalg.pinv(blocks, rcond=1e-10, hermitian=True) if pseudo \
        else np.linalg.inv(blocks)
    size = coupling.shape[-1]
    reduced = shared_block - coupling.reshape(-1, size).T @ (inverse @ coupling).reshape(-1, size)
    return 0.5 * (reduced + reduced.T), inverse


def damped_step(normal, damping):
    """Return the Levenberg–Marquardt step (angles (n, a), shared (q,)) for ``damping``."""
    blocks, coupling, shared_block, gradient_a, gradient_q = normal
    size = blocks.shape[1]
    diagonal = np.einsum('nii->ni', blocks)
    # A small ridge relative to each frame's scale holds still the angles no range sees (a
    # silent tag's): rounding in their zero gradient would otherwise step them by radians.
    ridge = damping * diagonal + 1e-9 * (diagonal.max(axis=1, keepdims=True) + 1.0)
    damped = blocks + ridge[:, :, None] * np.eye(size)
    shared_damped = shared_block + damping * np.diag(np.diag(shared_block) + 1e-9)
    reduced, inverse = eliminate(damped, coupling, shared_damped)
    eliminated = (inverse @ gradient_a[..., None])[..., 0]          # (n, a)
    right = gradient_q - coupling.reshape(-1, coupling.shape[-1]).T @ eliminated.ravel()
    step_q = -np.linalg.solve(reduced, right)
    step_a = -(inverse @ (gradient_a + coupling @ step_q)[..., None])[..., 0]
    return step_a, step_q


def least_squares(problem, psi, q, frames, max_iter, tol):
    """
    Return Levenberg–Marquardt's minimum from ``psi`` (n, a) and ``q``, as ``chain.fit``.

    ``problem`` gives the frames' scaled residuals and Jacobian blocks (``evaluate``), their
    robust cost, slope and weights (``robust``) and the terms of ``q`` alone
    (``shared_terms``). Returns the angles, q, the cost, the iterations and whether it
    converged.
    """
    mask = problem.mask[frames]
    shape = psi.shape

    def evaluate(x):
        angles, q = x[:psi.size].reshape(shape), x[psi.size:]
        scaled, angle, shared = problem.evaluate(angles, problem.x0 + problem.basis @ q, frames)
        cost, slope, weights, _ = problem.robust(scaled, mask, frames)
        shared_cost, shared_gradient, shared_information, _ = problem.shared_terms(q)
        return (float(cost.sum()) + shared_cost,
                (angle, shared, slope, weights, shared_gradient, shared_information))

    def step(normal, damping):
        return np.concatenate([part.ravel() for part in damped_step(normal, damping)])

    fit = levenberg_marquardt(np.r_[psi.ravel(), q], evaluate,
                              lambda x, parts: normal_equations(*parts), max_iter=max_iter,
                              tol=tol, step=step, stall=1e-10)
    return (fit.x[:psi.size].reshape(shape), fit.x[psi.size:], fit.cost, fit.iterations,
            fit.converged)
