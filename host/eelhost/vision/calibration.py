"""Pixels <-> metres on the markers' plane: a homography, from tank corners or a ChArUco board.

The overhead camera sees the robot's marker plates on one horizontal plane, so a plane-to-plane
homography H maps world metres (x, y on that plane, y to the left of x as seen from above) to pixel
coordinates (OpenCV's convention: the centre of pixel (row r, column c) is at (c, r)). A lens
that bends straight lines is calibrated apart (:func:`calibrate_lens`: OpenCV's camera
calibration on a ChArUco board shown at several poses); the homography then maps to undistorted
pixels, and :meth:`Calibration.to_px` and :meth:`Calibration.to_m` add and remove the distortion.

Two ways to get H:

- **Tank corners**: the pixels of the tank's four corners (clicked in an image, or known) and their
  world coordinates (by default a rectangle of the tank's length and width with the origin at the
  first corner). The corners are usually on the rim, not at the markers' height; give the camera's
  height above the corners' plane and the markers' height relative to it, and H is corrected by
  the exact pinhole scaling about the point under the camera.
- **ChArUco board** floated (or held) at the markers' height: the board's corners are detected to
  a tenth of a pixel and H is fitted to all of them. Accurate over the board; extrapolation far
  beyond it is not, so use a board that covers much of the tank, or the tank corners.

A calibration is saved as JSON (``format: eelbot-camera-calibration``, ``version: 1``, an optional
``lens``); loading checks every key and names the file and the key when something is wrong.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelhost.errors import UserError
from eelhost.files import atomic_write

FloatArray = NDArray[np.float64]
FORMAT = "eelbot-camera-calibration"
VERSION = 1


class CalibrationError(UserError, ValueError):
    """A calibration that cannot be made from what was given (corners, heights, a board's frame)."""


class CalibrationFileError(CalibrationError):
    """A calibration file that cannot be used; the message names the file and the key."""


class FrameSizeError(CalibrationError):
    """Frames of another size than the calibration's: its pixels are not the camera's pixels."""


UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)


def undistort_points(points_px: ArrayLike, camera_matrix: ArrayLike, distortion: ArrayLike
                     ) -> FloatArray:
    """Where a lens's pixels (N, 1, 2) would be in an ideal pinhole camera with the same matrix.

    OpenCV's iterative undistortion run to convergence (its default stops after 5 iterations,
    short of it near the corners of a wide lens); OpenCV 4 names it ``undistortPointsIter``,
    OpenCV 5 gives ``undistortPoints`` the criteria.
    """
    src = np.asarray(points_px, dtype=np.float64)
    k = np.asarray(camera_matrix, dtype=np.float64)
    d = np.asarray(distortion, dtype=np.float64)
    if hasattr(cv2, "undistortPointsIter"):
        out = cv2.undistortPointsIter(src, k, d, None, k, UNDISTORT_CRITERIA)
    else:
        out = cv2.undistortPoints(src, k, d, R=None, P=k, criteria=UNDISTORT_CRITERIA)
    return np.asarray(out, dtype=float)


@dataclass(frozen=True)
class Lens:
    """A camera's lens: its pinhole matrix and OpenCV distortion coefficients.

    Attributes
    ----------
    camera_matrix : ndarray, shape (3, 3)
        Focal lengths and principal point, pixels.
    distortion : ndarray, shape (K,)
        OpenCV's coefficients (k1, k2, p1, p2, k3, ...).
    rms_px : float
        RMS reprojection error of the board corners in the views it was fitted to.
    views : int
        Board views it was fitted to.
    """

    camera_matrix: FloatArray
    distortion: FloatArray
    rms_px: float
    views: int

    def undistort(self, xy_px: ArrayLike) -> FloatArray:
        """Pixels of the camera's frames (..., 2) to where an ideal pinhole camera sees them."""
        p = np.asarray(xy_px, dtype=float)
        out = undistort_points(p.reshape(-1, 1, 2), self.camera_matrix, self.distortion)
        return out.reshape(p.shape)

    def distort(self, xy_px: ArrayLike) -> FloatArray:
        """Ideal pinhole pixels (..., 2) to where the camera's lens puts them."""
        p = np.asarray(xy_px, dtype=float)
        flat = p.reshape(-1, 2)
        k_inv = np.linalg.inv(self.camera_matrix)
        rays = np.c_[flat, np.ones(len(flat))] @ k_inv.T
        out, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                   self.camera_matrix, self.distortion)
        return np.asarray(out, dtype=float).reshape(p.shape)


