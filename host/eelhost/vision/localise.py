"""Localise the robot in a frame from its link markers.

Per frame: detect the ArUco markers (``cv2.aruco.ArucoDetector``, contour corner refinement),
map each marker's four corners to metres through the calibration homography (undistorted first
when the calibration has a lens), and take

- the marker centre as the mean of its metric corners (exact for a square on the plane, unlike
  the mean of the pixel corners under perspective),
- the link angle as the direction of the marker's top edge (mean of its top and bottom edges),
- the link centre as the marker centre minus the layout's offset along the link.

With every link seen, the centre of mass is the mean of the link centres and the heading the mean
of the link angles (unwrapped along the chain, so a robot pointing at +-pi does not average to 0).
A single unseen link between two seen ones is rebuilt from the robot model: its ends are the
neighbours' joints, so its centre is their midpoint and its angle their direction. Anything less
(an unseen tail or head, two unseen links in a row, the robot half out of view) gives no pose:
``status`` says ``"partial"`` or ``"not_found"`` and ``message`` which links are missing; the
link angles that were seen are still reported.

The moving median filter is the twin's :class:`eelsim.camera.MedianFilter`;
:func:`filtered_poses` feeds it the frames that gave a pose.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from eelhost.vision.calibration import Calibration
from eelhost.vision.markers import MarkerLayout, default_layout
from eelsim.camera import MedianFilter
from eelsim.control import wrap_angle
from eelsim.robot import Robot

FloatArray = NDArray[np.float64]

REFINE_METHODS = {
    "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
    "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
    "none": cv2.aruco.CORNER_REFINE_NONE,
}


@dataclass(frozen=True)
class MarkerSighting:
    """One detected robot marker.

    Attributes
    ----------
    marker_id : int
        ArUco id.
    link : int
        Link index, 0 = tail.
    corners_px : ndarray, shape (4, 2)
        Corners in the image, the detector's order (top-left, top-right, bottom-right,
        bottom-left of the printed marker).
    centre_m : ndarray, shape (2,)
        Marker centre in the world.
    angle_rad : float
        Link angle in (-pi, pi].
    """

    marker_id: int
    link: int
    corners_px: FloatArray
    centre_m: FloatArray
    angle_rad: float


@dataclass(frozen=True)
class Localisation:
    """What one frame says about the robot.

    Attributes
    ----------
    t_s : float
        Frame time.
    status : str
        ``"ok"`` (every link seen), ``"rebuilt"`` (pose complete, some interior links rebuilt from
        their neighbours), ``"partial"`` (some links seen, no pose) or ``"not_found"``.
    com_m : ndarray (2,) or None
        Centre of mass, when the pose is complete.
    heading_rad : float or None
        Mean link angle, wrapped to (-pi, pi], when the pose is complete.
    link_angles_rad : ndarray, shape (N,)
        Link angles, NaN where unknown (unwrapped along the chain when the pose is complete).
    link_centres_m : ndarray, shape (N, 2)
        Link centres, NaN where unknown.
    seen : tuple of bool
        Whether each link's marker was detected.
    rebuilt : tuple of int
        Links (0 = tail) rebuilt from their neighbours.
    max_joint_gap_m : float
        Largest distance between the joint positions implied by two seen neighbours (0 for a
        perfect rigid chain; large values mean a wrong calibration, layout or robot model).
    message : str
        Human-readable reason when the pose is incomplete.
    sightings : tuple of MarkerSighting
        The robot's markers detected in the frame (their pixel corners, for display).
    """

    t_s: float
    status: str
    com_m: FloatArray | None
    heading_rad: float | None
    link_angles_rad: FloatArray
    link_centres_m: FloatArray
    seen: tuple[bool, ...]
    rebuilt: tuple[int, ...]
    max_joint_gap_m: float
    message: str
    sightings: tuple[MarkerSighting, ...] = ()

    @property
    def found(self) -> bool:
        """True when the frame gave a full pose (centre of mass and heading)."""
        return self.com_m is not None


def detector_parameters(refine: str = "contour") -> cv2.aruco.DetectorParameters:
    """Detector settings tuned for 15-20 px markers (the robot's at 3.8 mm per pixel).

    Parameters
    ----------
    refine : str
        Corner refinement: ``"contour"`` (default; measured best on blurred synthetic frames),
        ``"subpix"`` or ``"none"``.
    """
    if refine not in REFINE_METHODS:
        raise ValueError(f"corner refinement must be one of {sorted(REFINE_METHODS)}, got {refine!r}")
    p = cv2.aruco.DetectorParameters()
    p.cornerRefinementMethod = REFINE_METHODS[refine]
    # Small markers (2.6 px cells), settings measured on the synthetic benchmark: the default
    # threshold windows (3, 13, 23 px); bits read from 8 samples a cell, ignoring the outer 30 %
    # of each cell, which blur mixes with its neighbours; the dictionary's one correctable bit
    # used (errorCorrectionRate 1: the 6 robot ids of DICT_4X4_50 are far apart, and a duplicate
    # or foreign id is dropped anyway). Together these lift the markers read from 95 % to 99.8 %.
    p.perspectiveRemovePixelPerCell = 8
    p.perspectiveRemoveIgnoredMarginPerCell = 0.3
    p.errorCorrectionRate = 1.0
    p.minMarkerPerimeterRate = 0.02
    return p


class Localiser:
    """Find the robot in frames.

    Parameters
    ----------
    calibration : Calibration
        Pixels <-> metres on the markers' plane.
    robot : Robot
        The robot (link half-lengths, used to rebuild unseen interior links and check the chain).
    layout : MarkerLayout, optional
        Marker layout (default: :func:`default_layout` for the robot's link count).
    refine : str
        Corner refinement method (see :func:`detector_parameters`).
    """

    def __init__(
        self,
        calibration: Calibration,
        robot: Robot,
        layout: MarkerLayout | None = None,
        refine: str = "contour",
    ) -> None:
        self.calibration = calibration
        self.half_length_m = np.array([lk.half_length_m for lk in robot.links()])
        self.layout = layout or default_layout(robot.n_links)
        if self.layout.n_links != robot.n_links:
            raise ValueError(f"layout has {self.layout.n_links} markers, robot {robot.n_links} links")
        self._offsets = self.layout.offsets()
        self._to_m = np.linalg.inv(calibration.homography_m_to_px)
        self._detector = cv2.aruco.ArucoDetector(self.layout.dictionary(), detector_parameters(refine))

    def detect(self, frame: NDArray[np.uint8]) -> list[MarkerSighting]:
        """Detect the robot's markers in a grey or BGR frame.

        Markers of other ids are ignored; an id seen twice is dropped (one of the two is a
        misreading and nothing says which).
        """
        grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        corners, ids, _ = self._detector.detectMarkers(grey)
        if ids is None or len(ids) == 0:
            return []
        ids = np.asarray(ids).ravel()
        counts = np.bincount(ids)
        out = []
        for c, marker_id in zip(corners, ids, strict=True):
            link = self.layout.link_of(int(marker_id))
            if link is None or counts[marker_id] > 1:
                continue
            px = np.asarray(c, dtype=float).reshape(4, 2)
            ideal = px if self.calibration.lens is None else self.calibration.lens.undistort(px)
            q = np.c_[ideal, np.ones(4)] @ self._to_m.T
            m = q[:, :2] / q[:, 2:3]
            along = (m[1] - m[0]) + (m[2] - m[3])
            angle = math.atan2(along[1], along[0])
            out.append(MarkerSighting(int(marker_id), link, px, m.mean(axis=0), angle))
        return out

    def localise(self, t_s: float, frame: NDArray[np.uint8]) -> Localisation:
        """Localise the robot in one frame taken at ``t_s``.

        Raises
        ------
        FrameSizeError
            A frame of another size than the calibration's (no pose is made from it).
        """
        self.calibration.check_frame(frame)
        return self.from_sightings(t_s, self.detect(frame))

    def from_sightings(self, t_s: float, sightings: Iterable[MarkerSighting]) -> Localisation:
        """Build the pose from marker sightings (see the module docstring for the rules)."""
        t_s = float(t_s)
        sightings = tuple(sightings)
        n = self.layout.n_links
        angles = np.full(n, np.nan)
        centres = np.full((n, 2), np.nan)
        for s in sightings:
            angles[s.link] = s.angle_rad
            u = np.array([math.cos(s.angle_rad), math.sin(s.angle_rad)])
            centres[s.link] = s.centre_m - self._offsets[s.link] * u
        seen = tuple(bool(v) for v in np.isfinite(angles))
        gap = self._max_joint_gap(angles, centres)
        if not any(seen):
            return Localisation(t_s, "not_found", None, None, angles, centres, seen, (), 0.0,
                                "no robot marker in view", sightings)
        rebuilt = []
        for i in range(1, n - 1):
            if not seen[i] and seen[i - 1] and seen[i + 1]:
                self._rebuild(i, angles, centres)
                rebuilt.append(i)
        missing = [i + 1 for i in range(n) if not np.isfinite(angles[i])]
        if missing:
            msg = (f"links {missing} (1 = tail) not seen and not recoverable: no pose "
                   f"(saw {sum(seen)} of {n} markers)")
            return Localisation(t_s, "partial", None, None, angles, centres, seen, tuple(rebuilt),
                                gap, msg, sightings)
        # Joint angles stay within +-pi, so unwrapping along the chain gives consistent angles.
        chain = angles[0] + np.concatenate(([0.0], np.cumsum(wrap_angle(np.diff(angles)))))
        heading = float(wrap_angle(np.mean(chain)))
        status = "rebuilt" if rebuilt else "ok"
        msg = f"links {[i + 1 for i in rebuilt]} rebuilt from their neighbours" if rebuilt else ""
        return Localisation(t_s, status, centres.mean(axis=0), heading, chain, centres, seen,
                            tuple(rebuilt), gap, msg, sightings)

    def _rebuild(self, i: int, angles: FloatArray, centres: FloatArray) -> None:
        lh = self.half_length_m
        u_prev = np.array([math.cos(angles[i - 1]), math.sin(angles[i - 1])])
        u_next = np.array([math.cos(angles[i + 1]), math.sin(angles[i + 1])])
        tail_joint = centres[i - 1] + lh[i - 1] * u_prev
        head_joint = centres[i + 1] - lh[i + 1] * u_next
        d = head_joint - tail_joint
        angles[i] = math.atan2(d[1], d[0])
        centres[i] = (tail_joint + head_joint) / 2.0

    def _max_joint_gap(self, angles: FloatArray, centres: FloatArray) -> float:
        u = np.c_[np.cos(angles), np.sin(angles)]
        ends_head = centres + self.half_length_m[:, None] * u
        ends_tail = centres - self.half_length_m[:, None] * u
        gaps = np.linalg.norm(ends_head[:-1] - ends_tail[1:], axis=1)
        gaps = gaps[np.isfinite(gaps)]
        return float(gaps.max()) if len(gaps) else 0.0


def localise_frames(
    localiser: Localiser, frames: Iterable[tuple[float, NDArray[np.uint8]]]
) -> Iterator[Localisation]:
    """Localise every (t_s, frame) of a frame source."""
    for t_s, frame in frames:
        yield localiser.localise(t_s, frame)


def filtered_poses(
    results: Iterable[Localisation], window: int = 5
) -> Iterator[tuple[float, FloatArray | None]]:
    """Moving median of (x, y, heading) over the last ``window`` frames that gave a pose.

    Yields ``(t_s, pose)`` for every result; ``pose`` is None until the first full pose, and a
    frame without a pose repeats the last filtered pose (the controller holds it).
    """
    filt = MedianFilter(window)
    last: FloatArray | None = None
    for r in results:
        if r.found:
            assert r.com_m is not None and r.heading_rad is not None
            last = filt.push(float(r.com_m[0]), float(r.com_m[1]), r.heading_rad)
        yield r.t_s, last
