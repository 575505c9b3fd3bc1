"""The boom's vertical plane (the paper's Feature II) for CEPP.

All sections of a pump boom lie in the vertical plane through the base pivot along the slew
direction ``u = (cos theta, sin theta, 0)``. In-plane coordinates of a point x are
``a = (x - b) . u`` (horizontal reach) and its height z.
"""
import numpy as np

__all__ = ['fit_slew', 'to_plane', 'from_plane', 'project_ranges']


def fit_slew(points, base):
    """Slew angle of the vertical plane through ``base`` that best fits ``points``.

    Total least squares on the horizontal projections (the principal direction of their
    scatter about the base), which, unlike the paper's fitted slope ``K``, is defined for
    every direction including the y-axis. The sign is chosen so that the points lie on the
    positive side on average.

    Parameters
    ----------
    points : ndarray, shape (k, 3)
    base : ndarray, shape (3,)

    Returns
    -------
    slew : float, radians in [-pi, pi)
    """
    horizontal = np.asarray(points, dtype=float)[:, :2] - np.asarray(base, dtype=float)[:2]
    _, _, vt = np.linalg.svd(horizontal, full_matrices=False)
    direction = vt[0]
    if np.sum(horizontal @ direction) < 0:
        direction = -direction
    slew = float(np.arctan2(direction[1], direction[0]))
    return slew if slew < np.pi else -np.pi


def to_plane(points, base, slew):
    """In-plane coordinates (reach, z) of ``points`` (k, 3) -> (k, 2)."""
    points = np.asarray(points, dtype=float)
    offset = points[:, :2] - np.asarray(base, dtype=float)[:2]
    reach = offset @ np.array([np.cos(slew), np.sin(slew)])
    return np.column_stack([reach, points[:, 2]])


def from_plane(coords, base, slew):
    """World positions (k, 3) of in-plane coordinates (k, 2) in the plane of ``slew``."""
    coords = np.asarray(coords, dtype=float)
    base = np.asarray(base, dtype=float)
    return np.column_stack([base[0] + coords[:, 0] * np.cos(slew),
                            base[1] + coords[:, 0] * np.sin(slew), coords[:, 1]])


def project_ranges(ranges, anchors, base, slew):
    """Exact squared ranges, within the plane, from in-plane tags to projected anchors.

    A tag in the plane and an anchor at perpendicular distance ``d`` from it satisfy
    ``delta_plane^2 = delta^2 - d^2``. (The paper's formula uses the tag's own previous
    coordinates instead, which is not this.) Noise can make ``delta < d``; such values are
    clipped to zero and flagged.

    Parameters
    ----------
    ranges : ndarray, shape (p, m)
        Measured tag-anchor distances, NaN where missing.
    anchors : ndarray, shape (m, 3)
    base : ndarray, shape (3,)
    slew : float

    Returns
    -------
    squared : ndarray, shape (p, m)
        In-plane squared ranges (NaN where missing).
    clipped : ndarray of bool, shape (p, m)
        Where noise made the projection negative.
    """
    normal = np.array([-np.sin(slew), np.cos(slew)])
    offset = (np.asarray(anchors, dtype=float)[:, :2] - np.asarray(base, dtype=float)[:2]) @ normal
    squared = np.asarray(ranges, dtype=float) ** 2 - offset ** 2
    with np.errstate(invalid='ignore'):
        clipped = squared < 0
    return np.where(clipped, 0.0, squared), clipped
