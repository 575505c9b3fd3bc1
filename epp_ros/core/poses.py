"""Orientations of the boom's sections, for publishing a posture as poses.

Pose 0 is the base pivot, pose k (k = 1..p) joint k. Pose k's x-axis points along section k
(from joint k-1 to joint k) and its z-axis lies in the boom's vertical plane, pointing up;
the base pose points along the slew, level. Quaternions are (x, y, z, w).
"""
import numpy as np

__all__ = ['boom_frames', 'rotation_to_quaternion', 'boom_quaternions']


def boom_frames(base, joints):
    """Rotation matrices of the base and each section.

    Parameters
    ----------
    base : ndarray, shape (3,)
    joints : ndarray, shape (p, 3)

    Returns
    -------
    rotations : ndarray, shape (p + 1, 3, 3)
        Columns are the frame's x, y, z axes in the world frame.
    """
    base = np.asarray(base, dtype=float)
    chain = np.vstack([base, np.asarray(joints, dtype=float)])
    sections = np.diff(chain, axis=0)
    reach = chain[1:, :2] - base[:2]
    # Slew direction from the joints' horizontal reach (the sections' own when they are
    # vertical), falling back to +x for a boom standing straight up.
    horizontal = np.where(np.linalg.norm(sections[:, :2], axis=1)[:, None] > 1e-9,
                          sections[:, :2], reach)
    slew = horizontal.sum(axis=0)
    slew_direction = np.r_[slew / np.linalg.norm(slew), 0.0] if np.linalg.norm(slew) > 1e-9 \
        else np.array([1.0, 0.0, 0.0])
    lateral = np.cross([0.0, 0.0, 1.0], slew_direction)       # y: left of the boom
    x_axes = np.vstack([slew_direction, sections / np.linalg.norm(sections, axis=1)[:, None]])
    y_axes = np.broadcast_to(lateral, x_axes.shape)
    z_axes = np.cross(x_axes, y_axes)
    return np.stack([x_axes, y_axes, z_axes], axis=-1)


def rotation_to_quaternion(rotations):
    """Unit quaternions (x, y, z, w) of rotation matrices (..., 3, 3), w >= 0."""
    r = np.asarray(rotations, dtype=float)
    trace = np.trace(r, axis1=-2, axis2=-1)
    candidates = np.stack([
        np.stack([1 + 2 * r[..., 0, 0] - trace, r[..., 0, 1] + r[..., 1, 0],
                  r[..., 0, 2] + r[..., 2, 0], r[..., 2, 1] - r[..., 1, 2]], -1),
        np.stack([r[..., 0, 1] + r[..., 1, 0], 1 + 2 * r[..., 1, 1] - trace,
                  r[..., 1, 2] + r[..., 2, 1], r[..., 0, 2] - r[..., 2, 0]], -1),
        np.stack([r[..., 0, 2] + r[..., 2, 0], r[..., 1, 2] + r[..., 2, 1],
                  1 + 2 * r[..., 2, 2] - trace, r[..., 1, 0] - r[..., 0, 1]], -1),
        np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                  r[..., 1, 0] - r[..., 0, 1], 1 + trace], -1)], axis=-2)
    # Take the numerically best of the four formulas (largest diagonal term).
    best = np.argmax(np.stack([candidates[..., i, i] for i in range(4)], -1), axis=-1)
    quaternion = np.take_along_axis(candidates, best[..., None, None], axis=-2)[..., 0, :]
    quaternion /= np.linalg.norm(quaternion, axis=-1, keepdims=True)
    return np.where(quaternion[..., 3:] < 0, -quaternion, quaternion)


def boom_quaternions(base, joints):
    """Orientation (x, y, z, w) of the base and of each section, shape (p + 1, 4)."""
    return rotation_to_quaternion(boom_frames(base, joints))
