"""Closed-form focal lengths from floor homographies, against known cameras."""

from __future__ import annotations

import numpy as np
import pytest

from calibproj import _core


class Found:
    """The core's planar autocalibration of named homographies."""

    def __init__(self, homographies: dict[str, np.ndarray], known: dict[str, float] | None = None) -> None:
        self.focal, self.residual, self.circular_point = _core.selfcal.focal_lengths(list(homographies.items()),
                                                                                     known or {})


focal_lengths = Found


def look_at(centre: np.ndarray, target: np.ndarray) -> np.ndarray:
    forward = (target - centre) / np.linalg.norm(target - centre)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    return np.array([right, np.cross(forward, right), forward])


def floor_homographies(count: int, seed: int, frame: np.ndarray) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """Cameras around the floor with random focal lengths; their homographies from the
    floor in ``frame`` (a projective change of the metric floor frame) to centred pixels."""
    rng = np.random.default_rng(seed)
    homographies, truth = {}, {}
    for k in range(count):
        angle = 2 * np.pi * k / count + rng.normal(0, 0.2)
        centre = np.array([3 * np.cos(angle), 3 * np.sin(angle), rng.uniform(2.0, 3.0)])
        R = look_at(centre, np.array([rng.normal(0, 0.3), rng.normal(0, 0.3), 0.0]))
        focal = rng.uniform(500, 3000)
        truth[f"c{k}"] = focal
        homographies[f"c{k}"] = np.diag([focal, focal, 1.0]) @ np.column_stack([R[:, 0], R[:, 1], -R @ centre]) \
            @ np.linalg.inv(frame)
    return homographies, truth


# The floor reconstructed in a frame that is not metric: sheared, stretched and even
# slightly projective (the circular points are then not (1, +-i, 0)).
FRAME = np.array([[1.05, 0.08, 0.3], [-0.03, 0.97, -0.2], [0.004, -0.003, 1.0]])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_focal_lengths_of_five_cameras(seed: int) -> None:
    homographies, truth = floor_homographies(5, seed, FRAME)
    result = focal_lengths(homographies)
    for name, focal in truth.items():
        assert result.focal[name] == pytest.approx(focal, rel=1e-9)
        assert result.residual[name] < 1e-9


def test_one_known_camera_gives_the_floor_metric() -> None:
    homographies, truth = floor_homographies(3, 4, FRAME)
    result = focal_lengths(homographies, known={"c0": truth["c0"]})
    assert set(result.focal) == {"c1", "c2"}
    for name in ("c1", "c2"):
        assert result.focal[name] == pytest.approx(truth[name], rel=1e-9)


def test_too_few_cameras_and_degenerate_homographies_are_refused() -> None:
    homographies, _ = floor_homographies(3, 5, FRAME)
    with pytest.raises(ValueError, match="6 equations for 7 unknowns"):
        focal_lengths(homographies)
    homographies["c0"] = np.zeros((3, 3))
    with pytest.raises(ValueError, match="camera c0: degenerate floor homography"):
        focal_lengths(homographies, known={"c1": 1000.0})
    with pytest.raises(ValueError, match="finite 3x3"):
        focal_lengths({"c0": np.full((3, 3), np.nan)})
