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
Euclidean distance matrix helpers: cone projection, rank penalty, classical MDS, alignment.

An EDM here is a matrix of *squared* distances, ``D[i, j] = ||x_i - x_j||^2``; the stress
refinement (:func:`refine_stress`) fits the embedded points to the unsquared distances.
"""
import numpy as np
from scipy.linalg import lapack
from scipy.optimize import least_squares

__all__ = ['symmetric_eigh', 'squared_distances', 'centering_matrix', 'double_centre',
           'project_edm_cone', 'gram_spectrum', 'rank_penalty', 'classical_mds',
           'align_to_known', 'refine_stress']


def symmetric_eigh(matrix):
    """
    Eigenvalues (ascending) and eigenvectors of a small symmetric matrix (n, n).

    ``numpy.linalg.eigh`` without its per-call overhead (LAPACK ``dsyevd`` directly), which
    dominates for the n <= ~20 matrices solved thousands of times per posture.

    Non-finite input gives non-finite output, as with numpy.

    Raises
    ------
    numpy.linalg.LinAlgError
        When LAPACK reports that it failed to converge.

    """
    eigenvalues, eigenvectors, info = lapack.dsyevd(matrix)
    if info != 0:
        raise np.linalg.LinAlgError(f'dsyevd failed (info={info})')
    return eigenvalues, eigenvectors


def squared_distances(points):
    """Squared-distance matrix of ``points`` (n, d) -> (n, n)."""
    points = np.asarray(points, dtype=float)
    gram = points @ points.T
    norms = np.diag(gram)
    return np.maximum(norms[:, None] + norms[None, :] - 2.0 * gram, 0.0)


def centering_matrix(q):
    """
    Orthogonal projector ``I - q q^T / q^T q`` onto the complement of ``q`` (n,) -> (n, n).

    ``q = ones(n)`` gives the usual geometric centering matrix J.
    """
    q = np.asarray(q, dtype=float)
    return np.eye(q.size) - np.outer(q, q) / (q @ q)


def double_centre(matrix):
    """``J A J`` for the geometric centering ``J = I - 1 1^T / n``; (n, n) -> (n, n)."""
    n = matrix.shape[0]
    centering = np.eye(n) - 1.0 / n
    return centering @ matrix @ centering


def project_edm_cone(matrix, q=None):
    """
    Project a symmetric matrix onto ``K_-(q) = {Y : Y is NSD on q-perp}``.

    With ``q = ones`` this is the cone ``K^n_-`` of conditionally negative semidefinite
    matrices that, with a zero diagonal, are exactly the EDMs; the projection is closed form
    (Hayden & Wells 1988): ``Pi(A) = A - Pi_{S+}(J A J)``.

    Parameters
    ----------
    matrix : ndarray, shape (n, n), symmetric
        The matrix to project.
    q : ndarray, shape (n,), optional
        Centering direction; ones by default.

    Returns
    -------
    ndarray, shape (n, n)

    """
    matrix = np.asarray(matrix, dtype=float)
    n = matrix.shape[0]
    centering = centering_matrix(np.ones(n) if q is None else q)
    centred = centering @ matrix @ centering
    eigenvalues, eigenvectors = symmetric_eigh(0.5 * (centred + centred.T))
    positive = np.maximum(eigenvalues, 0.0)
    return matrix - (eigenvectors * positive) @ eigenvectors.T


def gram_spectrum(edm):
    """
    Eigenvalues, largest first, and eigenvectors of ``-J D J`` for an EDM ``D`` (n, n).

    The one eigendecomposition behind :func:`rank_penalty` and :func:`classical_mds`: an
    iterate that needs both computes it once.
    """
    gram = -double_centre(edm)
    eigenvalues, eigenvectors = symmetric_eigh(0.5 * (gram + gram.T))
    return eigenvalues[::-1], eigenvectors[:, ::-1]


def rank_penalty(edm, rank, spectrum=None):
    """
    Rank penalty ``p(D) = sum_{i > r} lambda_i(-J D J)`` and the top-r eigenvectors.

    Zero iff the points generating ``edm`` (an EDM or near one) span at most ``rank``
    dimensions. It is concave in D: linearising it at D^k gives the majorisation used by
    the penalty method, ``p(D) <= <D, -J (I - U) J>`` with ``U = P1 P1^T``.
    ``spectrum``: ``gram_spectrum(edm)``, when known.

    Returns
    -------
    penalty : float
        Sum of the eigenvalues of ``-J D J`` beyond the r-th (negatives count as zero).
    trace : float
        Sum of the positive eigenvalues, to turn ``penalty`` into a relative rank error.
    leading : ndarray, shape (n, rank)
        Eigenvectors of the r largest eigenvalues.

    """
    eigenvalues, eigenvectors = gram_spectrum(edm) if spectrum is None else spectrum
    positive = np.maximum(eigenvalues, 0.0)
    return float(positive[rank:].sum()), float(positive.sum()), eigenvectors[:, :rank]


def classical_mds(edm, dim, spectrum=None):
    """
    Classical multidimensional scaling (Torgerson): points whose EDM is nearest ``edm``.

    Parameters
    ----------
    edm : ndarray, shape (n, n)
        Squared distances.
    dim : int
        Embedding dimension r.
    spectrum : tuple of ndarray, optional
        ``gram_spectrum(edm)``, when known.

    Returns
    -------
    points : ndarray, shape (n, dim)
        ``P1 diag(sqrt(lambda_1..r))`` from ``-1/2 J D J = P diag(lambda) P^T``, centred at
        the origin; negative eigenvalues are clipped to zero.

    """
    eigenvalues, eigenvectors = gram_spectrum(edm) if spectrum is None else spectrum
    # Halving is exact: -1/2 J D J has the same eigenvectors, to the last bit.
    return eigenvectors[:, :dim] * np.sqrt(np.maximum(0.5 * eigenvalues[:dim], 0.0))


def align_to_known(points, known_index, known_positions, pivot=None, up_axis=-1):
    """
    Rigidly move an embedding so that its known points land on their true positions.

    Orthogonal Procrustes with translation, reflections allowed, no scaling (the embedding
    of an EDM is defined only up to a rigid motion and a reflection). With a ``pivot``, that
    known point is matched exactly and the rotation about it fits the others.

    When the known points do not span all dimensions (e.g. anchors in one plane), the
    mirror image through their affine hull fits them equally well; then the solution that
    puts the other points higher along ``up_axis`` is chosen (the boom is above the truck).

    Parameters
    ----------
    points : ndarray, shape (n, d)
        Embedded points.
    known_index : ndarray of int, shape (k,)
        Rows of ``points`` whose true positions are known.
    known_positions : ndarray, shape (k, d)
        Their true positions.
    pivot : int, optional
        Position in ``known_index`` of a point to match exactly (the boom's base pivot).
    up_axis : int
        Coordinate that points up, for the mirror rule.

    Returns
    -------
    aligned : ndarray, shape (n, d)

    """
    points = np.asarray(points, dtype=float)
    known_positions = np.asarray(known_positions, dtype=float)
    source = points[known_index]
    if pivot is None:
        source_mean = source.mean(axis=0)
        target_mean = known_positions.mean(axis=0)
    else:
        source_mean = source[pivot]
        target_mean = known_positions[pivot]
    u, s, vt = np.linalg.svd((source - source_mean).T @ (known_positions - target_mean))
    rotation = u @ vt
    aligned = (points - source_mean) @ rotation + target_mean
    spread = np.linalg.svd(known_positions - target_mean, compute_uv=False)
    degenerate = spread.size < points.shape[1] or spread[-1] <= 1e-9 * max(spread[0], 1.0)
    if degenerate:
        # Mirror through the known points' hull: flip along the direction they do not span.
        _, _, hull_vt = np.linalg.svd(known_positions - target_mean)
        normal = hull_vt[-1]
        mirror = np.eye(points.shape[1]) - 2.0 * np.outer(normal, normal)
        mirrored = (aligned - target_mean) @ mirror + target_mean
        others = np.setdiff1d(np.arange(points.shape[0]), known_index)
        if others.size and mirrored[others, up_axis].mean() > aligned[others, up_axis].mean():
            aligned = mirrored
    return aligned


def refine_stress(points, free, distances, weights, max_iter=500):
    """
    Move the free points to a local minimum of the weighted stress of the unsquared distances.

    Minimises ``sum_{i<j} weights[i, j] (||x_i - x_j|| - distances[i, j])^2`` over the rows
    ``free`` of ``points``, the others held: the refinement EMBED applies after its
    embedding (Toh's post-processing in SNLSDP; Biswas, Liang, Toh, Wang and Ye, ACM Trans.
    Sensor Netw. 2006), there by steepest descent on unit weights. Squared distances weight
    a long range's error by its length squared; the stress weighs each distance's error
    alike, as the range noise does. Levenberg-Marquardt (scipy's MINPACK) reaches the same
    local minimum in a few steps.

    Parameters
    ----------
    points : ndarray, shape (n, d)
        The embedding to start from, metres.
    free : ndarray of int or bool, shape (n,) or (k,)
        The points that move.
    distances : ndarray, shape (n, n), symmetric
        Target distances, metres; read only where ``weights > 0``.
    weights : ndarray, shape (n, n), symmetric, >= 0
        Weight of each distance; 0 where unknown.
    max_iter : int
        Jacobian evaluations at most.

    Returns
    -------
    refined : ndarray, shape (n, d)
        ``points`` with the free rows moved.
    evaluations : int
        Residual evaluations done.

    """
    points = np.array(points, dtype=float)
    moving = np.zeros(points.shape[0], bool)
    moving[free] = True
    rows, cols = np.nonzero(np.triu(weights > 0, 1) & (moving[:, None] | moving[None, :]))
    if rows.size < moving.sum() * points.shape[1]:
        return points, 0                    # fewer distances than unknowns: not determined
    scale = np.sqrt(weights[rows, cols])
    target = distances[rows, cols]
    index = np.cumsum(moving) - 1           # column block of each free point

    def place(flat):
        placed = points.copy()
        placed[moving] = flat.reshape(-1, points.shape[1])
        return placed

    def residuals(flat):
        placed = place(flat)
        return scale * (np.linalg.norm(placed[rows] - placed[cols], axis=1) - target)

    def jacobian(flat):
        placed = place(flat)
        offset = placed[rows] - placed[cols]
        unit = offset / np.maximum(np.linalg.norm(offset, axis=1), 1e-12)[:, None]
        d = points.shape[1]
        jac = np.zeros((rows.size, moving.sum(), d))
        edges = np.arange(rows.size)
        for ends, sign in ((rows, 1.0), (cols, -1.0)):
            on = moving[ends]
            jac[edges[on], index[ends[on]]] += sign * scale[on, None] * unit[on]
        return jac.reshape(rows.size, -1)

    fit = least_squares(residuals, points[moving].ravel(), jac=jacobian, method='lm',
                        xtol=1e-10, ftol=1e-12, max_nfev=max_iter)
    return place(fit.x), int(fit.nfev)