@dataclass(frozen=True)
class Calibration:
    """A metres <-> pixels homography on the markers' plane.

    Attributes
    ----------
    homography_m_to_px : ndarray, shape (3, 3)
        Maps homogeneous world metres to homogeneous pixels.
    image_size_px : (int, int)
        Width and height of the frames it applies to.
    method : str
        ``"tank_corners"`` or ``"charuco"``.
    points_m, points_px : ndarray, shape (K, 2)
        The correspondences it was fitted to (metres on the markers' plane, pixels).
    rms_reprojection_px : float
        RMS distance between ``points_px`` and the mapped ``points_m``.
    lens : Lens or None
        The lens distortion, when it was calibrated: the homography then maps to undistorted
        pixels, and :meth:`to_px` and :meth:`to_m` apply and remove the distortion.
    """

    homography_m_to_px: FloatArray
    image_size_px: tuple[int, int]
    method: str
    points_m: FloatArray
    points_px: FloatArray
    rms_reprojection_px: float
    lens: Lens | None = None
    source: str = field(default="calibration", compare=False)  # its file, for messages

    def check_frame(self, frame: NDArray[np.generic], where: str = "the camera") -> None:
        """Refuse a frame of another size than :attr:`image_size_px`.

        A homography fitted on 640x360 frames maps metres to pixels of those frames: on
        1280x720 frames it puts the robot metres away from where it is (measured: (1.57, -1.58) m
        for (0.08, 0) m), so no pose is made from such a frame (docs/vision.md).

        Raises
        ------
        FrameSizeError
            Naming the calibration, both sizes and where the frame came from.
        """
        height, width = frame.shape[:2]
        want_w, want_h = self.image_size_px
        if (width, height) != (want_w, want_h):
            raise FrameSizeError(
                f"{self.source}: made for {want_w}x{want_h} px frames, but {where} gives "
                f"{width}x{height} px frames; calibrate at this size (eelbot calibrate) or set "
                f"the camera to {want_w}x{want_h}"
            )

    def to_px(self, xy_m: ArrayLike) -> FloatArray:
        """Map world points (..., 2) in metres to pixels (..., 2) of the camera's frames."""
        ideal = _apply(self.homography_m_to_px, xy_m)
        return ideal if self.lens is None else self.lens.distort(ideal)

    def to_m(self, xy_px: ArrayLike) -> FloatArray:
        """Map pixels (..., 2) to world points (..., 2) in metres on the markers' plane."""
        ideal = xy_px if self.lens is None else self.lens.undistort(xy_px)
        return _apply(np.linalg.inv(self.homography_m_to_px), ideal)

    @property
    def rms_reprojection_m(self) -> float:
        """RMS distance on the markers' plane between ``points_m`` and the mapped ``points_px``."""
        err = self.to_m(self.points_px) - self.points_m
        return float(np.sqrt(np.mean(np.sum(err**2, axis=1))))

    def errors(self, points_m: ArrayLike, points_px: ArrayLike) -> tuple[float, float]:
        """RMS error of this calibration on correspondences it was not fitted to.

        Parameters
        ----------
        points_m, points_px : array, shape (K, 2)
            World points and where they were found in a frame.

        Returns
        -------
        (float, float)
            RMS distance in pixels (world points mapped into the image) and in metres (pixels
            mapped onto the markers' plane).
        """
        wm = np.asarray(points_m, dtype=float).reshape(-1, 2)
        px = np.asarray(points_px, dtype=float).reshape(-1, 2)
        e_px = self.to_px(wm) - px
        e_m = self.to_m(px) - wm
        return (float(np.sqrt(np.mean(np.sum(e_px**2, axis=1)))),
                float(np.sqrt(np.mean(np.sum(e_m**2, axis=1)))))

    def pixel_size_m(self, xy_m: ArrayLike) -> float:
        """Mean size of a pixel (m) near the world point ``xy_m`` (square root of the area)."""
        p = np.asarray(xy_m, dtype=float)
        d = 1e-3
        j = np.stack([self.to_px(p + [d, 0]) - self.to_px(p - [d, 0]),
                      self.to_px(p + [0, d]) - self.to_px(p - [0, d])], axis=1) / (2 * d)
        return 1.0 / math.sqrt(abs(np.linalg.det(j)))


