"""From projector light on the floor to a camera's 8-bit grey levels.

The model, per camera pixel (``Photometric`` holds the numbers):

1. light: the share of full projector white reaching the floor point, in [0, 1]
   (the warped projector image; its grey levels are taken as linear light);
2. optics: a Gaussian blur of ``blur_px`` pixels, applied with the pixel's own
   integration while sampling the projector image (``calibproj.simulate.warp``);
3. irradiance ``E = vignetting_gain * albedo * (ambient + contrast * light)``: the
   lights-off floor lit by the projector's finite contrast plus ambient light,
   reflected by the floor (``albedo``, 1 unless the floor has a texture), darkened
   towards the image corners by ``1 - vignetting * (r / r_corner)**2``;
4. encoded value ``(gain * E)**(1 / gamma)`` (the video's display gamma), full scale 1;
   ``gain`` is 1 unless the camera adjusts its exposure (``AutoExposure``);
5. grey level ``255 * encoded`` plus sensor noise of ``noise_std`` grey levels,
   rounded to 8 bits.

Steps 1-3 are linear in the light, so a frame exposed across a pattern change is
blended in irradiance, before the gamma.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibproj.simulate.scene import Camera, Photometric

# Every frame adds crops, at random offsets up to this, of two noise fields drawn once
# per camera: a sum of two, so that no frame's noise is a shifted copy of another's.
NOISE_OFFSET_RANGE_PX = 256


@dataclass(frozen=True, eq=False)
class CameraResponse:
    """Steps 3-4 of the model for one camera.

    Attributes:
        photometric: the settings.
        ambient_gain: ``vignetting_gain * ambient`` per pixel (``float32``).
        contrast_gain: ``vignetting_gain * contrast`` per pixel (``float32``).
    """

    photometric: Photometric
    ambient_gain: np.ndarray
    contrast_gain: np.ndarray

    @classmethod
    def for_camera(cls, camera: Camera, photometric: Photometric, albedo: np.ndarray | None = None) -> CameraResponse:
        gain = vignetting_gain(camera, photometric.vignetting)
        if albedo is not None:
            gain = gain * albedo
        return cls(photometric, (gain * photometric.ambient).astype(np.float32),
                   (gain * photometric.contrast).astype(np.float32))

    def irradiance(self, light: np.ndarray) -> np.ndarray:
        """Step 3: ``float32`` irradiance of a ``float32`` light image."""
        import cv2

        irradiance = self.ambient_gain.copy()
        cv2.accumulateProduct(light, self.contrast_gain, irradiance)
        return irradiance

    def encode(self, irradiance: np.ndarray) -> np.ndarray:
        """Step 4: ``float32`` display-encoded values (full scale 1) of an irradiance image."""
        import cv2

        gamma = self.photometric.gamma
        return irradiance if gamma == 1.0 else cv2.pow(irradiance, 1.0 / gamma)


def vignetting_gain(camera: Camera, vignetting: float) -> np.ndarray:
    """``1 - vignetting * (r / r_corner)**2``, ``r`` the distance to the principal point
    and ``r_corner`` that of the farthest image corner."""
    width, height = camera.resolution
    x = np.arange(width) - camera.cx
    y = np.arange(height) - camera.cy
    squared = x[None, :] ** 2 + y[:, None] ** 2
    corners = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [-0.5, height - 0.5], [width - 0.5, height - 0.5]])
    corner_squared = np.max(np.sum((corners - [camera.cx, camera.cy]) ** 2, axis=1))
    return 1.0 - vignetting * squared / corner_squared


class SensorNoise:
    """Step 5: Gaussian sensor noise and rounding to ``uint8``.

    By default the noise of a frame is the sum of crops, at random offsets, of two
    fields drawn once (drawing 2 million normal numbers per 1080p frame would cost
    more than the rest of the frame); ``fresh`` draws every frame anew.
    """

    def __init__(self, std: float, shape: tuple[int, int], rng: np.random.Generator, fresh: bool = False) -> None:
        if std < 0:
            raise ValueError(f"noise standard deviation must be >= 0, got {std}")
        self.std = float(std)
        self.shape = tuple(shape)
        self.rng = rng
        self.fresh = fresh
        self.fields: list[np.ndarray] = []
        if self.std > 0 and not fresh:
            height, width = self.shape
            size = (height + NOISE_OFFSET_RANGE_PX, width + NOISE_OFFSET_RANGE_PX)
            self.fields = [rng.standard_normal(size, dtype=np.float32) for _ in range(2)]

    def quantise(self, encoded: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """``uint8`` frame: ``255 * scale * encoded`` plus noise, rounded and clipped to
        0-255 (values beyond full scale saturate)."""
        import cv2

        if self.std == 0:
            # Encoded values are never negative, so the absolute value changes nothing.
            return cv2.convertScaleAbs(encoded, alpha=255.0 * scale)
        return cv2.addWeighted(encoded, 255.0 * scale, self._noise(), 1.0, 0.0, dtype=cv2.CV_8U)

    def _noise(self) -> np.ndarray:
        import cv2

        if self.fresh:
            return self.rng.standard_normal(self.shape, dtype=np.float32) * np.float32(self.std)
        height, width = self.shape
        (y1, x1), (y2, x2) = self.rng.integers(0, NOISE_OFFSET_RANGE_PX, size=(2, 2))
        first = self.fields[0][y1:y1 + height, x1:x1 + width]
        second = self.fields[1][y2:y2 + height, x2:x2 + width]
        weight = self.std / np.sqrt(2.0)
        return cv2.addWeighted(first, weight, second, weight, 0.0)


class ExposureControl:
    """The gain of a camera with automatic exposure (``AutoExposure``), frame by frame.

    After each frame the gain moves towards the one that would bring the frame's mean
    encoded level to the target, by the share ``1 - exp(-frame_time / time_constant)``
    (in log gain), within the limits. Without automatic exposure the gain stays 1.
    """

    def __init__(self, settings: Any, fps: float, gamma: float) -> None:
        self.settings = settings
        self.gamma = gamma
        self.gain = 1.0 if settings is None else settings.initial_gain
        self.step = 0.0 if settings is None else 1.0 - math.exp(-1.0 / (fps * settings.time_constant_s))

    @property
    def encoded_scale(self) -> float:
        """Factor of the encoded values: the gain through the display gamma."""
        return self.gain ** (1.0 / self.gamma)

    def meter(self, frame: np.ndarray) -> None:
        """Adjust the gain after ``frame`` (``uint8``), metered on a sparse grid."""
        if self.settings is None:
            return
        mean = max(float(frame[::4, ::4].mean()) / 255.0, 1e-3)
        wanted = (self.settings.target / mean) ** self.gamma
        gain = self.gain * wanted**self.step
        self.gain = min(max(gain, self.settings.min_gain), self.settings.max_gain)
