"""Frame sources behind one interface: iterate to get ``(t_s, frame)`` pairs.

- :class:`CameraSource`: a live camera by index; times from an injectable clock (the live camera is
  the one place where the wall clock is the truth), relative to the first frame.
- :class:`VideoFileSource`: a video file; times from the container's timestamps.
- :class:`FolderSource`: a folder of images in natural order (``frame2`` before ``frame10``);
  times are index / fps.
- :class:`SyntheticSource`: frames rendered from twin states by the synthetic camera; times from
  the run. Its :attr:`SyntheticSource.truth` holds the true pose of each frame yielded so far.

:func:`open_source` picks one from a string: an integer is a camera, a directory a folder, any
other path a video file.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelhost.errors import UserError
from eelhost.vision.synthetic import SyntheticCamera, TruePose

Frame = NDArray[np.uint8]
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


class FrameSourceError(UserError, ValueError):
    """Frames that cannot be read (a file that is not a video, an unreadable image)."""


class FrameSourceNotFound(UserError, FileNotFoundError):
    """A camera, video file or image folder that is not there."""


class FrameSource(Protocol):
    """Anything that yields ``(t_s, frame)``: time in seconds, BGR (or grey) uint8 image."""

    def __iter__(self) -> Iterator[tuple[float, Frame]]:
        """Yield the frames in order."""
        ...


class CameraSource:
    """Frames from a camera by index (OpenCV ``VideoCapture``).

    Parameters
    ----------
    index : int
        Camera index.
    clock : callable, optional
        Returns seconds; default ``time.monotonic``. Injected so tests need no wall clock.
    max_frames : int, optional
        Stop after this many frames.
    """

    def __init__(self, index: int, clock: Callable[[], float] = time.monotonic,
                 max_frames: int | None = None) -> None:
        self.index = index
        self.clock = clock
        self.max_frames = max_frames

    def __iter__(self) -> Iterator[tuple[float, Frame]]:
        """Yield frames until the camera stops or ``max_frames`` is reached."""
        cap = cv2.VideoCapture(self.index)
        if not cap.isOpened():
            raise FrameSourceNotFound(f"camera {self.index}: cannot open")
        try:
            start = None
            count = 0
            while self.max_frames is None or count < self.max_frames:
                ok, frame = cap.read()
                if not ok:
                    return
                now = self.clock()
                start = now if start is None else start
                count += 1
                yield now - start, np.asarray(frame, np.uint8)
        finally:
            cap.release()


class VideoFileSource:
    """Frames of a video file.

    Parameters
    ----------
    path : str or Path
        The video.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FrameSourceNotFound(f"{self.path}: no such video file")

    def __iter__(self) -> Iterator[tuple[float, Frame]]:
        """Yield every frame with its presentation time."""
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            raise FrameSourceError(f"{self.path}: cannot open as a video")
        fps = cap.get(cv2.CAP_PROP_FPS) or 30.0
        try:
            index = 0
            while True:
                ok, frame = cap.read()
                if not ok:
                    return
                ms = cap.get(cv2.CAP_PROP_POS_MSEC)
                # Some containers report no timestamps; fall back on the nominal rate.
                t_s = ms / 1000.0 if ms > 0 or index == 0 else index / fps
                index += 1
                yield t_s, np.asarray(frame, np.uint8)
        finally:
            cap.release()


def _natural_key(path: Path) -> list[object]:
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path.name)]


class FolderSource:
    """Images of a folder, in natural name order, at a nominal frame rate.

    Parameters
    ----------
    folder : str or Path
        The folder.
    fps : float
        Frame rate used for the times (index / fps).
    """

    def __init__(self, folder: str | Path, fps: float = 30.0) -> None:
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise FrameSourceNotFound(f"{self.folder}: no such folder")
        if not fps > 0:
            raise ValueError(f"fps must be positive, got {fps}")
        self.fps = fps
        self.paths = sorted(
            (p for p in self.folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES),
            key=_natural_key,
        )
        if not self.paths:
            raise FrameSourceNotFound(f"{self.folder}: no images ({', '.join(IMAGE_SUFFIXES)})")

    def __iter__(self) -> Iterator[tuple[float, Frame]]:
        """Yield the images in order."""
        for i, path in enumerate(self.paths):
            frame = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if frame is None:
                raise FrameSourceError(f"{path}: cannot read as an image")
            yield i / self.fps, np.asarray(frame, np.uint8)


class SyntheticSource:
    """Frames rendered by the synthetic camera from twin states.

    Parameters
    ----------
    camera : SyntheticCamera
        The renderer.
    t_s : array, shape (F,)
        Frame times.
    states : array, shape (F, 2 N + 4)
        Twin states at those times.
    """

    def __init__(self, camera: SyntheticCamera, t_s: ArrayLike, states: ArrayLike) -> None:
        self.camera = camera
        self.t_s = np.asarray(t_s, dtype=float)
        self.states = np.asarray(states, dtype=float)
        if len(self.t_s) != len(self.states):
            raise ValueError("need one state per frame time")
        self.truth: list[TruePose] = []

    def __iter__(self) -> Iterator[tuple[float, Frame]]:
        """Render and yield each frame; append its true pose to :attr:`truth`."""
        for t, x in zip(self.t_s, self.states, strict=True):
            frame, pose = self.camera.render(x, float(t))
            self.truth.append(pose)
            yield float(t), frame


def open_source(spec: str | int, fps: float = 30.0) -> FrameSource:
    """Open a frame source from a command-line style spec.

    Parameters
    ----------
    spec : str or int
        A camera index (``0``), a folder of images, or a video file.
    fps : float
        Frame rate of a folder of images.

    Returns
    -------
    FrameSource
    """
    text = str(spec).strip()
    if re.fullmatch(r"\d+", text):
        return CameraSource(int(text))
    path = Path(text)
    if path.is_dir():
        return FolderSource(path, fps)
    return VideoFileSource(path)
