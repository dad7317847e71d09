"""Synthetic views of a ChArUco board through a lens that distorts: the lens calibration's test bed.

A pinhole camera (matrix K) with OpenCV's distortion model sees the board held at several poses
(rotation and translation of the board's frame in the camera's: x right, y down the page, z away
from the camera). Each view is rendered as an ideal pinhole image (the board warped by
K [r1 r2 t]), then bent by the lens: every output pixel takes the ideal image at the point the lens
maps it from (``cv2.undistortPoints`` of the pixel grid). Blur and noise come last, from a seeded
generator.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelhost.vision.calibration import CharucoSpec, Lens, undistort_points

__all__ = ["default_board_poses", "lens_views"]

FloatArray = NDArray[np.float64]


def default_board_poses(spec: CharucoSpec, distance_m: float = 1.1
                        ) -> list[tuple[FloatArray, FloatArray]]:
    """Eight poses of the board: tilted about both axes, spread over the image.

    Returns
    -------
    list of (rvec, tvec)
        Rodrigues rotation vectors and translations of the board's origin, metres.
    """
    w = spec.square_m * spec.squares[0]
    h = spec.square_m * spec.squares[1]
    poses = []
    tilts = [(0.35, 0.0), (-0.35, 0.0), (0.0, 0.35), (0.0, -0.35),
             (0.3, 0.3), (-0.3, 0.3), (0.3, -0.3), (-0.3, -0.3)]
    shifts = [(-0.55, -0.3), (0.55, -0.3), (-0.55, 0.3), (0.55, 0.3),
              (0.0, 0.0), (-0.6, 0.0), (0.6, 0.0), (0.0, 0.3)]
    for (ax, ay), (sx, sy) in zip(tilts, shifts, strict=True):
        rvec = np.array([ax, ay, 0.1 * ax])
        rot, _ = cv2.Rodrigues(rvec)
        centre = np.array([sx, sy, distance_m])
        tvec = centre - rot @ np.array([w / 2, h / 2, 0.0])  # the board's centre at ``centre``
        poses.append((rvec, tvec))
    return poses


def lens_views(
    spec: CharucoSpec,
    lens: Lens,
    image_size_px: tuple[int, int] = (1280, 720),
    poses: Sequence[tuple[ArrayLike, ArrayLike]] | None = None,
    blur_sigma_px: float = 0.7,
    noise_sigma: float = 2.0,
    seed: int = 0,
) -> list[NDArray[np.uint8]]:
    """Render the board at each pose through the lens.

    Parameters
    ----------
    spec : CharucoSpec
        The board.
    lens : Lens
        The camera matrix and distortion coefficients (``rms_px`` and ``views`` unused).
    image_size_px : (int, int)
        Width and height.
    poses : sequence of (rvec, tvec), optional
        Board poses in the camera frame (default :func:`default_board_poses`).
    blur_sigma_px, noise_sigma : float
        Gaussian blur (pixels) and noise (grey levels).
    seed : int
        Seed of the noise.

    Returns
    -------
    list of ndarray, uint8, (H, W)
        Grey frames.
    """
    w, h = image_size_px
    k = lens.camera_matrix
    tex = spec.image(dpi=60.0).astype(np.float32)
    m_per_texel = spec.square_m * spec.squares[0] / tex.shape[1]
    texel = np.array([[m_per_texel, 0, 0.5 * m_per_texel], [0, m_per_texel, 0.5 * m_per_texel],
                      [0, 0, 1.0]])
    # Where each output pixel's light comes from in the ideal image.
    grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), axis=-1).reshape(-1, 1, 2)
    ideal = undistort_points(grid, k, lens.distortion).reshape(h, w, 2).astype(np.float32)
    rng = np.random.default_rng(seed)
    views = []
    for rvec, tvec in poses if poses is not None else default_board_poses(spec):
        rot, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float))
        plane_to_px = k @ np.c_[rot[:, 0], rot[:, 1], np.asarray(tvec, dtype=float)]
        s = 2  # render at twice the resolution, then average down
        up = np.diag([s, s, 1.0]) @ np.array([[1, 0, 0.5], [0, 1, 0.5], [0, 0, 1.0]])
        to_super = np.array([[1, 0, -0.5], [0, 1, -0.5], [0, 0, 1.0]]) @ up
        board = cv2.warpPerspective(tex, to_super @ plane_to_px @ texel, (w * s, h * s),
                                    flags=cv2.INTER_LINEAR, borderValue=150.0)
        pinhole = cv2.resize(board, (w, h), interpolation=cv2.INTER_AREA)
        frame = cv2.remap(pinhole, ideal[..., 0], ideal[..., 1], cv2.INTER_LINEAR,
                          borderValue=150.0)
        if blur_sigma_px > 0:
            frame = cv2.GaussianBlur(frame, (0, 0), blur_sigma_px)
        noisy = np.asarray(frame, np.float32) + noise_sigma * rng.standard_normal(
            (h, w), dtype=np.float32)
        views.append(np.clip(noisy, 0, 255).astype(np.uint8))
    return views
