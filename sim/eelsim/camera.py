"""The overhead camera as the controller sees it: 30 fps samples, pixel quantisation, median filter.

The camera's frame period (1/30 s) is not a multiple of the physics step (0.01 s), and it does not
need to be: the camera only observes. A frame between two physics steps sees the pose given by the
cubic Hermite interpolant of the centre of mass and heading, built from their values and rates at
both steps (all part of the state), which is accurate to a few micrometres here, far below a pixel.

Positions are quantised to pixel centres (0.0038 m per pixel in the paper's tank). The heading is
taken as measured (optionally with Gaussian noise). A moving median over the last ``median_window``
frames filters position and (unwrapped) heading.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CameraModel:
    """Camera parameters.

    Attributes
    ----------
    fps : float
        Frame rate.
    pixel_m : float
        Size of a pixel on the water plane; positions are rounded to pixel centres. 0 disables.
    median_window : int
        Length of the moving median filter, in frames (1 disables it).
    heading_noise_rad : float
        Standard deviation of the heading measurement noise.
    """

    fps: float = 30.0
    pixel_m: float = 0.0038
    median_window: int = 5
    heading_noise_rad: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"camera fps must be positive, got {self.fps}")
        if not (np.isfinite(self.pixel_m) and self.pixel_m >= 0):
            raise ValueError(f"camera pixel size must be >= 0, got {self.pixel_m}")
        if self.median_window < 1:
            raise ValueError(f"median window must be at least 1 frame, got {self.median_window}")

    def frame_times(self, duration_s: float) -> np.ndarray:
        """Times of the frames in [0, duration_s]."""
        count = int(np.floor(duration_s * self.fps + 1e-9)) + 1
        return np.arange(count) / self.fps


def quantise_position(position_m: np.ndarray, pixel_m: float) -> np.ndarray:
    """Round positions to the centre of the pixel they fall in (no-op when ``pixel_m`` is 0)."""
    if pixel_m <= 0:
        return np.asarray(position_m, dtype=float)
    return (np.floor(np.asarray(position_m) / pixel_m) + 0.5) * pixel_m


def hermite(y0: np.ndarray, dy0: np.ndarray, y1: np.ndarray, dy1: np.ndarray, h: float, s: float):
    """Cubic Hermite interpolation at fraction ``s`` in [0, 1] of a step of length ``h``."""
    s2, s3 = s * s, s * s * s
    return (
        (2 * s3 - 3 * s2 + 1) * y0
        + (s3 - 2 * s2 + s) * h * dy0
        + (-2 * s3 + 3 * s2) * y1
        + (s3 - s2) * h * dy1
    )


class MedianFilter:
    """Moving median of the last ``window`` pose samples (x, y, unwrapped heading).

    Parameters
    ----------
    window : int
        Number of samples.
    """

    def __init__(self, window: int) -> None:
        self._buf: deque[np.ndarray] = deque(maxlen=window)
        self._last_heading: float | None = None

    def push(self, x_m: float, y_m: float, heading_rad: float) -> np.ndarray:
        """Add a sample and return the filtered (x, y, heading).

        Headings are unwrapped against the previous sample so that the median does not jump
        across +-pi.
        """
        if self._last_heading is not None:
            heading_rad = self._last_heading + float(
                np.angle(np.exp(1j * (heading_rad - self._last_heading)))
            )
        self._last_heading = heading_rad
        self._buf.append(np.array([x_m, y_m, heading_rad]))
        return np.median(np.array(self._buf), axis=0)
