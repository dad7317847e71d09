"""Line-of-sight guidance along waypoints, from camera poses (docs/model.md section 4).

What the robot's host does between the camera and the offset command, as one object, used by the
twin's closed loop (:func:`eelsim.closed_loop.simulate_closed_loop`) and meant for the tank's run
loop too (the batched kernel's copy, ``eelsim.batch.kernel_template._observe``, is tested
against it):

1. each camera pose (x, y, heading) passes the moving median over the last ``median_window``
   poses (:class:`eelsim.camera.MedianFilter`, the heading unwrapped first);
2. the target moves to the next waypoint when the filtered position is inside the acceptance
   circle, |p - w| < r; reaching the last one is the arrival, at that pose's time;
3. when the caller's control period comes, :meth:`Guidance.offset` gives
   gamma = k_theta wrap(theta_ref - theta_bar), theta_ref = atan2(y_w - p_y, x_w - p_x), from the
   latest filtered pose towards the current waypoint (the last one once all are reached),
   clipped to +-``offset_limit_rad`` when a limit is given (the radio command's range).

Time is an argument: the object keeps no clock, so the same code runs in simulated time and in
wall time.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from eelsim.camera import MedianFilter
from eelsim.control import heading_offset

FloatArray = NDArray[np.float64]


class Guidance:
    """Median filter, waypoint switching and the line-of-sight offset law (module docstring).

    Parameters
    ----------
    waypoints_m : sequence of (x, y)
        The waypoints, in order (at least one).
    acceptance_radius_m : float
        A waypoint is reached when the filtered position is closer than this (0.15 m).
    k_theta : float
        Gain of the offset law, rad of offset per rad of heading error.
    median_window : int
        Poses in the moving median (1: no filtering).
    offset_limit_rad : float, optional
        Clip the offset to +-this; ``None`` (the twin's default) does not clip.

    Raises
    ------
    ValueError
        No waypoint, a radius or window that is not positive, or a limit that is not positive.
    """

    def __init__(
        self,
        waypoints_m: Sequence[Sequence[float]] | FloatArray,
        acceptance_radius_m: float,
        k_theta: float,
        median_window: int = 5,
        offset_limit_rad: float | None = None,
    ) -> None:
        waypoints = np.asarray(waypoints_m, dtype=float).reshape(-1, 2)
        if waypoints.shape[0] == 0:
            raise ValueError("guidance needs at least one waypoint")
        if not acceptance_radius_m > 0:
            raise ValueError(f"acceptance radius must be positive, got {acceptance_radius_m}")
        if median_window < 1:
            raise ValueError(f"median window must be at least 1 pose, got {median_window}")
        if offset_limit_rad is not None and not offset_limit_rad > 0:
            raise ValueError(f"offset limit must be positive, got {offset_limit_rad}")
        self.waypoints_m = waypoints
        self.acceptance_radius_m = float(acceptance_radius_m)
        self.k_theta = float(k_theta)
        self.offset_limit_rad = offset_limit_rad
        self._filter = MedianFilter(median_window)
        self._filtered: FloatArray | None = None
        self._target = 0
        self._arrival_s: float | None = None
        self._offset = 0.0

    @property
    def filtered_pose(self) -> FloatArray | None:
        """The latest filtered (x, y, heading), or ``None`` before the first pose."""
        return self._filtered

    @property
    def target_index(self) -> int:
        """How many waypoints have been reached (the index of the current one)."""
        return self._target

    @property
    def target_m(self) -> FloatArray | None:
        """The waypoint being steered to, ``None`` once the last one is reached."""
        return self.waypoints_m[self._target] if self._target < len(self.waypoints_m) else None

    @property
    def arrived(self) -> bool:
        """Whether the last waypoint has been reached."""
        return self._target >= len(self.waypoints_m)

    @property
    def arrival_time_s(self) -> float | None:
        """Time of the pose that reached the last waypoint, ``None`` before."""
        return self._arrival_s

    def observe(self, t_s: float, x_m: float, y_m: float, heading_rad: float) -> FloatArray:
        """Take one camera pose; return the filtered pose (and switch waypoints if reached).

        Parameters
        ----------
        t_s : float
            When the pose was taken (any origin; it becomes the arrival time).
        x_m, y_m : float
            The measured centre of mass.
        heading_rad : float
            The measured heading (any branch: it is unwrapped against the previous one).

        Returns
        -------
        ndarray, shape (3,)
            The filtered (x, y, heading).
        """
        filtered = self._filter.push(x_m, y_m, heading_rad)
        self._filtered = filtered
        target = self.target_m
        if target is not None and np.linalg.norm(filtered[:2] - target) < self.acceptance_radius_m:
            self._target += 1
            if self.arrived and self._arrival_s is None:
                self._arrival_s = float(t_s)
        return filtered

    def offset(self) -> float:
        """The offset gamma for the joints from the latest filtered pose, rad.

        Before any pose the last offset holds (0 at the start).

        Returns
        -------
        float
        """
        if self._filtered is None:
            return self._offset
        waypoint = self.waypoints_m[min(self._target, len(self.waypoints_m) - 1)]
        gamma = heading_offset(self._filtered[:2], float(self._filtered[2]), waypoint, self.k_theta)
        if self.offset_limit_rad is not None:
            gamma = float(np.clip(gamma, -self.offset_limit_rad, self.offset_limit_rad))
        self._offset = gamma
        return gamma