def _apply(h: ArrayLike, xy: ArrayLike) -> FloatArray:
    h = np.asarray(h, dtype=float)
    p = np.asarray(xy, dtype=float)
    flat = p.reshape(-1, 2)
    q = np.c_[flat, np.ones(len(flat))] @ h.T
    return (q[:, :2] / q[:, 2:3]).reshape(p.shape)


def _four_point_homography(src: FloatArray, dst: FloatArray) -> FloatArray:
    # The exact homography through four correspondences, in double precision (OpenCV's
    # getPerspectiveTransform takes float32 points, which costs 1e-5 px).
    a = np.zeros((8, 8))
    b = np.zeros(8)
    for k, ((x, y), (u, v)) in enumerate(zip(src, dst, strict=True)):
        a[2 * k] = [x, y, 1, 0, 0, 0, -u * x, -u * y]
        a[2 * k + 1] = [0, 0, 0, x, y, 1, -v * x, -v * y]
        b[2 * k], b[2 * k + 1] = u, v
    try:
        h = np.linalg.solve(a, b)
    except np.linalg.LinAlgError:
        raise CalibrationError("the four corners are degenerate (three on a line?)") from None
    return np.append(h, 1.0).reshape(3, 3)


def height_scaling(camera_height_m: float, marker_height_m: float, nadir_m: ArrayLike) -> FloatArray:
    """Homography taking points on the markers' plane to where they appear on the reference plane.

    A point at height ``marker_height_m`` above the reference plane, seen from a camera
    ``camera_height_m`` above it, projects onto the reference plane along the ray through the
    camera: scaled by k = Zc / (Zc - dz) about the point under the camera (the nadir).

    Parameters
    ----------
    camera_height_m : float
        Height of the camera's optical centre above the reference plane.
    marker_height_m : float
        Height of the markers above the reference plane (negative if below).
    nadir_m : (float, float)
        World point directly under the camera.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    if not camera_height_m > marker_height_m:
        raise CalibrationError("the camera must be above the markers")
    k = camera_height_m / (camera_height_m - marker_height_m)
    n = np.asarray(nadir_m, dtype=float)
    return np.array([[k, 0, (1 - k) * n[0]], [0, k, (1 - k) * n[1]], [0, 0, 1.0]])


def from_tank_corners(
    corners_px: ArrayLike,
    image_size_px: tuple[int, int],
    tank_size_m: tuple[float, float] | None = None,
    corners_m: ArrayLike | None = None,
    camera_height_m: float | None = None,
    marker_height_m: float = 0.0,
    nadir_m: ArrayLike | None = None,
    lens: Lens | None = None,
) -> Calibration:
    """Calibrate from the four tank corners.

    Parameters
    ----------
    corners_px : array, shape (4, 2)
        Pixel coordinates of the corners, in the order of ``corners_m``.
    image_size_px : (int, int)
        Frame width and height.
    tank_size_m : (float, float), optional
        Tank length (along x) and width (along y); the corners are then (0, 0), (L, 0), (L, W),
        (0, W): first corner the origin, x along the first side, y along the last.
    corners_m : array, shape (4, 2), optional
        World coordinates of the corners (instead of ``tank_size_m``).
    camera_height_m : float, optional
        Camera height above the corners' plane; with ``marker_height_m`` corrects H to the
        markers' height. None: the corners are taken to be at the markers' height.
    marker_height_m : float
        Markers' height above the corners' plane (negative when below the rim).
    nadir_m : (float, float), optional
        World point under the camera; default: the point seen at the image centre.
    lens : Lens, optional
        The lens distortion (the corners are undistorted before the fit).

    Returns
    -------
    Calibration
    """
    px = np.asarray(corners_px, dtype=float).reshape(-1, 2)
    if corners_m is None:
        if tank_size_m is None:
            raise CalibrationError("give tank_size_m or corners_m")
        length, width = tank_size_m
        corners_m = [(0.0, 0.0), (length, 0.0), (length, width), (0.0, width)]
    wm = np.asarray(corners_m, dtype=float).reshape(-1, 2)
    if px.shape != (4, 2) or wm.shape != (4, 2):
        raise CalibrationError("need exactly four corners in pixels and in metres")
    ideal = px if lens is None else lens.undistort(px)
    h = _four_point_homography(wm, ideal)
    if camera_height_m is not None and marker_height_m != 0.0:
        if nadir_m is None:
            centre = np.array(image_size_px, dtype=float) / 2 - 0.5
            nadir_m = _apply(np.linalg.inv(h), centre if lens is None else lens.undistort(centre))
        h = h @ height_scaling(camera_height_m, marker_height_m, nadir_m)
        wm = _apply(np.linalg.inv(h), ideal)  # the corners' rays, where they cross the markers' plane
    width_px, height_px = image_size_px
    return _fitted(h, (width_px, height_px), "tank_corners", wm, px, lens)


def _fitted(h: FloatArray, size: tuple[int, int], method: str, points_m: FloatArray,
            points_px: FloatArray, lens: Lens | None) -> Calibration:
    """A calibration with its reprojection error over the points it was fitted to."""
    cal = Calibration(h / h[2, 2], size, method, points_m, points_px, 0.0, lens)
    rms = cal.errors(points_m, points_px)[0]
    return Calibration(cal.homography_m_to_px, size, method, points_m, points_px, rms, lens)


@dataclass(frozen=True)
class CharucoSpec:
    """A ChArUco board.

    The default (7 x 5 squares of 0.11 m, 0.08 m markers of ``DICT_4X4_50`` ids 10 to 26, clear of
    the robot's ids 0 to 5) fits on A1 paper and its markers span about 21 px at 3.8 mm/px.

    Attributes
    ----------
    squares : (int, int)
        Squares along x and y.
    square_m, marker_m : float
        Side of a chessboard square and of the marker inside a white square.
    dictionary_name : str
        Predefined ArUco dictionary.
    first_id : int
        Id of the board's first marker.
    """

    squares: tuple[int, int] = (7, 5)
    square_m: float = 0.11
    marker_m: float = 0.08
    dictionary_name: str = "DICT_4X4_50"
    first_id: int = 10

    def __post_init__(self) -> None:
        if len(self.squares) != 2 or min(self.squares) < 2:
            raise CalibrationError(f"ChArUco board: need at least 2 x 2 squares, got {self.squares}")
        if not 0 < self.marker_m < self.square_m:
            raise CalibrationError(
                f"ChArUco board: the marker ({self.marker_m} m) must be smaller than the square "
                f"({self.square_m} m)"
            )
        if not hasattr(cv2.aruco, self.dictionary_name):
            raise CalibrationError(f"ChArUco board: unknown ArUco dictionary {self.dictionary_name!r}")
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary_name))
        last = self.first_id + self.squares[0] * self.squares[1] // 2 - 1
        if self.first_id < 0 or last >= dictionary.bytesList.shape[0]:
            raise CalibrationError(
                f"ChArUco board: ids {self.first_id}..{last} do not fit {self.dictionary_name}"
            )

    def board(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV board object."""
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary_name))
        n_markers = self.squares[0] * self.squares[1] // 2
        ids = np.arange(self.first_id, self.first_id + n_markers, dtype=np.int32)
        return cv2.aruco.CharucoBoard(self.squares, self.square_m, self.marker_m, dictionary, ids)

    def image(self, dpi: float = 150.0) -> NDArray[np.uint8]:
        """The board as a printable grey image at ``dpi`` (print at 100 %)."""
        dots_per_m = dpi / 0.0254
        size = (int(round(self.squares[0] * self.square_m * dots_per_m)),
                int(round(self.squares[1] * self.square_m * dots_per_m)))
        return np.asarray(self.board().generateImage(size, marginSize=0, borderBits=1), np.uint8)


