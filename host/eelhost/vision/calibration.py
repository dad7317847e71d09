"""Pixels <-> metres on the markers' plane: a homography, from tank corners or a ChArUco board.

The overhead camera sees the robot's marker plates on one horizontal plane, so a plane-to-plane
homography H maps world metres (x, y on that plane, y to the left of x as seen from above) to pixel
coordinates (OpenCV's convention: the centre of pixel (row r, column c) is at (c, r)). Lens
distortion is not modelled: undistort the frames first if the lens needs it.

Two ways to get H:

- **Tank corners**: the pixels of the tank's four corners (clicked in an image, or known) and their
  world coordinates (by default a rectangle of the tank's length and width with the origin at the
  first corner). The corners are usually on the rim, not at the markers' height; give the camera's
  height above the corners' plane and the markers' height relative to it, and H is corrected by
  the exact pinhole scaling about the point under the camera.
- **ChArUco board** floated (or held) at the markers' height: the board's corners are detected to
  a tenth of a pixel and H is fitted to all of them. Accurate over the board; extrapolation far
  beyond it is not, so use a board that covers much of the tank, or the tank corners.

A calibration is saved as JSON (``format: eelbot-camera-calibration``, ``version: 1``); loading
checks every key and names the file and the key when something is wrong.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelhost.errors import UserError

FloatArray = NDArray[np.float64]
FORMAT = "eelbot-camera-calibration"
VERSION = 1


class CalibrationError(UserError, ValueError):
    """A calibration that cannot be made from what was given (corners, heights, a board's frame)."""


class CalibrationFileError(CalibrationError):
    """A calibration file that cannot be used; the message names the file and the key."""


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
    """

    homography_m_to_px: FloatArray
    image_size_px: tuple[int, int]
    method: str
    points_m: FloatArray
    points_px: FloatArray
    rms_reprojection_px: float

    def to_px(self, xy_m: ArrayLike) -> FloatArray:
        """Map world points (..., 2) in metres to pixels (..., 2)."""
        return _apply(self.homography_m_to_px, xy_m)

    def to_m(self, xy_px: ArrayLike) -> FloatArray:
        """Map pixels (..., 2) to world points (..., 2) in metres on the markers' plane."""
        return _apply(np.linalg.inv(self.homography_m_to_px), xy_px)

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


def _rms(h: ArrayLike, points_m: FloatArray, points_px: FloatArray) -> float:
    err = _apply(h, points_m) - points_px
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1))))


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
    h = _four_point_homography(wm, px)
    if camera_height_m is not None and marker_height_m != 0.0:
        if nadir_m is None:
            nadir_m = _apply(np.linalg.inv(h), np.array(image_size_px, dtype=float) / 2 - 0.5)
        h = h @ height_scaling(camera_height_m, marker_height_m, nadir_m)
        wm = _apply(np.linalg.inv(h), px)  # the corners' rays, where they cross the markers' plane
    width_px, height_px = image_size_px
    return Calibration(h / h[2, 2], (width_px, height_px), "tank_corners", wm, px, _rms(h, wm, px))


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


def from_charuco(
    frame: NDArray[np.uint8],
    spec: CharucoSpec | None = None,
    board_origin_m: tuple[float, float] = (0.0, 0.0),
    board_angle_rad: float = 0.0,
) -> Calibration:
    """Calibrate from one frame showing a ChArUco board at the markers' height.

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
    Calibration

    Raises
    ------
    ValueError
        When fewer than 8 board corners are found.
    """
    spec = spec or CharucoSpec()
    board = spec.board()
    grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    detector = cv2.aruco.CharucoDetector(board)
    corners, ids, _, _ = detector.detectBoard(grey)
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
    h, _ = cv2.findHomography(wm, px, 0)
    size = (grey.shape[1], grey.shape[0])
    return Calibration(h / h[2, 2], size, "charuco", wm, px, _rms(h, wm, px))


def save_calibration(calibration: Calibration, path: str | Path) -> Path:
    """Write ``calibration`` as JSON; return the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
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
    out.write_text(json.dumps(data, indent=2) + "\n")
    return out


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
             "points_px", "rms_reprojection_px"}
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
    return Calibration(h / h[2, 2], (size[0], size[1]), method, points_m, points_px, float(rms))
