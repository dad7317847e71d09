"""A synthetic overhead camera: frames of the twin with the true pose alongside.

Each frame (1280 x 720 BGR by default) shows the tank floor under an uneven light (a brighter side
and a vignette), the dark tank walls outside it, and the robot: each link as a rounded body (its
top view, 2 l by 2 b), with its marker plate warped onto it through the camera's homography (a
slight keystone, as from a camera not quite overhead). The plates are drawn at four times the
resolution and box-filtered down, so edges fall where the geometry says to a small fraction of a
pixel. Then the camera's faults: Gaussian blur, Gaussian noise, JPEG re-encoding. Randomness comes
from a seeded numpy Generator.

The homography is known exactly, so :meth:`SyntheticCamera.calibration` gives the calibration a
perfect tank-corner click would give, and :class:`TruePose` says where the robot really was.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelhost.vision.calibration import Calibration, CharucoSpec, from_tank_corners
from eelhost.vision.markers import MarkerLayout, default_layout, plate_image
from eelsim.dynamics import link_positions, split_state
from eelsim.model import SwimmerModel
from eelsim.robot import Robot

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TankView:
    """Where the tank is in the world and in the image.

    The default is a 4.6 m x 2.5 m tank at about 3.8 mm per pixel (the paper's camera), world
    x from -1.5 to 3.1 m and y from -1.0 to 1.5 m so that the named scenarios stay in view, and a
    keystone of 8 px (far edge narrower) from a slightly tilted camera.

    Attributes
    ----------
    image_size_px : (int, int)
        Width, height.
    corners_m : tuple of 4 (x, y)
        Tank corners in the world, counter-clockwise seen from above.
    corners_px : tuple of 4 (x, y)
        The same corners in the image.
    """

    image_size_px: tuple[int, int] = (1280, 720)
    corners_m: tuple[tuple[float, float], ...] = ((-1.5, -1.0), (3.1, -1.0), (3.1, 1.5), (-1.5, 1.5))
    corners_px: tuple[tuple[float, float], ...] = (
        (35.0, 689.0), (1245.0, 689.0), (1237.0, 31.0), (43.0, 31.0)
    )

    @classmethod
    def covering(cls, size_m: tuple[float, float], margin_m: float = 0.3,
                 image_size_px: tuple[int, int] = (1280, 720)) -> TankView:
        """A view of a tank ``size_m`` (x from 0, y from 0) with ``margin_m`` around it.

        The scale is the largest that fits the image with a 31 px border, equal in x and y; the
        far edge is 8 px narrower (the default view's keystone). A planning world's tank
        (docs/planning.md) is filmed whole this way, walls included.

        Parameters
        ----------
        size_m : (float, float)
            The tank's width and height, m.
        margin_m : float
            Floor shown beyond each wall, m.
        image_size_px : (int, int)

        Returns
        -------
        TankView
        """
        w, h = size_m
        x0, y0, x1, y1 = -margin_m, -margin_m, w + margin_m, h + margin_m
        iw, ih = image_size_px
        border = 31.0
        scale = min((iw - 2 * border) / (x1 - x0), (ih - 2 * border) / (y1 - y0))
        cx, cy = iw / 2.0, ih / 2.0
        half_x, half_y = (x1 - x0) * scale / 2.0, (y1 - y0) * scale / 2.0
        corners_px = ((cx - half_x, cy + half_y), (cx + half_x, cy + half_y),
                      (cx + half_x - 8.0, cy - half_y), (cx - half_x + 8.0, cy - half_y))
        return cls(image_size_px, ((x0, y0), (x1, y0), (x1, y1), (x0, y1)), corners_px)


@dataclass(frozen=True)
class RenderOptions:
    """The camera's faults and the scene's look.

    Attributes
    ----------
    noise_sigma : float
        Standard deviation of the additive Gaussian noise, grey levels (0..255).
    blur_sigma_px : float
        Gaussian blur (focus, optics), pixels; 0 disables.
    jpeg_quality : int
        JPEG re-encoding quality 1..100; 0 disables.
    light_range : (float, float)
        Illumination gain across the tank, from the dim side to the bright side.
    vignette : float
        Relative darkening at the image corners.
    supersample : int
        Resolution factor at which the robot is drawn before box filtering.
    """

    noise_sigma: float = 3.0
    blur_sigma_px: float = 0.7
    jpeg_quality: int = 80
    light_range: tuple[float, float] = (0.65, 1.05)
    vignette: float = 0.25
    supersample: int = 4


@dataclass(frozen=True)
class TruePose:
    """Where the robot really was in a synthetic frame.

    Attributes
    ----------
    t_s : float
        Time of the frame.
    com_m : ndarray, shape (2,)
        Centre of mass (mean of the link centres).
    heading_rad : float
        Mean link angle (not wrapped).
    link_angles_rad : ndarray, shape (N,)
        Absolute link angles, tail first.
    link_centres_m : ndarray, shape (N, 2)
        Link centres.
    com_px : ndarray, shape (2,)
        The centre of mass in pixels.
    """

    t_s: float
    com_m: FloatArray
    heading_rad: float
    link_angles_rad: FloatArray
    link_centres_m: FloatArray
    com_px: FloatArray


FLOOR_BGR = np.array([205.0, 190.0, 170.0])  # pale blue-grey tank floor
WALL_BGR = np.array([60.0, 55.0, 50.0])
BODY_BGR = np.array([40.0, 110.0, 150.0])  # ochre shell, darker than the plates, lighter than ink


class SyntheticCamera:
    """Renders overhead frames of the twin.

    Parameters
    ----------
    robot : Robot
        The robot (link lengths and widths).
    layout : MarkerLayout, optional
        Marker layout (default: :func:`default_layout`).
    view : TankView, optional
        Tank placement and image size.
    options : RenderOptions, optional
        Noise, blur, JPEG, lighting.
    seed : int
        Seed of the noise generator.
    """

    def __init__(
        self,
        robot: Robot,
        layout: MarkerLayout | None = None,
        view: TankView | None = None,
        options: RenderOptions | None = None,
        seed: int = 0,
    ) -> None:
        self.model = SwimmerModel.from_robot(robot)
        self.layout = layout or default_layout(self.model.n_links)
        if self.layout.n_links != self.model.n_links:
            raise ValueError(f"layout has {self.layout.n_links} markers, robot {self.model.n_links} links")
        self.view = view or TankView()
        self.options = options or RenderOptions()
        self.rng = np.random.default_rng(seed)
        self._calibration = from_tank_corners(
            self.view.corners_px, self.view.image_size_px, corners_m=self.view.corners_m
        )
        self.homography_m_to_px = self._calibration.homography_m_to_px
        cells = self.layout.cells
        self._px_per_cell = 16  # texture finer than the supersampled frame: no aliasing
        self._plates = [
            plate_image(self.layout, i, self._px_per_cell).astype(np.float32)
            for i in range(self.layout.n_links)
        ]
        # The texture spans the plate; its metric size follows from the whole cells drawn.
        self._plate_tex_m = (
            self._plates[0].shape[0] / (cells * self._px_per_cell) * self.layout.marker_size_m
        )
        self._background = self._make_background()

    def calibration(self) -> Calibration:
        """The exact calibration (what perfect tank-corner clicks would give)."""
        return self._calibration

    def _make_background(self) -> NDArray[np.float32]:
        w, h = self.view.image_size_px
        o = self.options
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        gain = o.light_range[0] + (o.light_range[1] - o.light_range[0]) * (xx / (w - 1))
        r2 = ((xx - w / 2) / (w / 2)) ** 2 + ((yy - h / 2) / (h / 2)) ** 2
        self._light = (gain * (1.0 - o.vignette * r2 / 2.0))[..., None].astype(np.float32)
        mask = np.zeros((h, w), np.float32)
        poly = np.round(np.asarray(self.view.corners_px) * 16).astype(np.int32)
        cv2.fillPoly(mask, [poly], 1.0, cv2.LINE_AA, shift=4)
        colour = mask[..., None] * FLOOR_BGR + (1 - mask[..., None]) * WALL_BGR
        return (colour * self._light).astype(np.float32)

    def true_pose(self, state: ArrayLike, t_s: float = 0.0) -> TruePose:
        """The true pose of the twin in ``state``."""
        theta, p, _, _ = split_state(self.model, state)
        x, y = link_positions(self.model, state)
        com = np.asarray(p, dtype=float)
        return TruePose(
            t_s=float(t_s),
            com_m=com,
            heading_rad=float(np.mean(theta)),
            link_angles_rad=np.asarray(theta, dtype=float).copy(),
            link_centres_m=np.c_[x, y],
            com_px=self._calibration.to_px(com),
        )

    def render(self, state: ArrayLike, t_s: float = 0.0) -> tuple[NDArray[np.uint8], TruePose]:
        """Render the twin in ``state`` at time ``t_s``.

        Returns
        -------
        frame : ndarray, uint8, (H, W, 3)
            BGR image.
        pose : TruePose
            Ground truth.
        """
        pose = self.true_pose(state, t_s)
        img = self._background.copy()
        self._draw_bodies(img, pose)
        offsets = self.layout.offsets()
        for i in range(self.model.n_links):
            u = np.array([np.cos(pose.link_angles_rad[i]), np.sin(pose.link_angles_rad[i])])
            centre = pose.link_centres_m[i] + offsets[i] * u
            self._draw_plate(img, i, centre, pose.link_angles_rad[i])
        return self._degrade(img), pose

    def _draw_bodies(self, img: NDArray[np.float32], pose: TruePose) -> None:
        half = self.model.half_length_m
        width = self.model.half_axis_horizontal_m
        arc = np.linspace(-np.pi / 2, np.pi / 2, 9)
        polys = []
        for i in range(self.model.n_links):
            a = pose.link_angles_rad[i]
            u = np.array([np.cos(a), np.sin(a)])
            n = np.array([-u[1], u[0]])
            # Top view of the link: a stadium, straight sides 2 (l - b) long, round ends radius b.
            straight = max(half[i] - width[i], 0.0)
            pts = [straight * u + width[i] * (np.cos(t) * u + np.sin(t) * n) for t in arc]
            pts += [-straight * u + width[i] * (-np.cos(t) * u - np.sin(t) * n) for t in arc]
            polys.append(self._calibration.to_px(pose.link_centres_m[i] + np.array(pts)))
        # Work in the robot's bounding box only: full-frame float passes cost more than the rest.
        w, h = self.view.image_size_px
        allpts = np.concatenate(polys)
        x0, y0 = np.maximum(np.floor(allpts.min(axis=0)).astype(int) - 2, 0)
        x1, y1 = np.minimum(np.ceil(allpts.max(axis=0)).astype(int) + 3, (w, h))
        if x1 <= x0 or y1 <= y0:
            return
        body = np.zeros((y1 - y0, x1 - x0), np.float32)
        for px in polys:
            q = np.round((px - [x0, y0]) * 16).astype(np.int32)
            cv2.fillPoly(body, [q], 1.0, cv2.LINE_AA, shift=4)
        b = body[..., None]
        roi = img[y0:y1, x0:x1]
        roi *= 1 - b
        roi += b * BODY_BGR * self._light[y0:y1, x0:x1]

    def render_board(
        self, spec: CharucoSpec, origin_m: ArrayLike = (0.0, 0.0), angle_rad: float = 0.0
    ) -> NDArray[np.uint8]:
        """A frame of the empty tank with a ChArUco board lying face up on the markers' plane.

        Parameters
        ----------
        spec : CharucoSpec
            The board.
        origin_m : (float, float)
            World position of the board's origin (its printed image's top-left corner).
        angle_rad : float
            World angle of the board's x axis (docs/vision.md, calibration).

        Returns
        -------
        ndarray, uint8, (H, W, 3)
            BGR frame with the camera's faults.
        """
        # Texture finer than the supersampled frame (about 0.5 mm per texel).
        tex = spec.image(dpi=50.8).astype(np.float32)
        k = spec.square_m * spec.squares[0] / tex.shape[1]  # metres per texel
        c, sn = np.cos(angle_rad), np.sin(angle_rad)
        o = np.asarray(origin_m, dtype=float)
        # Texture (column, row) -> world: columns along the board's x, rows down the page (-y).
        tex_to_m = np.array([[c * k, sn * k, o[0]], [sn * k, -c * k, o[1]], [0.0, 0.0, 1.0]])
        w_m, h_m = spec.square_m * spec.squares[0], spec.square_m * spec.squares[1]
        outline = o + np.array([[0, 0], [w_m, 0], [w_m, -h_m], [0, -h_m]]) @ np.array(
            [[c, sn], [-sn, c]])
        img = self._background.copy()
        self._draw_texture(img, tex, tex_to_m, outline)
        return self._degrade(img)

    def _draw_plate(
        self, img: NDArray[np.float32], i: int, centre_m: FloatArray, angle_rad: float
    ) -> None:
        tex = self._plates[i]
        n_tex = tex.shape[0]
        k = self._plate_tex_m / n_tex  # metres per texture pixel
        c, sn = np.cos(angle_rad), np.sin(angle_rad)
        # Texture (column, row) -> world: columns run along the link (towards the head), rows down
        # the printed page, which face up and seen from above is the link's right-hand side.
        tex_to_m = np.array([
            [c * k, sn * k, centre_m[0] - (c + sn) * k * n_tex / 2],
            [sn * k, -c * k, centre_m[1] - (sn - c) * k * n_tex / 2],
            [0.0, 0.0, 1.0],
        ])
        outline = centre_m + self.layout.plate_size_m * 0.75 * np.array(
            [[1, 1], [1, -1], [-1, 1], [-1, -1]])
        self._draw_texture(img, tex, tex_to_m, outline)

    def _draw_texture(
        self, img: NDArray[np.float32], tex: NDArray[np.float32], tex_to_m: FloatArray,
        outline_m: FloatArray,
    ) -> None:
        """Paint a grey texture (0 ink .. 255 paper) lying on the markers' plane into ``img``.

        ``tex_to_m`` maps texel (column, row) corners to world metres; ``outline_m`` bounds it.
        """
        s = self.options.supersample
        tex_to_m = tex_to_m @ np.array([[1, 0, 0.5], [0, 1, 0.5], [0, 0, 1.0]])  # texel centre
        corners = self._calibration.to_px(outline_m)
        w, h = self.view.image_size_px
        x0, y0 = np.floor(corners.min(axis=0)).astype(int) - 2
        x1, y1 = np.ceil(corners.max(axis=0)).astype(int) + 2
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        if x1 <= x0 or y1 <= y0:
            return  # out of view
        # Frame pixel coordinate x maps to supersampled index s (x + 0.5 - x0) - 0.5.
        to_super = np.array([[s, 0, s * (0.5 - x0) - 0.5], [0, s, s * (0.5 - y0) - 0.5], [0, 0, 1.0]])
        m = to_super @ self.homography_m_to_px @ tex_to_m
        size = ((x1 - x0) * s, (y1 - y0) * s)
        ink = cv2.warpPerspective(tex, m, size, flags=cv2.INTER_LINEAR, borderValue=0)
        alpha = cv2.warpPerspective(np.ones_like(tex), m, size, flags=cv2.INTER_LINEAR, borderValue=0)
        ink = cv2.resize(ink, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
        alpha = cv2.resize(alpha, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)[..., None]
        roi = img[y0:y1, x0:x1]
        # Ink is premultiplied by coverage (the border outside the texture warps to 0).
        roi *= 1 - alpha
        roi += (ink[..., None] / 255.0) * np.array([235.0, 235.0, 235.0]) * self._light[y0:y1, x0:x1]

    def _degrade(self, img: NDArray[np.float32]) -> NDArray[np.uint8]:
        o = self.options
        if o.blur_sigma_px > 0:
            img = np.asarray(cv2.GaussianBlur(img, (0, 0), o.blur_sigma_px), np.float32)
        if o.noise_sigma > 0:
            # Luminance noise, one draw per pixel shared by the channels: what the detector sees
            # after grey conversion, at a third of the cost of per-channel noise.
            noise = self.rng.standard_normal(img.shape[:2], dtype=np.float32)
            img += o.noise_sigma * noise[..., None]
        out = np.clip(img, 0, 255).astype(np.uint8)
        if o.jpeg_quality > 0:
            ok, enc = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(o.jpeg_quality)])
            out = np.asarray(cv2.imdecode(enc, cv2.IMREAD_COLOR), np.uint8)
        return out


@dataclass
class SyntheticRun:
    """States of a twin run sampled at camera frame times.

    Attributes
    ----------
    t_s : ndarray, shape (F,)
        Frame times.
    states : ndarray, shape (F, 2 N + 4)
        States at those times (linear interpolation between the twin's 0.01 s steps; the truth
        is computed from these states, so the interpolation is not an error of the vision).
    """

    t_s: FloatArray
    states: FloatArray = field(repr=False)


def sample_run(t_s: ArrayLike, states: ArrayLike, fps: float = 30.0,
               n_frames: int | None = None) -> SyntheticRun:
    """Sample a recorded run (times, states) at ``fps``, optionally the first ``n_frames``.

    Parameters
    ----------
    t_s : array, shape (K,)
        Recorded times.
    states : array, shape (K, S)
        Recorded states.
    fps : float
        Frame rate.
    n_frames : int, optional
        Number of frames (default: as many as the run covers).

    Returns
    -------
    SyntheticRun
    """
    t = np.asarray(t_s, dtype=float)
    x = np.asarray(states, dtype=float)
    count = int(np.floor((t[-1] - t[0]) * fps + 1e-9)) + 1
    if n_frames is not None:
        count = min(count, n_frames)
    frames = t[0] + np.arange(count) / fps
    cols = [np.interp(frames, t, x[:, j]) for j in range(x.shape[1])]
    return SyntheticRun(frames, np.stack(cols, axis=1))