def charuco_points(
    frame: NDArray[np.uint8],
    spec: CharucoSpec | None = None,
    board_origin_m: tuple[float, float] = (0.0, 0.0),
    board_angle_rad: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """The ChArUco board's corners found in a frame: world metres and pixels.

    The board's own frame has its origin at the outer corner of its first square, x along the
    squares' rows and y across them, as the board lies face up (its printed image's top-left
    corner at the origin, printed rows running down the page towards -y); ``board_origin_m`` and
    ``board_angle_rad`` place it in the world.

    Parameters
    ----------
    frame : ndarray
        Grey or BGR image.
    spec : CharucoSpec, optional
        The board (default :class:`CharucoSpec`).
    board_origin_m : (float, float)
        World position of the board's origin.
    board_angle_rad : float
        World angle of the board's x axis.

    Returns
    -------
    points_m, points_px : ndarray, shape (K, 2)

    Raises
    ------
    CalibrationError
        When fewer than 8 board corners are found.
    """
    spec = spec or CharucoSpec()
    board = spec.board()
    grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(board).detectBoard(grey)
    if ids is None or len(ids) < 8:
        found = 0 if ids is None else len(ids)
        raise CalibrationError(f"ChArUco board: found {found} corners, need at least 8")
    ids = np.asarray(ids).ravel()
    px = np.asarray(corners, dtype=float).reshape(-1, 2)
    # Board object points: x right along the printed image, y down the page; face up, seen from
    # above, the page's "down" is the world's -y.
    obj = np.asarray(board.getChessboardCorners(), dtype=float)[ids, :2] * [1.0, -1.0]
    c, s = math.cos(board_angle_rad), math.sin(board_angle_rad)
    wm = obj @ np.array([[c, s], [-s, c]]) + np.asarray(board_origin_m, dtype=float)
    return wm, px


def from_charuco(
    frame: NDArray[np.uint8],
    spec: CharucoSpec | None = None,
    board_origin_m: tuple[float, float] = (0.0, 0.0),
    board_angle_rad: float = 0.0,
    lens: Lens | None = None,
) -> Calibration:
    """Calibrate from one frame showing a ChArUco board at the markers' height.

    Parameters
    ----------
    frame : ndarray
        Grey or BGR image.
    spec : CharucoSpec, optional
        The board (default :class:`CharucoSpec`).
    board_origin_m : (float, float)
        World position of the board's origin (see :func:`charuco_points`).
    board_angle_rad : float
        World angle of the board's x axis.
    lens : Lens, optional
        The lens distortion (the corners are undistorted before the fit).

    Returns
    -------
    Calibration

    Raises
    ------
    CalibrationError
        When fewer than 8 board corners are found.
    """
    wm, px = charuco_points(frame, spec, board_origin_m, board_angle_rad)
    ideal = px if lens is None else lens.undistort(px)
    h, _ = cv2.findHomography(wm, ideal, 0)
    return _fitted(np.asarray(h, dtype=float), (frame.shape[1], frame.shape[0]), "charuco", wm,
                   px, lens)


def calibrate_lens(
    frames: Iterable[NDArray[np.uint8]], spec: CharucoSpec | None = None, min_views: int = 4
) -> Lens:
    """Fit the lens (pinhole matrix and distortion) to views of a ChArUco board at several poses.

    OpenCV's camera calibration (``cv2.calibrateCamera``, radial k1, k2 and tangential p1, p2; k3
    fixed at 0) on the board corners of every view in which at least 8 were found. The board must be seen tilted in different directions and over
    the whole image, or the focal length and the distortion cannot be told apart.

    Parameters
    ----------
    frames : iterable of ndarray
        Grey or BGR images, all of one size.
    spec : CharucoSpec, optional
        The board (default :class:`CharucoSpec`).
    min_views : int
        Fewest views with the board found.

    Returns
    -------
    Lens

    Raises
    ------
    CalibrationError
        Too few views showed the board, or the images differ in size.
    """
    spec = spec or CharucoSpec()
    board = spec.board()
    detector = cv2.aruco.CharucoDetector(board)
    obj_points, img_points = [], []
    size: tuple[int, int] | None = None
    seen = 0
    for frame in frames:
        seen += 1
        grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        this = (grey.shape[1], grey.shape[0])
        if size is not None and this != size:
            raise CalibrationError(f"lens views differ in size: {size} and {this}")
        size = this
        corners, ids, _, _ = detector.detectBoard(grey)
        if ids is None or len(ids) < 8:
            continue
        obj, img = board.matchImagePoints(cast(Any, corners), ids)
        obj_points.append(np.asarray(obj, np.float32))
        img_points.append(np.asarray(img, np.float32))
    if size is None or len(obj_points) < min_views:
        raise CalibrationError(
            f"lens calibration: the board was found in {len(obj_points)} of {seen} views, "
            f"need at least {min_views} (tilted differently, over the whole image)"
        )
    # k3 fixed at 0 (OpenCV's advice for all but very wide lenses): with it free, k2 and k3 trade
    # off against each other and the fit extrapolates badly where the board was not shown.
    rms, k, dist, _, _ = cv2.calibrateCamera(obj_points, img_points, size, None, None,
                                             flags=cv2.CALIB_FIX_K3)
    return Lens(np.asarray(k, dtype=float), np.asarray(dist, dtype=float).ravel(), float(rms),
                len(obj_points))


def save_calibration(calibration: Calibration, path: str | Path) -> Path:
    """Write ``calibration`` as JSON (whole: a temporary file renamed into place); return the path."""
    out = Path(path)
    data = {
        "format": FORMAT,
        "version": VERSION,
        "method": calibration.method,
        "image_size_px": list(calibration.image_size_px),
        "homography_m_to_px": calibration.homography_m_to_px.tolist(),
        "points_m": calibration.points_m.tolist(),
        "points_px": calibration.points_px.tolist(),
        "rms_reprojection_px": calibration.rms_reprojection_px,
    }
    if calibration.lens is not None:
        lens = calibration.lens
        data["lens"] = {
            "camera_matrix": lens.camera_matrix.tolist(),
            "distortion": lens.distortion.tolist(),
            "rms_px": lens.rms_px,
            "views": lens.views,
        }
    return atomic_write(out, json.dumps(data, indent=2) + "\n")  # whole (eelhost.files)


def _all_numbers(value: Any) -> bool:
    """Whether a nested list holds only JSON numbers (not strings, not true/false)."""
    if isinstance(value, list):
        return all(_all_numbers(v) for v in value)
    return isinstance(value, int | float) and not isinstance(value, bool)


def _matrix(data: dict[str, Any], key: str, shape: tuple[int | None, int], source: str) -> FloatArray:
    if key not in data:
        raise CalibrationFileError(f"{source}: missing key '{key}'")
    try:
        if not _all_numbers(data[key]):  # numpy would read "1.5" and true as numbers
            raise TypeError
        m = np.asarray(data[key], dtype=float)
    except (TypeError, ValueError):
        raise CalibrationFileError(f"{source}: '{key}' must be an array of numbers") from None
    if m.ndim != 2 or m.shape[1] != shape[1] or (shape[0] is not None and m.shape[0] != shape[0]):
        want = f"{shape[0] if shape[0] is not None else 'K'} x {shape[1]}"
        raise CalibrationFileError(f"{source}: '{key}' must be {want}, got shape {m.shape}")
    if not np.all(np.isfinite(m)):
        raise CalibrationFileError(f"{source}: '{key}' has a non-finite number")
    return m


def load_calibration(path: str | Path) -> Calibration:
    """Read a calibration JSON file.

    Raises
    ------
    CalibrationFileError
        When the file cannot be read, is not JSON, or a key is missing, unknown or malformed;
        the message names the file and the key.
    """
    source = str(path)
    try:
        data = json.loads(Path(path).read_text())
    except OSError as err:
        raise CalibrationFileError(f"{source}: cannot read calibration file: {err.strerror}") from None
    except json.JSONDecodeError as err:
        raise CalibrationFileError(f"{source}: not valid JSON: {err}") from None
    if not isinstance(data, dict):
        raise CalibrationFileError(f"{source}: expected a JSON object at the top level")
    known = {"format", "version", "method", "image_size_px", "homography_m_to_px", "points_m",
             "points_px", "rms_reprojection_px", "lens"}
    for key in data:
        if key not in known:
            raise CalibrationFileError(f"{source}: unknown key '{key}'")
    if data.get("format") != FORMAT:
        raise CalibrationFileError(f"{source}: 'format' must be {FORMAT!r}, got {data.get('format')!r}")
    if data.get("version") != VERSION:
        raise CalibrationFileError(f"{source}: 'version' must be {VERSION}, got {data.get('version')!r}")
    method = data.get("method")
    if method not in ("tank_corners", "charuco"):
        raise CalibrationFileError(f"{source}: 'method' must be 'tank_corners' or 'charuco', got {method!r}")
    size = data.get("image_size_px")
    if not (isinstance(size, list) and len(size) == 2 and all(
        isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in size)):
        raise CalibrationFileError(f"{source}: 'image_size_px' must be [width, height], got {size!r}")
    h = _matrix(data, "homography_m_to_px", (3, 3), source)
    if abs(np.linalg.det(h)) < 1e-12:
        raise CalibrationFileError(f"{source}: 'homography_m_to_px' is singular")
    points_m = _matrix(data, "points_m", (None, 2), source)
    points_px = _matrix(data, "points_px", (None, 2), source)
    if len(points_m) != len(points_px):
        raise CalibrationFileError(f"{source}: 'points_m' and 'points_px' differ in length")
    rms = data.get("rms_reprojection_px")
    if not isinstance(rms, int | float) or isinstance(rms, bool) or not math.isfinite(rms) or rms < 0:
        raise CalibrationFileError(f"{source}: 'rms_reprojection_px' must be a number >= 0")
    lens = _load_lens(data["lens"], source) if "lens" in data else None
    return Calibration(h / h[2, 2], (size[0], size[1]), method, points_m, points_px, float(rms),
                       lens, source)


def _load_lens(data: Any, source: str) -> Lens:
    if not isinstance(data, dict):
        raise CalibrationFileError(f"{source}: 'lens' must be an object")
    for key in data:
        if key not in ("camera_matrix", "distortion", "rms_px", "views"):
            raise CalibrationFileError(f"{source}: unknown key 'lens.{key}'")
    k = _matrix(data, "camera_matrix", (3, 3), f"{source}: lens")
    try:
        dist = np.asarray(data.get("distortion"), dtype=float)
    except (TypeError, ValueError):
        dist = np.zeros((0, 0))
    if dist.ndim != 1 or len(dist) not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(dist)):
        raise CalibrationFileError(f"{source}: 'lens.distortion' must be 4, 5, 8, 12 or 14 "
                                   f"finite numbers, got {data.get('distortion')!r}")
    rms, views = data.get("rms_px"), data.get("views")
    if not isinstance(rms, int | float) or not math.isfinite(rms) or rms < 0:
        raise CalibrationFileError(f"{source}: 'lens.rms_px' must be a number >= 0")
    if not isinstance(views, int) or views < 1:
        raise CalibrationFileError(f"{source}: 'lens.views' must be a positive integer")
    return Lens(k, dist, float(rms), views)
