"""Synthetic bundle-adjustment problems with known truth.

The ring rig of the paper (section 3.1): cameras on two horizontal circles, all
looking at the floor centre, observing a regular grid of floor points. Used by the
bundle-adjustment tests and by ``tools/bench/ba_speed.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class SyntheticProblem:
    """Ground truth and noisy observations of a synthetic rig (world z up, floor z = 0)."""

    K: np.ndarray  # (C, 3, 3)
    resolution: tuple[int, int]
    poses: np.ndarray  # (C, 6) cam_from_world [angle-axis, t]
    points: np.ndarray  # (P, 3)
    camera_index: np.ndarray  # (N,)
    point_index: np.ndarray  # (N,)
    observed: np.ndarray  # (N, 2) undistorted pixels, with noise

    @property
    def plane(self) -> np.ndarray:
        """The floor as [n, d] with n . X = d."""
        return np.array([0.0, 0.0, 1.0, 0.0])


def rotvec_from_matrix(R: np.ndarray) -> np.ndarray:
    """Angle-axis vector of a rotation matrix (angle in [0, pi])."""
    cos_angle = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos_angle)
    if angle < 1e-12:
        return np.zeros(3)
    if np.pi - angle < 1e-6:
        # Near pi the antisymmetric part vanishes; take the axis from R + I.
        column = np.argmax(np.diag(R))
        axis = (R[:, column] + np.eye(3)[:, column]) / np.sqrt(2.0 * (1.0 + R[column, column]))
        return angle * axis / np.linalg.norm(axis)
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (2.0 * np.sin(angle))
    return angle * axis


def matrix_from_rotvec(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of an angle-axis vector (Rodrigues)."""
    angle = float(np.linalg.norm(w))
    if angle < 1e-12:
        return np.eye(3)
    k = np.asarray(w, dtype=float) / angle
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * Kx + (1.0 - np.cos(angle)) * Kx @ Kx


def look_at_pose(position: np.ndarray, target: np.ndarray) -> np.ndarray:
    """cam_from_world [angle-axis, t] of a camera at ``position`` looking at ``target``
    (the scene convention of ``calibproj.simulate.scene.look_at_rotation``)."""
    from calibproj.simulate.scene import look_at_rotation

    R = look_at_rotation(position, target)
    return np.concatenate([rotvec_from_matrix(R), -R @ np.asarray(position, float)])


def project(K: np.ndarray, pose: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (N, 2) and depths (N,) of world points through one camera."""
    cam = points @ matrix_from_rotvec(pose[:3]).T + pose[3:]
    uv = cam @ K.T
    return uv[:, :2] / uv[:, 2:3], cam[:, 2]


def paper_ring_rig(
    seed: int = 0,
    noise_px: float = 0.5,
    num_points: int = 3200,
    floor_size_m: tuple[float, float] = (4.0, 2.4),
    fx: float = 917.0,
    resolution: tuple[int, int] = (1920, 1080),
    random_angles: bool = True,
) -> SyntheticProblem:
    """The paper's synthetic rig: 6 cameras on r = 2.8 m at h = 2.8 m, 4 on r = 1.2 m at
    h = 1.4 m, all looking at the floor centre, observing a regular floor grid.

    Points are observed where they project inside the image in front of the camera.
    """
    rng = np.random.default_rng(seed)
    rings = [(6, 2.8, 2.8), (4, 1.2, 1.4)]
    poses = []
    for count, radius, height in rings:
        offset = rng.uniform(0.0, 2.0 * np.pi) if random_angles else 0.0
        angles = offset + 2.0 * np.pi * np.arange(count) / count
        if random_angles:
            angles += rng.uniform(-0.2, 0.2, count)
        for angle in angles:
            position = np.array([radius * np.cos(angle), radius * np.sin(angle), height])
            poses.append(look_at_pose(position, np.zeros(3)))
    poses = np.array(poses)
    width, height = resolution
    K = np.array([[fx, 0.0, (width - 1) / 2.0], [0.0, fx, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    Ks = np.repeat(K[None], len(poses), axis=0)

    aspect = floor_size_m[0] / floor_size_m[1]
    cols = int(round(np.sqrt(num_points * aspect)))
    rows = int(np.ceil(num_points / cols))
    xs = np.linspace(-floor_size_m[0] / 2, floor_size_m[0] / 2, cols)
    ys = np.linspace(-floor_size_m[1] / 2, floor_size_m[1] / 2, rows)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)[:num_points]
    points = np.column_stack([grid, np.zeros(len(grid))])

    camera_index, point_index, observed = [], [], []
    for c, pose in enumerate(poses):
        uv, depth = project(K, pose, points)
        visible = (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= height - 1)
        ids = np.flatnonzero(visible)
        camera_index.append(np.full(len(ids), c))
        point_index.append(ids)
        observed.append(uv[ids] + rng.normal(0.0, noise_px, (len(ids), 2)))
    camera_index = np.concatenate(camera_index)
    point_index = np.concatenate(point_index)
    observed = np.concatenate(observed)
    # Keep points seen by at least two cameras, renumbered densely.
    counts = np.bincount(point_index, minlength=len(points))
    keep = counts >= 2
    renumber = np.cumsum(keep) - 1
    mask = keep[point_index]
    return SyntheticProblem(
        K=Ks,
        resolution=resolution,
        poses=poses,
        points=points[keep],
        camera_index=camera_index[mask],
        point_index=renumber[point_index[mask]],
        observed=observed[mask],
    )


def perturb_poses(poses: np.ndarray, rotation_deg: float, translation_m: float, rng: np.random.Generator) -> np.ndarray:
    """Each pose rotated by ``rotation_deg`` about a random axis and its centre moved
    by ``translation_m`` in a random direction."""
    out = poses.copy()
    for c, pose in enumerate(poses):
        axis = rng.normal(size=3)
        axis *= np.deg2rad(rotation_deg) / np.linalg.norm(axis)
        R = matrix_from_rotvec(pose[:3])
        centre = -R.T @ pose[3:]
        step = rng.normal(size=3)
        centre = centre + translation_m * step / np.linalg.norm(step)
        R_new = matrix_from_rotvec(axis) @ R
        out[c, :3] = rotvec_from_matrix(R_new)
        out[c, 3:] = -R_new @ centre
    return out
