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
   gamma = k_theta wrap(theta_ref - theta_bar) from the latest filtered pose, clipped to
   +-``offset_limit_rad`` when a limit is given (the radio command's range). theta_ref comes from
   the guidance law (:class:`GuidanceLaw`, docs/model.md section 4):

   - ``pursuit`` (the paper's, the default): theta_ref = atan2(y_w - p_y, x_w - p_x) towards the
     current waypoint (the last one once all are reached);
   - ``ilos``, integral line-of-sight path following along the present leg, from the previous
     waypoint (for the first, the leg's given start) to the current one, at angle alpha_k:
     cross-track error e = -(p_x - x_0) sin alpha_k + (p_y - y_0) cos alpha_k,
     theta_ref = alpha_k - atan((e + sigma y_i) / Delta), and at every control update the
     integral state moves by T Delta e / ((e + sigma y_i)^2 + Delta^2) (Borhaug, Pavlov and
     Pettersen 2008; Kelasidi et al., IEEE T-RO 2017). Delta is a length, sigma a speed (below
     the robot's speed less the current's), y_i a time. y_i is the projection n_k . I of a
     world-frame integral vector I (s) on the leg's left normal n_k, and each update adds its
     increment along n_k to I: on a straight leg this is the published law, and at a waypoint
     the integral carries over as the part of the current it has learnt that crosses the next
     leg (our choice; the published law is for one straight path). Also ours: the look-ahead
     point never passes the waypoint. With s the along-track distance and L the leg's length,
     theta_ref = alpha_k + atan2(-(e + sigma y_i), min(Delta, L - s)), which is the published
     law while the waypoint is more than Delta ahead; nearer, it aims at the waypoint offset by
     -sigma y_i n_k, and past it back at it, so that a waypoint whose acceptance circle the body
     missed is turned back to (an infinite line would lead it away for ever).
   - ``pursuit_ff``, pure pursuit with a feed-forward of the known current (a crab angle): with
     d the unit vector from the filtered position to the current waypoint, n = (-d_y, d_x) its
     left normal, c the known current and U the robot's still-water speed,
     theta_ref = atan2(d_y, d_x) + asin(clip(-(c . n) / U, -s_max, s_max)): the heading whose
     water-relative velocity U h plus c points along d. Where c is zero it is ``pursuit``
     itself, to the bit. The current and U are the law's own (:meth:`GuidanceLaw.with_water`:
     the planner fills them in from the world it knows and its twin's straight run), never the
     water's unknown part.

Time is an argument: the object keeps no clock, so the same code runs in simulated time and in
wall time.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from eelsim.camera import MedianFilter
from eelsim.control import heading_offset, wrap_angle
from eelsim.registry import Registry

FloatArray = NDArray[np.float64]

SteeringLaw = Callable[["Guidance", FloatArray], float]
"""``steer(guidance, waypoint) -> gamma``: a law's offset from the latest filtered pose, rad."""

GUIDANCE_LAWS: Registry[SteeringLaw] = Registry("guidance law", None)
"""The guidance laws by name, each its steering function (:mod:`eelsim.registry`).

Closed to plug-ins (no entry-point group): the batched kernel carries every law's code
(``eelsim.batch.kernel_template._observe``, tested against these), so a law is added here and
there together."""


@GUIDANCE_LAWS.add("pursuit", "the paper's pure pursuit of each waypoint (the Guidance object's default)")
def _steer_pursuit(guidance: Guidance, waypoint: FloatArray) -> float:
    pose = guidance.filtered_pose
    assert pose is not None  # steered only after a pose
    return heading_offset(pose[:2], float(pose[2]), waypoint, guidance.k_theta)


@GUIDANCE_LAWS.add("ilos", "integral line-of-sight path following along each leg")
def _steer_ilos(guidance: Guidance, waypoint: FloatArray) -> float:
    pose, start = guidance.filtered_pose, guidance.leg_start_m
    assert pose is not None and start is not None  # set by the first pose
    theta_ref, di_x, di_y = ilos_reference(pose[:2], start, waypoint, guidance.integral_s,
                                           guidance.law, guidance.control_period_s)
    guidance.integral_s += (di_x, di_y)
    return guidance.k_theta * float(wrap_angle(theta_ref - float(pose[2])))


@GUIDANCE_LAWS.add("pursuit_ff", "pure pursuit aimed off by the known current (a crab angle)")
def _steer_pursuit_ff(guidance: Guidance, waypoint: FloatArray) -> float:
    pose = guidance.filtered_pose
    assert pose is not None  # steered only after a pose
    law = guidance.law
    theta_ref = feed_forward_reference(pose[:2], waypoint, law.current_m_s, law.speed_m_s,
                                       law.crab_limit)
    if theta_ref is None:  # no current: the paper's pursuit, to the bit
        return heading_offset(pose[:2], float(pose[2]), waypoint, guidance.k_theta)
    return guidance.k_theta * float(wrap_angle(theta_ref - float(pose[2])))


CRAB_LIMIT = 0.8
"""s_max, the largest sine of the feed-forward's crab angle (53 degrees; docs/model.md section 4).

The planner refuses a current at least the robot's speed, but a cross current near it would turn
the body almost square to its leg, where its own speed along the leg, U sqrt(1 - s^2), is
nearly nothing and a small error in U or c turns the crab into swimming backwards. At 0.8 the
body keeps 0.6 U along its leg; the worlds' currents (at most 0.06 m/s against 0.086 m/s, a
sine of 0.7) never reach it."""


@dataclass(frozen=True)
class GuidanceLaw:
    """Which line-of-sight law turns the filtered pose into theta_ref (module docstring).

    Attributes
    ----------
    name : str
        ``"pursuit"`` (the paper's, the default), ``"ilos"`` or ``"pursuit_ff"``.
    lookahead_m : float
        Delta, the look-ahead distance along the leg, m (ILOS only).
    integral_gain : float
        sigma, the weight of the integral state, m/s (ILOS only; 0 gives plain LOS path
        following). Borhaug et al.'s stability condition wants it below the robot's speed
        less the current's.
    heading_gain : float or None
        k_theta, rad of offset per rad of heading error, used instead of the gait's (the heading
        controller is the host's, like the law); ``None`` keeps the gait's.
    current_m_s : (float, float)
        c, the known current the law aims off by, m/s, world frame (``pursuit_ff`` only).
    speed_m_s : float
        U, the robot's still-water swimming speed, m/s (``pursuit_ff`` only); 0: not yet known,
        to be filled in with the current by :meth:`with_water` (the planner does).
    crab_limit : float
        s_max, the largest sine of the crab angle (``pursuit_ff`` only; :data:`CRAB_LIMIT`).

    Raises
    ------
    ValueError
        An unknown name, a look-ahead that is not positive or a negative gain (ILOS), a
        heading gain that is not positive, or (``pursuit_ff``) a current that is not finite, a
        negative speed or a crab limit outside (0, 1].
    """

    name: str = "pursuit"
    lookahead_m: float = 0.4
    integral_gain: float = 0.04
    heading_gain: float | None = None
    current_m_s: tuple[float, float] = (0.0, 0.0)
    speed_m_s: float = 0.0
    crab_limit: float = CRAB_LIMIT

    def __post_init__(self) -> None:
        if self.heading_gain is not None and not (math.isfinite(self.heading_gain)
                                                  and self.heading_gain > 0):
            raise ValueError(f"heading gain must be positive, got {self.heading_gain}")
        if self.name not in GUIDANCE_LAWS:
            raise ValueError(GUIDANCE_LAWS.unknown_message(self.name))
        if self.name == "ilos":
            if not (math.isfinite(self.lookahead_m) and self.lookahead_m > 0):
                raise ValueError(f"ILOS look-ahead must be positive, got {self.lookahead_m}")
            if not (math.isfinite(self.integral_gain) and self.integral_gain >= 0):
                raise ValueError(f"ILOS integral gain must be 0 or more, got {self.integral_gain}")
        if self.feed_forward:
            if not all(math.isfinite(float(v)) for v in self.current_m_s):
                raise ValueError(f"feed-forward current must be finite, got {self.current_m_s}")
            if not (math.isfinite(self.speed_m_s) and self.speed_m_s >= 0):
                raise ValueError(f"feed-forward speed must be 0 or more, got {self.speed_m_s}")
            if not 0 < self.crab_limit <= 1:
                raise ValueError(f"crab limit must be in (0, 1], got {self.crab_limit}")

    @property
    def integral(self) -> bool:
        """Whether the law has an integral state (ILOS)."""
        return self.name == "ilos"

    @property
    def feed_forward(self) -> bool:
        """Whether the law aims off by a known current (``pursuit_ff``)."""
        return self.name == "pursuit_ff"

    @property
    def needs_water(self) -> bool:
        """A feed-forward law whose speed U is not yet known (:meth:`with_water` fills it in)."""
        return self.feed_forward and self.speed_m_s == 0.0

    def with_water(self, current_m_s: Sequence[float], speed_m_s: float) -> GuidanceLaw:
        """The law with the known current and the robot's still-water speed filled in.

        Parameters
        ----------
        current_m_s : (vx, vy)
            The current the planner knows, m/s (the world's, with a fitted tank's), never the
            water's unknown part.
        speed_m_s : float
            U, the robot's steady straight speed in still water, m/s (positive).

        Returns
        -------
        GuidanceLaw
            Itself for a law without feed-forward.

        Raises
        ------
        ValueError
            A speed that is not positive.
        """
        if not self.feed_forward:
            return self
        if not (math.isfinite(speed_m_s) and speed_m_s > 0):
            raise ValueError(f"feed-forward speed must be positive, got {speed_m_s}")
        return dataclasses.replace(self, current_m_s=(float(current_m_s[0]),
                                                      float(current_m_s[1])),
                                   speed_m_s=float(speed_m_s))

    def describe(self) -> str:
        """One line: the law and its gains."""
        gain = ("" if self.heading_gain is None
                else f", heading gain k_theta {self.heading_gain:g}")
        if self.integral:
            return (f"integral line-of-sight along each leg (look-ahead {self.lookahead_m:g} m, "
                    f"integral gain {self.integral_gain:g} m/s{gain})")
        if self.feed_forward:
            water = ("the planner gives it the known current and the robot's speed"
                     if self.needs_water else
                     f"current ({self.current_m_s[0]:.4f}, {self.current_m_s[1]:.4f}) m/s, "
                     f"speed {self.speed_m_s:.4f} m/s")
            return (f"pure pursuit aimed off by the known current ({water}, crab sine at most "
                    f"{self.crab_limit:g}{gain})")
        return f"the paper's pure pursuit of each waypoint{gain}"

    def gain(self, k_theta: float) -> float:
        """The heading gain in force: this law's, else the gait's ``k_theta``."""
        return float(k_theta) if self.heading_gain is None else self.heading_gain


PURSUIT = GuidanceLaw()
"""The paper's pure pursuit towards the current waypoint."""


def feed_forward_reference(
    position_m: Sequence[float] | FloatArray,
    waypoint_m: Sequence[float] | FloatArray,
    current_m_s: Sequence[float],
    speed_m_s: float,
    crab_limit: float,
) -> float | None:
    """``pursuit_ff``'s reference heading: the pursuit's aim turned by the crab angle.

    Parameters
    ----------
    position_m, waypoint_m : (x, y)
        The filtered centre of mass and the current waypoint.
    current_m_s : (vx, vy)
        c, the known current, m/s.
    speed_m_s : float
        U, the robot's still-water speed, m/s.
    crab_limit : float
        s_max: the crab angle's sine is clipped to +-this.

    Returns
    -------
    float or None
        atan2(d) + asin(clip(-(c . n) / U, -s_max, s_max)), rad; ``None`` where there is no
        current (or the waypoint is reached to the bit): then the law is pure pursuit itself.

    Raises
    ------
    ValueError
        A current but no positive speed (the law's water was never filled in).
    """
    cx, cy = float(current_m_s[0]), float(current_m_s[1])
    dx = float(waypoint_m[0]) - float(position_m[0])
    dy = float(waypoint_m[1]) - float(position_m[1])
    dist = math.sqrt(dx * dx + dy * dy)
    if (cx == 0.0 and cy == 0.0) or dist == 0.0:
        return None
    if not speed_m_s > 0:
        raise ValueError("pursuit_ff: the robot's speed is not given (GuidanceLaw.with_water)")
    # c . n with n = (-d_y, d_x) / |d|; the sine of the crab angle that cancels it
    sine = -(cy * dx - cx * dy) / dist / speed_m_s
    sine = min(max(sine, -crab_limit), crab_limit)
    return math.atan2(dy, dx) + math.asin(sine)


def ilos_reference(
    position_m: Sequence[float] | FloatArray,
    leg_start_m: Sequence[float] | FloatArray,
    waypoint_m: Sequence[float] | FloatArray,
    integral_s: Sequence[float] | FloatArray,
    law: GuidanceLaw,
    period_s: float,
) -> tuple[float, float, float]:
    """ILOS's reference heading along a leg, and its integral's increment (module docstring).

    Parameters
    ----------
    position_m : (x, y)
        The filtered centre of mass.
    leg_start_m, waypoint_m : (x, y)
        The leg's start and end; a leg shorter than 1 mm is steered as pure pursuit.
    integral_s : (x, y)
        The world-frame integral vector I, s.
    law : GuidanceLaw
    period_s : float
        T, the control period: the integral is advanced by T times its rate.

    Returns
    -------
    (theta_ref, dI_x, dI_y)
        The reference heading, rad, and the integral's increment over one control period.
    """
    x0, y0 = float(leg_start_m[0]), float(leg_start_m[1])
    dx, dy = float(waypoint_m[0]) - x0, float(waypoint_m[1]) - y0
    px, py = float(position_m[0]), float(position_m[1])
    if dx * dx + dy * dy < 1e-6:
        return math.atan2(float(waypoint_m[1]) - py, float(waypoint_m[0]) - px), 0.0, 0.0
    alpha = math.atan2(dy, dx)
    tx, ty = math.cos(alpha), math.sin(alpha)
    nx, ny = -ty, tx
    e = (px - x0) * nx + (py - y0) * ny
    # the look-ahead point stays on the leg: within Delta of the waypoint the law aims at the
    # (offset) waypoint itself, and past it back at it, so the waypoint is always reached
    ahead = min(law.lookahead_m, math.sqrt(dx * dx + dy * dy) - ((px - x0) * tx + (py - y0) * ty))
    lateral = e + law.integral_gain * (float(integral_s[0]) * nx + float(integral_s[1]) * ny)
    theta_ref = alpha + math.atan2(-lateral, ahead)
    rate = law.lookahead_m * e / (lateral * lateral + law.lookahead_m * law.lookahead_m)
    return theta_ref, period_s * rate * nx, period_s * rate * ny


class Guidance:
    """Median filter, waypoint switching and the line-of-sight offset law (module docstring).

    Parameters
    ----------
    waypoints_m : sequence of (x, y)
        The waypoints, in order (at least one).
    acceptance_radius_m : float
        A waypoint is reached when the filtered position is closer than this (0.15 m).
    k_theta : float
        Gain of the offset law, rad of offset per rad of heading error (the law's own heading
        gain replaces it when it has one).
    median_window : int
        Poses in the moving median (1: no filtering).
    offset_limit_rad : float, optional
        Clip the offset to +-this; ``None`` (the twin's default) does not clip.
    law : GuidanceLaw
        The line-of-sight law (default the paper's pure pursuit).
    leg_start_m : (x, y), optional
        Where the first leg starts (ILOS); default the first filtered position.
    integral_s : (x, y)
        The ILOS integral vector to start from (a run restarted from another's state carries it).
    control_period_s : float
        T, the period of the caller's control updates (ILOS's integral step; 0.3 s at the tank).

    Raises
    ------
    ValueError
        No waypoint, a radius or window that is not positive, a limit that is not positive, or a
        feed-forward law with a current but no speed.
    """

    def __init__(
        self,
        waypoints_m: Sequence[Sequence[float]] | FloatArray,
        acceptance_radius_m: float,
        k_theta: float,
        median_window: int = 5,
        offset_limit_rad: float | None = None,
        law: GuidanceLaw = PURSUIT,
        leg_start_m: Sequence[float] | None = None,
        integral_s: Sequence[float] = (0.0, 0.0),
        control_period_s: float = 0.3,
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
        self.k_theta = law.gain(k_theta)
        self.offset_limit_rad = offset_limit_rad
        self._filter = MedianFilter(median_window)
        self._filtered: FloatArray | None = None
        self._target = 0
        self._arrival_s: float | None = None
        self._offset = 0.0
        if law.needs_water and law.current_m_s != (0.0, 0.0):
            raise ValueError("pursuit_ff: the robot's speed is not given (GuidanceLaw.with_water)")
        if law.integral and not control_period_s > 0:
            raise ValueError(f"control period must be positive, got {control_period_s}")
        self.law = law
        self.control_period_s = float(control_period_s)
        self._leg_start = None if leg_start_m is None else np.asarray(leg_start_m, dtype=float)
        self.integral_s = np.asarray(integral_s, dtype=float).reshape(2).copy()

    @property
    def leg_start_m(self) -> FloatArray | None:
        """Where the present leg starts: the previous waypoint, or the first leg's start."""
        leg = min(self._target, len(self.waypoints_m) - 1)
        return self.waypoints_m[leg - 1] if leg > 0 else self._leg_start

    @property
    def filtered_pose(self) -> FloatArray | None:
        """The latest filtered (x, y, heading), or ``None`` before the first pose."""
        return self._filtered

    def state(self) -> tuple[float, float, float, float]:
        """The guidance's own state, as a run restarted now must start with it.

        Returns
        -------
        (x, y, I_x, I_y)
            Where the present leg starts (NaN before the first pose when no start was given)
            and the ILOS integral vector, s: ``Twin.run``'s ``guidance`` and
            ``Planner.plan``'s ``guide`` (docs/planning.md, "The guidance").
        """
        start = self.leg_start_m
        x, y = (math.nan, math.nan) if start is None else (float(start[0]), float(start[1]))
        return (x, y, float(self.integral_s[0]), float(self.integral_s[1]))

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
        if self._leg_start is None:
            self._leg_start = filtered[:2].copy()
        target = self.target_m
        if target is not None and np.linalg.norm(filtered[:2] - target) < self.acceptance_radius_m:
            self._target += 1
            if self.arrived and self._arrival_s is None:
                self._arrival_s = float(t_s)
        return filtered

    def offset(self) -> float:
        """The offset gamma for the joints from the latest filtered pose, rad.

        Before any pose the last offset holds (0 at the start). With ILOS every call is a
        control update: it advances the integral by one period.

        Returns
        -------
        float
        """
        if self._filtered is None:
            return self._offset
        waypoint = self.waypoints_m[min(self._target, len(self.waypoints_m) - 1)]
        gamma = GUIDANCE_LAWS[self.law.name](self, waypoint)
        if self.offset_limit_rad is not None:
            gamma = float(np.clip(gamma, -self.offset_limit_rad, self.offset_limit_rad))
        self._offset = gamma
        return gamma
