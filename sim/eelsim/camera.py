"""The overhead camera as the controller sees it: 30 fps samples, pixel quantisation, median filter.

The camera's frame period (1/30 s) is not a multiple of the physics step (0.01 s), and it does not
need to be: the camera only observes. A frame between two physics steps sees the pose given by the
cubic Hermite interpolant of the centre of mass and heading, built from their values and rates at
both steps (all part of the state), which is accurate to a few micrometres here, far below a pixel.

Positions are quantised to pixel centres (0.0038 m per pixel in the paper's tank). The heading is
taken as measured (optionally with Gaussian noise). A moving median over the last ``median_window``
frames filters position and (unwrapped) heading.

The controller's median is causal (it cannot see future frames). A *recording* may be filtered
afterwards with a centred median instead (``median = "centred"``: the window of frame f holds
frames f - (w - 1) // 2 .. f + w // 2, fewer at the recording's ends), which has no lag;
:func:`observed_positions` reproduces either, so that the estimator sees the twin exactly as the
recording's camera saw the robot.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from eelsim.control import wrap_angle

MEDIAN_PLACEMENTS = ("causal", "centred")


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
    median : {"causal", "centred"}
        How a recording's median filter is placed: over the last ``median_window`` frames (the
        controller's, always) or centred on the frame (a recording filtered afterwards). Only
        :func:`observed_positions` reads it; the closed loop's controller filters causally.
    """

    fps: float = 30.0
    pixel_m: float = 0.0038
    median_window: int = 5
    heading_noise_rad: float = 0.0
    median: str = "causal"

    def __post_init__(self) -> None:
        if not (np.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"camera fps must be positive, got {self.fps}")
        if not (np.isfinite(self.pixel_m) and self.pixel_m >= 0):
            raise ValueError(f"camera pixel size must be >= 0, got {self.pixel_m}")
        if self.median_window < 1:
            raise ValueError(f"median window must be at least 1 frame, got {self.median_window}")
        if self.median not in MEDIAN_PLACEMENTS:
            raise ValueError(f"median must be 'causal' or 'centred', got {self.median!r}")

    def window_frames(self) -> tuple[int, int]:
        """Frames before and after frame f that its median window holds."""
        w = self.median_window
        return (w - 1, 0) if self.median == "causal" else ((w - 1) // 2, w // 2)

    def frame_times(self, duration_s: float) -> np.ndarray:
        """Times of the frames in [0, duration_s]."""
        count = int(np.floor(duration_s * self.fps + 1e-9)) + 1
        return np.arange(count) / self.fps


def quantise_position(position_m: np.ndarray, pixel_m: float) -> np.ndarray:
    """Round positions to the centre of the pixel they fall in (no-op when ``pixel_m`` is 0)."""
    if pixel_m <= 0:
        return np.asarray(position_m, dtype=float)
    return (np.floor(np.asarray(position_m) / pixel_m) + 0.5) * pixel_m


def hermite(
    y0: np.ndarray, dy0: np.ndarray, y1: np.ndarray, dy1: np.ndarray, h: float,
    s: float | np.ndarray,
) -> np.ndarray:
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

    The streaming form of :func:`causal_median` (the controller's, one frame at a time); both
    unwrap the heading with :func:`unwrap_heading` and take the median of the same window, so
    a recording filtered at once gives what the controller saw frame by frame (tested).

    Parameters
    ----------
    window : int
        Number of samples.
    """

    def __init__(self, window: int) -> None:
        self._buf: deque[np.ndarray] = deque(maxlen=max(1, int(window)))
        self._last_heading: float | None = None

    def push(self, x_m: float, y_m: float, heading_rad: float) -> np.ndarray:
        """Add a sample and return the filtered (x, y, heading).

        Headings are unwrapped against the previous sample (:func:`unwrap_heading`) so that the
        median does not jump across +-pi.
        """
        if self._last_heading is not None:
            heading_rad = unwrap_heading(self._last_heading, heading_rad)
        self._last_heading = heading_rad
        self._buf.append(np.array([x_m, y_m, heading_rad]))
        return np.median(np.array(self._buf), axis=0)


def unwrap_heading(previous_rad: float, heading_rad: float) -> float:
    """A heading moved by whole turns to within (-pi, pi] of the previous (unwrapped) one.

    The change is taken in (-pi, pi] (:func:`eelsim.control.wrap_angle`), the twin's one
    convention, so that a median over headings does not jump across +-pi.

    Parameters
    ----------
    previous_rad : float
        The previous sample's unwrapped heading.
    heading_rad : float
        The new sample's heading, any branch.

    Returns
    -------
    float
        ``previous_rad + wrap(heading_rad - previous_rad)``.
    """
    return previous_rad + float(wrap_angle(heading_rad - previous_rad))


def causal_median(poses: np.ndarray, window: int) -> np.ndarray:
    """:class:`MedianFilter` over a whole recording at once (vectorised).

    Parameters
    ----------
    poses : ndarray, shape (K, 3)
        x (m), y (m) and heading (rad, any branch) of each frame, in time order.
    window : int
        Number of samples in the median (at least 1).

    Returns
    -------
    ndarray, shape (K, 3)
        Row k is what :meth:`MedianFilter.push` returns for frame k: the median of frames
        max(0, k - window + 1) .. k, the heading unwrapped against the previous frame first
        (frames before a full window take the median of those there are).
    """
    poses = np.array(poses, dtype=float, copy=True).reshape(-1, 3)
    window = max(1, int(window))
    if len(poses) > 1:
        # unwrap_heading, frame after frame: wrap_angle(h - u_prev) = wrap_angle(h - h_prev)
        steps = np.asarray(wrap_angle(np.diff(poses[:, 2])), dtype=float)
        poses[1:, 2] = poses[0, 2] + np.cumsum(steps)
    filtered = np.empty_like(poses)
    head = min(window - 1, len(poses))
    for k in range(head):
        filtered[k] = np.median(poses[: k + 1], axis=0)
    if len(poses) > head:
        filtered[head:] = np.median(sliding_window_view(poses, window, axis=0), axis=-1)
    return filtered


def _frame_steps(frame: int, fps: float, dt_s: float) -> tuple[int, float]:
    """The physics step at or before a frame and the frame's fraction of the way to the next."""
    t = frame / fps
    k = int(np.floor(t / dt_s + 1e-9))
    return k, (t - k * dt_s) / dt_s


def observation_steps(
    times_s: np.ndarray, camera: CameraModel, dt_s: float, last_time_s: float | None = None
) -> np.ndarray:
    """Physics steps whose states :func:`observed_positions` needs for the given query times.

    Parameters
    ----------
    times_s : ndarray
        Times at which the filtered camera position is wanted (>= 0).
    camera : CameraModel
    dt_s : float
        Physics step.
    last_time_s : float, optional
        The recording's last frame time (a centred window ends there), as for
        :func:`observed_positions`.

    Returns
    -------
    ndarray of int
        Sorted, unique step indices.
    """
    before, after = camera.window_frames()
    last = _last_frame(last_time_s, camera.fps)
    steps: set[int] = set()
    for t in np.asarray(times_s, dtype=float):
        f = int(np.floor(t * camera.fps + 1e-9))
        for g in range(max(0, f - before), max(f + 1, min(f + 1 + after, last)) + 1):
            k, _ = _frame_steps(g, camera.fps, dt_s)
            steps.update((k, k + 1))
    return np.array(sorted(steps), dtype=np.int64)


def _last_frame(last_time_s: float | None, fps: float) -> int:
    """Index of the recording's last frame (no end: a very large index)."""
    if last_time_s is None:
        return np.iinfo(np.int64).max // 2
    return int(np.floor(last_time_s * fps + 1e-9))


def observed_positions(
    times_s: np.ndarray,
    steps: np.ndarray,
    position_m: np.ndarray,
    velocity_m_s: np.ndarray,
    camera: CameraModel,
    dt_s: float,
    last_time_s: float | None = None,
) -> np.ndarray:
    """What the camera pipeline reports for the centre of mass at the query times.

    The same model as the closed loop's camera: frames at ``fps``, each the cubic Hermite
    interpolant between physics steps, quantised to pixel centres, then the moving median over the
    last ``median_window`` frames (fewer at the start), or centred on the frame with
    ``camera.median == "centred"`` (fewer at the recording's ends); a query time between two
    frames gets the linear interpolation of their filtered positions, as a recording read between
    frames does. Any number of runs at once (leading axes of the states): estimation scores a
    whole generation of candidates in one call.

    Parameters
    ----------
    times_s : ndarray, shape (n,)
        Query times.
    steps : ndarray of int, shape (S,)
        The steps of the states given (must include :func:`observation_steps`).
    position_m, velocity_m_s : ndarray, shape (..., S, 2)
        Centre of mass and its velocity at those steps.
    camera : CameraModel
    dt_s : float
    last_time_s : float, optional
        Time of the recording's last frame: a centred window holds no frame after it (a causal
        one never does). Default: no end.

    Returns
    -------
    ndarray, shape (..., n, 2)

    Raises
    ------
    ValueError
        When ``steps`` lacks a step the query times need.
    """
    times = np.asarray(times_s, dtype=float)
    # a run that blew up (infinite states) has no camera view there, as one that ended (NaN):
    # NaN passes through the arithmetic below silently, where inf times a zero weight is invalid
    position = np.asarray(position_m, dtype=float)
    velocity = np.asarray(velocity_m_s, dtype=float)
    position = np.where(np.isfinite(position), position, np.nan)
    velocity = np.where(np.isfinite(velocity), velocity, np.nan)
    index = {int(s): i for i, s in enumerate(steps)}
    frame = np.floor(times * camera.fps + 1e-9).astype(np.int64)
    between = times * camera.fps - frame
    # the filtered frames the queries read, and the raw frames their windows hold
    wanted = np.unique(np.concatenate([frame, frame[between >= 1e-12] + 1]))
    before, after = camera.window_frames()
    first = np.maximum(0, wanted - before)
    # no frame after the recording's last one (a frame past it, read only to interpolate up to
    # the last sample, keeps at least itself)
    last = np.maximum(wanted, np.minimum(wanted + after, _last_frame(last_time_s, camera.fps)))
    spans = [np.arange(a, b + 1) for a, b in zip(first, last, strict=True)]
    raw_frames = np.unique(np.concatenate(spans))
    at, fraction = zip(*(_frame_steps(int(g), camera.fps, dt_s) for g in raw_frames), strict=True)
    try:
        i = np.array([index[k] for k in at])
        j = np.array([index[k + 1] for k in at])
    except KeyError as err:
        raise ValueError(
            f"observed_positions: the state at step {err.args[0]} is missing "
            "(pass the steps of observation_steps)"
        ) from None
    s = np.asarray(fraction)[:, None]
    raw = quantise_position(
        hermite(position[..., i, :], velocity[..., i, :], position[..., j, :],
                velocity[..., j, :], dt_s, s),
        camera.pixel_m,
    )
    # moving median by sorting each window, short windows padded with +inf (sorted last): the
    # middle value, or the mean of the two middle ones, as np.median gives
    slot = np.searchsorted(raw_frames, first[:, None] + np.arange(camera.median_window))
    count = np.minimum(camera.median_window, last - first + 1)
    padded = np.concatenate([raw, np.full(raw.shape[:-2] + (1, 2), np.inf)], axis=-2)
    slot = np.where(np.arange(camera.median_window) < count[:, None], slot, raw.shape[-2])
    window = padded[..., slot, :]
    ordered = np.sort(window, axis=-2)
    rows = np.arange(wanted.size)
    filtered = (ordered[..., rows, (count - 1) // 2, :] + ordered[..., rows, count // 2, :]) / 2
    # a window holding a frame without a view has no median (NaN sorts after the padding)
    filtered[np.isnan(window).any(axis=-2)] = np.nan
    lo = np.searchsorted(wanted, frame)
    hi = np.minimum(lo + 1, wanted.size - 1)
    weight = between[:, None]
    mixed = (1 - weight) * filtered[..., lo, :] + weight * filtered[..., hi, :]
    return np.where(between[:, None] < 1e-12, filtered[..., lo, :], mixed)
