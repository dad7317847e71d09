"""The robot's whole body state at the tank, from the camera, for replanning and contact checks.

docs/planning.md ("The robot's state at the tank") is the long form. The planner swims every leg
from a full twin state (docs/model.md section 1: link angles theta, centre of mass p, and their
rates), so a replan needs all of it, not only the filtered pose:

- **pose and shape** from the camera: the localiser measures every link's angle and the centre of
  mass in each frame (:class:`eelhost.vision.localise.Localisation`); a link whose marker was not
  read gets the gait's reference at the frame's phase (joint j's reference is
  A sin(omega t + (j - 1) beta) + gamma, docs/model.md section 4), placed around the measured mean
  heading;
- **rates** from a filter: a quadratic least-squares fit over the last ``window`` frames of each
  link angle (unwrapped in time) and of the centre of mass, differentiated at the newest frame. A
  quadratic follows the gait's oscillation (period 1.6 s at 3.9 rad/s) over the 0.2 s window,
  where a straight line would lag it;
- the twin is the **process model**: :meth:`eelhost.planning.replan.TankReplanner` predicts the
  estimated state forward with it to the moment a replan will be ready, and compares its
  prediction with the camera track to estimate the current (:class:`CurrentEstimator`).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from eelhost.planning.geometry import FloatArray
from eelsim.control import Gait
from eelsim.model import SwimmerModel

__all__ = ["BodyEstimate", "BodyStateEstimator", "CurrentEstimator", "gait_link_angles"]


def gait_link_angles(model: SwimmerModel, gait: Gait, t_s: float, heading_rad: float,
                     offset_rad: float = 0.0) -> FloatArray:
    """Link angles of a body following the gait's joint references exactly, at a mean heading.

    Joint j (between links j and j + 1, tail first) is at A sin(omega t + (j - 1) beta) + gamma
    (docs/model.md section 4); the links' angles are the running sums of the joint angles,
    shifted so that their mean is ``heading_rad``.

    Parameters
    ----------
    model : SwimmerModel
    gait : Gait
    t_s : float
        Time since the gait started.
    heading_rad : float
        Mean link angle.
    offset_rad : float
        The heading offset gamma added to every joint.

    Returns
    -------
    ndarray, shape (N,)
    """
    n = model.n_links
    j = np.arange(n - 1)
    phi = gait.amplitude_rad * np.sin(gait.omega_rad_s * t_s + j * gait.beta_rad) + offset_rad
    theta = np.concatenate([[0.0], np.cumsum(phi)])
    return theta - theta.mean() + heading_rad


@dataclass(frozen=True)
class BodyEstimate:
    """The body's estimated state at one frame.

    Attributes
    ----------
    t_s : float
        Frame time, since the gait started.
    state : ndarray, shape (2 N + 4,)
        theta, p, theta_dot, p_dot (the twin's layout).
    measured_links : int
        Links whose angle the camera measured (the rest from the gait's reference).
    """

    t_s: float
    state: FloatArray
    measured_links: int


class BodyStateEstimator:
    """The whole body state from the camera's link angles and centre of mass (module docstring).

    Parameters
    ----------
    model : SwimmerModel
    gait : Gait
    window : int
        Frames of the rate filter.
    """

    def __init__(self, model: SwimmerModel, gait: Gait, window: int = 7) -> None:
        self.model = model
        self.gait = gait
        self.window = max(int(window), 3)
        self._t: deque[float] = deque(maxlen=self.window)
        self._x: deque[FloatArray] = deque(maxlen=self.window)
        self._measured = 0

    def observe(self, t_s: float, com_m: FloatArray, link_angles_rad: FloatArray,
                offset_rad: float = 0.0) -> None:
        """Add one frame's pose.

        Parameters
        ----------
        t_s : float
        com_m : ndarray, shape (2,)
        link_angles_rad : ndarray, shape (N,)
            NaN where the camera did not measure a link.
        offset_rad : float
            The offset the robot is steering with (for the gait's reference of unseen links).
        """
        theta = np.asarray(link_angles_rad, dtype=float).copy()
        known = np.isfinite(theta)
        self._measured = int(known.sum())
        if not known.all():
            heading = float(np.mean(theta[known])) if known.any() else self._last_heading()
            theta[~known] = gait_link_angles(self.model, self.gait, t_s, heading,
                                             offset_rad)[~known]
        if self._x:
            # unwrap against the previous frame, so rates never see a 2 pi jump
            prev = self._x[-1][: self.model.n_links]
            theta = prev + np.angle(np.exp(1j * (theta - prev)))
        self._t.append(float(t_s))
        self._x.append(np.concatenate([theta, np.asarray(com_m, dtype=float)]))

    def _last_heading(self) -> float:
        return float(np.mean(self._x[-1][: self.model.n_links])) if self._x else 0.0

    @property
    def ready(self) -> bool:
        """Enough frames for the rates."""
        return len(self._t) >= 3

    def estimate(self) -> BodyEstimate | None:
        """The state at the newest frame (None before three frames).

        Returns
        -------
        BodyEstimate or None
        """
        if not self.ready:
            return None
        t = np.asarray(self._t)
        x = np.asarray(self._x)
        tau = t - t[-1]
        degree = 2 if len(t) >= 5 else 1
        coef = np.polynomial.polynomial.polyfit(tau, x, degree)  # (degree + 1, N + 2)
        value, rate = coef[0], coef[1]  # at tau = 0: the fitted value and its derivative
        n = self.model.n_links
        state = np.concatenate([value[:n], value[n:], rate[:n], rate[n:]])
        return BodyEstimate(float(t[-1]), state, self._measured)

    def latest_pose(self) -> FloatArray | None:
        """The newest frame's link angles and centre of mass as measured (no fit), (N + 2,)."""
        return self._x[-1].copy() if self._x else None


@dataclass
class CurrentEstimator:
    """The water's unknown current, from the camera track against the twin's prediction.

    Over each window the twin predicts where the centre of mass goes from the window's first
    estimated state, in the current the planner assumes plus the present estimate; the camera
    says where it went. In a uniform current the twin's body drifts with the water (drag and added
    mass act on the velocity relative to it), so a current the twin lacks shows as a drift of the
    track from the prediction at that current's velocity: the estimate moves by ``gain`` times
    the drift over the window, and is kept within ``max_m_s``. A robot that swims slower or faster
    than its coefficients say shows up the same way, along its heading (docs/planning.md says what
    that costs).

    Attributes
    ----------
    window_s : float
        Length of a comparison window.
    gain : float
        Fraction of a window's drift taken into the estimate.
    max_m_s : float
        Largest speed the estimate may reach.
    value_m_s : ndarray, shape (2,)
        The estimate, added to the planner's current.
    history : list of dict
        Every update: time, drift velocity, estimate.
    """

    window_s: float = 3.0
    gain: float = 0.6
    max_m_s: float = 0.08
    value_m_s: FloatArray = None  # type: ignore[assignment]
    history: list[dict] = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.value_m_s is None:
            self.value_m_s = np.zeros(2)
        if self.history is None:
            self.history = []

    def update(self, t_s: float, predicted_m: FloatArray, measured_m: FloatArray,
               span_s: float) -> FloatArray:
        """Take one window's comparison into the estimate.

        Parameters
        ----------
        t_s : float
            End of the window.
        predicted_m, measured_m : ndarray, shape (2,)
            Where the twin put the centre of mass and where the camera saw it.
        span_s : float
            Length of the window.

        Returns
        -------
        ndarray, shape (2,)
            The new estimate.
        """
        drift = (np.asarray(measured_m, float) - np.asarray(predicted_m, float)) / span_s
        value = self.value_m_s + self.gain * drift
        speed = float(math.hypot(*value))
        if speed > self.max_m_s:
            value = value * (self.max_m_s / speed)
        self.value_m_s = value
        self.history.append({"t_s": round(float(t_s), 3),
                             "drift_m_s": [round(float(v), 4) for v in drift],
                             "current_m_s": [round(float(v), 4) for v in value]})
        return value
