"""The robot's whole body state at the tank, from the camera and the telemetry, for replanning.

docs/planning.md ("The robot's state at the tank") is the long form, with the equations. The
planner swims every leg from a full twin state (docs/model.md section 1: link angles theta, centre
of mass p, and their rates), so a replan needs all of it, not only the filtered pose:

- **pose** from the camera: the localiser measures every link's angle and the centre of mass in
  each frame (:class:`eelhost.vision.localise.Localisation`);
- **joint angles** from three sources, fused per joint by inverse variance
  (:class:`JointSources`; the telemetry's variance measured from its disagreement with the
  camera, :meth:`BodyStateEstimator.telemetry_variance`): the telemetry's measured angles (feedback servos, ``phi_mrad`` with the
  flag JOINT_FEEDBACK, docs/firmware.md "Joint loop"), predicted from their sample time to the
  frame's with the gait's reference and the phase read from the same telemetry
  (:class:`TelemetryJoints`); without them the gait's reference at the frame's phase (the
  telemetry's phase when it comes, the host's gait clock otherwise); and the camera's joint angles
  (differences of its link angles). The fused shape is turned onto the links the camera read
  (:func:`place_on_seen_links`, right for a body curled beyond pi); with a link unread, all link
  angles are solved by least squares from the read links and the joints' prior
  (:func:`fill_unread_links`). :func:`body_error_m` measures an estimate against the true body;
- **rates** from a filter: a quadratic least-squares fit over the last ``window`` frames of each
  link angle (unwrapped in time) and of the centre of mass, differentiated at the newest frame. A
  quadratic follows the gait's oscillation (period 1.6 s at 3.9 rad/s) over the 0.2 s window,
  where a straight line would lag it;
- the twin is the **process model**: :meth:`eelhost.planning.replan.TankReplanner` predicts the
  estimated state forward with it to the moment a replan will be ready, and compares its
  prediction with the camera track to estimate the current (:class:`CurrentEstimator`).
"""

from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from eelhost.planning.body import link_endpoints
from eelhost.planning.geometry import FloatArray
from eelhost.wire import protocol
from eelsim.control import Gait, gait_reference, joint_amplitudes, wrap_angle
from eelsim.model import SwimmerModel

log = logging.getLogger(__name__)

__all__ = ["BodyEstimate", "BodyStateEstimator", "CurrentEstimator", "CurrentWindow",
           "JointSources", "JointsAtFrame", "TelemetryJoints", "body_error_m", "error_summary_mm",
           "fill_unread_links", "gait_link_angles", "place_on_seen_links", "steady_towards"]

#: Telemetry's ``phi_mrad`` of a joint without a measured angle (docs/firmware.md, "Joint loop").
NO_ANGLE_MRAD = -32768
#: The Telemetry's shortest trip to the host: its 58 bytes at 10 bits a byte on the line, and the
#: XBee's 5 ms (docs/firmware.md, "Messages" and "Link").
TELEMETRY_TRANSIT_S = 58 * 10 / protocol.BAUD + 0.005


def links_from_joints(joint_angles_rad: FloatArray, heading_rad: float) -> FloatArray:
    """Link angles of a body with these joint angles, whose mean link angle is ``heading_rad``.

    The links' angles are the running sums of the joint angles (joint j between links j and
    j + 1, tail first: phi_j = theta_{j+1} - theta_j, docs/model.md section 1).

    Parameters
    ----------
    joint_angles_rad : ndarray, shape (N - 1,)
    heading_rad : float

    Returns
    -------
    ndarray, shape (N,)
    """
    theta = np.concatenate([[0.0], np.cumsum(np.asarray(joint_angles_rad, dtype=float))])
    return theta - theta.mean() + heading_rad


def place_on_seen_links(theta_rad: FloatArray, seen_rad: FloatArray) -> FloatArray:
    """Turn a body's shape onto the link angles the camera read (least squares).

    The shape ``theta_rad`` (link angles from the fused joint angles, a chain unwrapped along
    the body) is turned by the mean of its differences to the links read, each difference taken
    modulo 2 pi about the first one's. The differences all lie near the one turn the shape
    needs, whatever the body's bend; the link angles themselves do not: a body curled in a hard
    turn spans more than pi from tail to head (4.3 rad seen in a bench world), and wrapping them
    about the first link moved the far links by 2 pi, which turned the whole estimate by
    2 pi k / N (docs/planning.md, "The robot's state at the tank").

    Parameters
    ----------
    theta_rad : ndarray, shape (N,)
        The shape's link angles, consistent along the body.
    seen_rad : ndarray, shape (N,)
        The camera's link angles, each in any 2 pi branch, NaN where a link was not read (at
        least one read).

    Returns
    -------
    ndarray, shape (N,)
        ``theta_rad`` turned by one angle.
    """
    seen = np.asarray(seen_rad, dtype=float)
    known = np.isfinite(seen)
    diff = seen[known] - theta_rad[known]
    diff = diff[0] + wrap_angle(diff - diff[0])
    return theta_rad + float(np.mean(diff))


def fill_unread_links(theta_rad: FloatArray, seen_rad: FloatArray, prior_rad: FloatArray,
                      prior_var_rad2: FloatArray | float, link_var_rad2: float) -> FloatArray:
    """Link angles by least squares from the links the camera read and the joints' prior.

    Minimises sum over read links (theta_i - seen_i)^2 / s_link^2 + sum over joints
    (theta_{j+1} - theta_j - prior_j)^2 / s_prior,j^2. A link not read between two read ones
    then takes its two joints' prior moved so that they add up to the angle between the read
    links (which the camera measured), instead of the prior's joints as they are: in a hard
    turn the gait's reference is 0.2-0.4 rad RMS from the PD joints (they lag it under load),
    and taking the reference's two joints as they are put the head 0.15 m off (docs/planning.md,
    "The robot's state at the tank").

    Parameters
    ----------
    theta_rad : ndarray, shape (N,)
        The shape placed on the read links (:func:`place_on_seen_links`): the 2 pi branch the
        read angles are taken in.
    seen_rad : ndarray, shape (N,)
        The camera's link angles, NaN where not read (at least one read).
    prior_rad : ndarray, shape (N - 1,)
        The joints' prior (telemetry or the gait's reference).
    prior_var_rad2 : float or ndarray (N - 1,)
    link_var_rad2 : float
        A read link angle's variance.

    Returns
    -------
    ndarray, shape (N,)
    """
    n = len(theta_rad)
    seen = np.asarray(seen_rad, dtype=float)
    known = np.isfinite(seen)
    # the read angles on the shape's branch (each within pi of the placed shape)
    target = np.where(known, theta_rad + wrap_angle(np.where(known, seen, 0.0) - theta_rad), 0.0)
    diff = np.diff(np.eye(n), axis=0)  # (N - 1, N): joint j = theta_{j+1} - theta_j
    w_joint = 1.0 / np.broadcast_to(np.asarray(prior_var_rad2, dtype=float), (n - 1,))
    w_link = known / link_var_rad2
    normal = np.diag(w_link) + diff.T @ (w_joint[:, None] * diff)
    rhs = w_link * target + diff.T @ (w_joint * np.asarray(prior_rad, dtype=float))
    return np.asarray(np.linalg.solve(normal, rhs), dtype=float)


def body_error_m(model: SwimmerModel, estimated: FloatArray, true: FloatArray) -> FloatArray:
    """How far an estimated body is from the true one: the largest distance of its points.

    Every joint and tip of the estimate is compared with the same point of the true body
    (:func:`eelhost.planning.body.link_endpoints`); each link is rigid, so a point's displacement
    is affine along the link and the largest over the whole centre line is at one of its ends.
    A point of the outline off the centre line (the link's half width b off it) moves by at most
    b times the link's angle error more. This is what a contact test on the estimated body can
    be wrong by (docs/planning.md, "The robot's state at the tank").

    Parameters
    ----------
    model : SwimmerModel
    estimated, true : ndarray, shape (K, 2 N + 4) or (K, N + 2)
        Link angles and centre of mass first (rates, if any, are not used).

    Returns
    -------
    ndarray, shape (K,)
        Metres, per state.
    """
    n = model.n_links
    est = np.atleast_2d(np.asarray(estimated, dtype=float))[:, : n + 2]
    tru = np.atleast_2d(np.asarray(true, dtype=float))[:, : n + 2]
    pad = np.zeros((len(est), n + 2))
    a = link_endpoints(model, np.concatenate([est, pad], axis=1))
    b = link_endpoints(model, np.concatenate([tru, pad], axis=1))
    return np.asarray(np.linalg.norm(a - b, axis=-1).max(axis=1), dtype=float)


def error_summary_mm(errors_m: FloatArray) -> dict[str, float]:
    """Median, 95th percentile and largest of body errors (:func:`body_error_m`), in mm.

    Parameters
    ----------
    errors_m : ndarray

    Returns
    -------
    dict
        ``frames``, ``p50_mm``, ``p95_mm``, ``max_mm`` (only ``frames`` = 0 when empty).
    """
    e = np.asarray(errors_m, dtype=float) * 1000.0
    if e.size == 0:
        return {"frames": 0}
    p50, p95 = np.percentile(e, [50, 95])
    return {"frames": int(e.size), "p50_mm": round(float(p50), 1),
            "p95_mm": round(float(p95), 1), "max_mm": round(float(e.max()), 1)}


def gait_link_angles(model: SwimmerModel, gait: Gait, t_s: float, heading_rad: float,
                     offset_rad: float = 0.0) -> FloatArray:
    """Link angles of a body following the gait's joint references exactly, at a mean heading.

    Joint j (between links j and j + 1, tail first) is at A_j sin(omega t + (j - 1) beta) + gamma
    with the tapered amplitude A_j = A (N - j) / (N + 1) (docs/model.md section 4,
    :func:`eelsim.control.gait_reference`).

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
    alpha, _ = gait_reference(t_s, gait, offset_rad, model.n_links)
    return links_from_joints(alpha, heading_rad)


def _state_name(state: int) -> str:
    """A Telemetry's robot state by its name (the number when the protocol has none)."""
    try:
        return protocol.State(state).name
    except ValueError:
        return str(state)


@dataclass(frozen=True)
class JointSample:
    """One accepted Telemetry, on the host's clock.

    Attributes
    ----------
    t_s : float
        When the robot sampled it, on the host's clock (since the gait started).
    phase_rad : float or None
        The gait's phase psi at ``t_s`` read from the references (None at zero amplitude).
    amplitude_rad, offset_rad : float
        The gait's (slewed) amplitude A and offset gamma at ``t_s``.
    phi_rad : ndarray (N - 1,) or None
        The measured joint angles (None: no feedback servos).
    """

    t_s: float
    phase_rad: float | None
    amplitude_rad: float
    offset_rad: float
    phi_rad: FloatArray | None


@dataclass(frozen=True)
class JointsAtFrame:
    """The telemetry's joint angles predicted to a frame's time.

    Attributes
    ----------
    phi_rad : ndarray, shape (N - 1,)
    measured : bool
        True: the robot's measured angles moved on with the reference; False: the reference.
    age_s : float
        Frame time minus the sample's time.
    """

    phi_rad: FloatArray
    measured: bool
    age_s: float


class TelemetryJoints:
    """The robot's joint angles and gait phase from its Telemetry (docs/planning.md).

    Each Telemetry carries the robot's clock ``time_us``, the references alpha_j it commands, the
    slewed amplitude A and offset gamma, and, with feedback servos (flag JOINT_FEEDBACK), the
    measured angles ``phi_mrad``. The robot's clock is put on the host's by the delays' bounds: a
    sample read at a poll at t_r arrived after the previous poll t_p, and was sent
    ``transit_s`` before it arrived, so the offset c = t_host - t_robot lies between
    max_k (t_p,k - t_robot,k) - transit_s and min_k (t_r,k - t_robot,k) - transit_s over the last
    ``clock_window`` samples; c is the middle of that interval (its upper end when the bounds
    cross). The phase
    psi at the sample is the least-squares solution of alpha_j - gamma = A_j sin(psi + (j - 1)
    beta). A sample is moved to the frame's time t by the gait: psi(t) = psi_s + omega (t -
    t_s), and the measured angle by the change of its own oscillation: over the last ``history``
    samples each joint is fitted, by least squares, as h_j(psi) = c_j + a_j sin(psi + (j - 1) beta)
    + b_j cos(psi + (j - 1) beta) (the joint follows the gait's phase with its own gain and lag),
    and phi_j(t) = phi_j(t_s) + h_j(psi(t)) - h_j(psi_s). Before 6 such samples the reference
    stands for h_j (a_j = A_j, b_j = 0).

    Samples are ignored, with the reason logged (the first of each reason as a warning, the
    rest counted in :attr:`ignored`): the robot not RUNNING, a wrong joint count, angles
    beyond ``limit_rad`` or not finite, a clock that went back or jumped ahead of the host's,
    and, at a frame, a newest sample older than ``max_age_s`` (stale).

    Parameters
    ----------
    model : SwimmerModel
    gait : Gait
        The gait sent to the robot (omega, beta).
    max_age_s : float
        Oldest sample used at a frame (the robot sends one every 0.1 s).
    limit_rad : float
        Largest joint angle taken as a measurement.
    clock_window : int
        Samples over which the delays' bounds are taken.
    transit_s : float
        The Telemetry's trip from the robot's clock to the host's transport.
    history : int
        Samples of measured angles in each joint's fit of its oscillation.
    offset_tolerance_rad : float
        A sample is not moved to a frame when the host's offset differs from the sample's by
        more (:meth:`at`); the fit takes the offset as a regressor when it moved by more over
        the history.
    """

    def __init__(self, model: SwimmerModel, gait: Gait, max_age_s: float = 0.3,
                 limit_rad: float = 1.6, clock_window: int = 50,
                 transit_s: float = TELEMETRY_TRANSIT_S, history: int = 16,
                 offset_tolerance_rad: float = 0.05) -> None:
        self.n_joints = model.n_links - 1
        self.gait = gait
        self.max_age_s = max_age_s
        self.limit_rad = limit_rad
        self.transit_s = transit_s
        self.offset_tolerance_rad = offset_tolerance_rad
        #: frames at which the newest sample was not used although fresh, by reason
        self.unused: dict[str, int] = {}
        self.phase_fit_rad = 0.005
        self._phase_at: tuple[float, float] | None = None  # (robot time, phase) of the last
        self._history: deque[JointSample] = deque(maxlen=max(int(history), 6))
        self._fit: FloatArray | None = None  # (N - 1, 2): a_j, b_j of the newest fit
        self.ratio = joint_amplitudes(1.0, model.n_links)
        self.lag = np.arange(self.n_joints) * gait.beta_rad
        self.latest: JointSample | None = None
        self.ignored: dict[str, int] = {}
        self._warned: set[str] = set()  # reasons already warned about (later ones at debug)
        self.taken = 0
        # (latest, earliest) offset t_host - t_robot each sample allows
        self._bounds: deque[tuple[float, float]] = deque(maxlen=max(int(clock_window), 1))
        self._wraps = 0
        self._last_raw_us: int | None = None
        self._last_rx_s = -math.inf
        self._last_robot_s = -math.inf
        self._stale_logged = False

    def _ignore(self, reason: str, detail: str, expected: bool = False) -> None:
        """Count a sample not taken; the first unexpected one of each reason is a warning."""
        self.ignored[reason] = self.ignored.get(reason, 0) + 1
        warn = not expected and reason not in self._warned
        if warn:
            self._warned.add(reason)
        (log.warning if warn else log.debug)(
            "telemetry ignored for the state estimate (%s): %s", reason, detail)

    def _robot_time_s(self, time_us: int) -> float:
        """The robot's clock unwrapped across its 32-bit wrap (not yet committed)."""
        wraps = self._wraps
        if self._last_raw_us is not None and time_us < self._last_raw_us - 2**31:
            wraps += 1
        return (wraps * 2**32 + time_us) * 1e-6

    def add(self, t_received_s: float, msg: protocol.Telemetry,
            t_polled_before_s: float | None = None) -> bool:
        """Take one Telemetry read at ``t_received_s`` (host clock since the gait started).

        Parameters
        ----------
        t_received_s : float
            The poll that read it.
        msg : protocol.Telemetry
        t_polled_before_s : float, optional
            The poll before it (the message arrived after it); none: no lower bound.

        Returns
        -------
        bool
            Whether it was accepted.
        """
        if msg.state != protocol.State.RUNNING:
            # before the first running sample the robot has not yet started its gait: every run
            # begins so, which is no news; once it has run, a robot that stops running is news
            self._ignore("not_running", f"robot state {_state_name(msg.state)} at time_us "
                         f"{msg.time_us}",
                         expected=self.taken == 0)
            return False
        alpha = np.asarray(msg.alpha_rad, dtype=float)
        phi_mrad = np.asarray(msg.phi_mrad, dtype=float)
        if len(alpha) != self.n_joints or len(phi_mrad) != self.n_joints:
            self._ignore("joint_count", f"{len(alpha)} references and {len(phi_mrad)} angles "
                                        f"for {self.n_joints} joints")
            return False
        t_robot = self._robot_time_s(int(msg.time_us))
        if t_robot <= self._last_robot_s:
            self._ignore("clock_back", f"time_us {msg.time_us} not after the previous sample")
            return False
        if (math.isfinite(self._last_robot_s)
                and t_robot - self._last_robot_s > (t_received_s - self._last_rx_s) + 1.0):
            self._ignore("clock_jump", f"the robot's clock moved {t_robot - self._last_robot_s:.3f}"
                                       f" s while {t_received_s - self._last_rx_s:.3f} s passed")
            return False
        gamma, amp = float(msg.offset_rad), float(msg.amplitude_rad)
        if not (np.all(np.isfinite(alpha)) and math.isfinite(gamma) and math.isfinite(amp)):
            self._ignore("garbled", f"references not finite at time_us {msg.time_us}")
            return False
        feedback = bool(msg.flags & protocol.Flags.JOINT_FEEDBACK)
        phi: FloatArray | None = None
        if feedback:
            phi = phi_mrad * 1e-3
            if np.any(phi_mrad == NO_ANGLE_MRAD) or np.any(np.abs(phi) > self.limit_rad):
                self._ignore("garbled", f"measured angles {msg.phi_mrad} mrad outside "
                                        f"+-{self.limit_rad:g} rad")
                return False
        if self._last_raw_us is not None and int(msg.time_us) < self._last_raw_us - 2**31:
            self._wraps += 1
        self._last_raw_us = int(msg.time_us)
        self._last_robot_s, self._last_rx_s = t_robot, t_received_s
        earliest = -math.inf if t_polled_before_s is None else t_polled_before_s - t_robot
        self._bounds.append((t_received_s - t_robot - self.transit_s,
                             earliest - self.transit_s))
        t_s = t_robot + self.clock_offset_s()
        self.latest = JointSample(t_s, self._phase(alpha, gamma, amp, t_robot), amp, gamma, phi)
        if phi is None or self.latest.phase_rad is None:
            self._history.clear()
            self._fit = None
        else:
            self._history.append(self.latest)
            self._fit = self._fit_oscillation()
        self._stale_logged = False
        self.taken += 1
        return True

    def _fit_oscillation(self) -> FloatArray | None:
        """Each joint's a_j, b_j over the history (class docstring); None before 6 samples."""
        if len(self._history) < 6:
            return None
        psi = np.array([h.phase_rad for h in self._history], dtype=float)
        phi = np.array([h.phi_rad for h in self._history], dtype=float)  # (K, N - 1)
        gamma = np.array([h.offset_rad for h in self._history], dtype=float)
        # the offset as a regressor when it moved over the history (steering), so its steps
        # do not leak into the swing's a_j, b_j
        steering = float(np.ptp(gamma)) > self.offset_tolerance_rad
        out = np.empty((self.n_joints, 2))
        for j in range(self.n_joints):
            arg = psi + self.lag[j]
            columns = [np.sin(arg), np.cos(arg), np.ones_like(psi)]
            if steering:
                columns.append(gamma)
            basis = np.stack(columns, axis=1)
            coef, _, rank, _ = np.linalg.lstsq(basis, phi[:, j], rcond=None)
            if rank < len(columns):
                return None
            out[j] = coef[:2]
        return out

    def _oscillation(self, phase_rad: float) -> FloatArray | None:
        """h_j(psi) - c_j of the newest fit (None without one)."""
        if self._fit is None:
            return None
        arg = phase_rad + self.lag
        return self._fit[:, 0] * np.sin(arg) + self._fit[:, 1] * np.cos(arg)

    def clock_offset_s(self) -> float:
        """The host's clock minus the robot's, from the delays' bounds (class docstring)."""
        hi = min(b[0] for b in self._bounds)
        lo = max(b[1] for b in self._bounds)
        return hi if not lo <= hi else 0.5 * (lo + hi)

    def _phase(self, alpha: FloatArray, gamma: float, amp: float, t_robot_s: float
               ) -> float | None:
        """The gait's phase psi at the sample (class docstring).

        Least squares on alpha_j - gamma = A_j (sin psi cos lag_j + cos psi sin lag_j) when the
        references fit the gait within ``phase_fit_rad`` RMS; otherwise (references clamped at
        the joint limits in a hard turn) the previous sample's phase moved on by omega times the
        robot's clock, which is exact while omega stays.
        """
        if amp < 1e-3:
            self._phase_at = None
            return None
        a = amp * self.ratio
        basis = np.stack([a * np.cos(self.lag), a * np.sin(self.lag)], axis=1)
        coef, *_ = np.linalg.lstsq(basis, alpha - gamma, rcond=None)
        misfit = float(np.sqrt(np.mean(np.square(basis @ coef - (alpha - gamma)))))
        psi: float | None = math.atan2(coef[0], coef[1])
        if misfit > self.phase_fit_rad or abs(math.hypot(*coef) - 1.0) > 0.05:
            prev = self._phase_at
            psi = (None if prev is None
                   else prev[1] + self.gait.omega_rad_s * (t_robot_s - prev[0]))
        self._phase_at = None if psi is None else (t_robot_s, psi)
        return psi

    def reference(self, phase_rad: float, amplitude_rad: float, offset_rad: float) -> FloatArray:
        """The gait's references alpha_j at phase psi (docs/model.md section 4)."""
        return amplitude_rad * self.ratio * np.sin(phase_rad + self.lag) + offset_rad

    def at(self, t_s: float, offset_rad: float | None = None) -> JointsAtFrame | None:
        """The newest sample's joint angles moved to ``t_s`` (None: none, stale, or steering).

        Parameters
        ----------
        t_s : float
            Frame time, host clock since the gait started.
        offset_rad : float, optional
            The offset the host last sent. When it differs from the sample's by more than
            ``offset_tolerance_rad`` the robot is changing its offset, which moves every joint
            by up to that much within the sample's age (the joints follow the step with their
            own lag): the sample is not moved across it, and None is returned (counted as
            ``offset_changing``).

        Returns
        -------
        JointsAtFrame or None
        """
        sample = self.latest
        if sample is None:
            return None
        if offset_rad is not None and abs(offset_rad - sample.offset_rad) > \
                self.offset_tolerance_rad:
            self.unused["offset_changing"] = self.unused.get("offset_changing", 0) + 1
            return None
        age = t_s - sample.t_s
        if age > self.max_age_s:
            if not self._stale_logged:
                self._ignore("stale", f"newest sample {age:.3f} s old at t = {t_s:.3f} s "
                                      f"(limit {self.max_age_s:g} s)")
                self._stale_logged = True
            return None
        if sample.phase_rad is None:
            ref_now = ref_then = np.full(self.n_joints, sample.offset_rad)
        else:
            psi_now = sample.phase_rad + self.gait.omega_rad_s * age
            ref_now = self.reference(psi_now, sample.amplitude_rad, sample.offset_rad)
            ref_then = self.reference(sample.phase_rad, sample.amplitude_rad, sample.offset_rad)
            own_now, own_then = self._oscillation(psi_now), self._oscillation(sample.phase_rad)
            if own_now is not None and own_then is not None:
                ref_now, ref_then = own_now, own_then
        if sample.phi_rad is not None:
            return JointsAtFrame(sample.phi_rad + (ref_now - ref_then), True, age)
        return JointsAtFrame(ref_now, False, age)


@dataclass(frozen=True)
class JointSources:
    """Standard deviations of the joint-angle sources, for their inverse-variance fusion.

    Attributes
    ----------
    camera_rad : float
        A joint angle from two of the camera's link angles.
    measured_rad : float
        A measured angle (ADC, calibration) at its sample time.
    measured_growth_rad_s : float
        Added per second of age: the reference's change stands for the joint's. Used until
        ``adapt_after`` frames have measured the telemetry's error against the camera.
    reference_rad : float
        The gait's reference standing for the joint's angle (servo lag, load).
    adapt_weight : float
        Weight of each frame in the running mean of the camera's and the telemetry's squared
        disagreement (:class:`BodyStateEstimator`).
    adapt_after : int
        Frames of disagreement before it sets the telemetry's variance.
    """

    camera_rad: float = 0.025
    measured_rad: float = 0.005
    measured_growth_rad_s: float = 0.3
    reference_rad: float = 0.15
    adapt_weight: float = 0.05
    adapt_after: int = 10


def fuse_joints(camera: FloatArray, camera_var: float, prior: FloatArray | None,
                prior_var: FloatArray | float) -> FloatArray:
    """Inverse-variance mean of two joint-angle estimates; NaN in one takes the other.

    Parameters
    ----------
    camera : ndarray, shape (N - 1,)
        NaN where the camera did not see both links of a joint.
    camera_var : float
    prior : ndarray (N - 1,) or None
    prior_var : float or ndarray (N - 1,)

    Returns
    -------
    ndarray, shape (N - 1,)
        NaN where neither has a value.
    """
    if prior is None:
        return camera.copy()
    w_c, w_p = 1.0 / camera_var, 1.0 / prior_var
    fused = (w_c * camera + w_p * prior) / (w_c + w_p)
    return np.where(np.isfinite(camera), fused, prior)


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
        Links whose angle the camera measured.
    joint_source : str
        What the newest frame's joint angles came from besides the camera: ``telemetry`` (the
        robot's measured angles), ``reference`` (the gait's reference at the telemetry's phase, or
        at the host's gait clock without telemetry) or ``camera`` (the camera alone).
    """

    t_s: float
    state: FloatArray
    measured_links: int
    joint_source: str = "camera"


class BodyStateEstimator:
    """The whole body state from the camera, the telemetry and the gait (module docstring).

    Parameters
    ----------
    model : SwimmerModel
    gait : Gait
    window : int
        Frames of the rate filter.
    sources : JointSources
        The joint-angle sources' standard deviations.
    use_reference : bool
        Fuse the gait's reference with the camera when no measured angles come (feedback-free
        servos); False: the reference only fills links the camera did not read.
    telemetry : TelemetryJoints, optional
        Where the Telemetry goes (:meth:`add_telemetry`); by default one with its defaults.
    """

    def __init__(self, model: SwimmerModel, gait: Gait, window: int = 7,
                 sources: JointSources | None = None, use_reference: bool = True,
                 telemetry: TelemetryJoints | None = None) -> None:
        self.model = model
        self.gait = gait
        self.window = max(int(window), 3)
        self.sources = sources or JointSources()
        self.use_reference = use_reference
        self.telemetry = telemetry or TelemetryJoints(model, gait)
        self._t: deque[float] = deque(maxlen=self.window)
        self._x: deque[FloatArray] = deque(maxlen=self.window)
        self._measured = 0
        self._source = "camera"
        self.frames_by_source: dict[str, int] = {}
        # running mean of (camera - telemetry)^2 per joint, and the frames in it
        self._disagreement = np.zeros(model.n_links - 1)
        self._disagreement_frames = np.zeros(model.n_links - 1, dtype=int)
        self.history: list[tuple[float, FloatArray]] | None = None
        """Set to a list to keep every frame's (t, link angles and centre of mass): benchmarks
        compare them with the true body (:func:`body_error_m`)."""

    def add_telemetry(self, t_received_s: float, msg: protocol.Telemetry,
                      t_polled_before_s: float | None = None) -> bool:
        """Take one Telemetry (:meth:`TelemetryJoints.add`)."""
        return self.telemetry.add(t_received_s, msg, t_polled_before_s)

    def telemetry_variance(self, age_s: float) -> FloatArray:
        """Each joint's variance of the telemetry's angle moved to a frame.

        The camera's and the telemetry's errors are independent, so their squared disagreement
        averages s_cam^2 + s_tel^2: once ``adapt_after`` frames have measured it,
        s_tel,j^2 = max(D_j - s_cam^2, s_m^2) with D_j its running mean (innovation-based, at the
        frames' own ages: the prediction's error, a jitter the 10 Hz samples cannot follow, a
        clock error, all in one); before, (s_m + g age)^2 with the defaults.

        Parameters
        ----------
        age_s : float

        Returns
        -------
        ndarray, shape (N - 1,)
        """
        s = self.sources
        start = (s.measured_rad + s.measured_growth_rad_s * abs(age_s)) ** 2
        adapted = np.maximum(self._disagreement - s.camera_rad**2, s.measured_rad**2)
        return np.where(self._disagreement_frames >= s.adapt_after, adapted, start)

    def disagreement_rad(self) -> FloatArray:
        """RMS of the camera's and the telemetry's joint angles' disagreement, per joint."""
        return np.sqrt(self._disagreement)

    def joint_prior(self, t_s: float, offset_rad: float
                    ) -> tuple[FloatArray, FloatArray | float, str]:
        """The joint angles at ``t_s`` besides the camera's, with their variance and source.

        The telemetry's measured angles when a fresh sample has them; else the gait's reference at
        the telemetry's phase (fresh sample without feedback) or at the host's gait clock and the
        offset last sent (no fresh telemetry).

        Returns
        -------
        phi_rad : ndarray (N - 1,)
        variance_rad2 : float or ndarray (N - 1,)
        source : str
            ``telemetry`` or ``reference``.
        """
        s = self.sources
        tel = self.telemetry.at(t_s, offset_rad)
        if tel is not None and tel.measured:
            return tel.phi_rad, self.telemetry_variance(tel.age_s), "telemetry"
        if tel is not None:
            return tel.phi_rad, s.reference_rad**2, "reference"
        alpha, _ = gait_reference(t_s, self.gait, offset_rad, self.model.n_links)
        return alpha, s.reference_rad**2, "reference"

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
            The offset the robot is steering with (the host's reference without telemetry).
        """
        seen = np.asarray(link_angles_rad, dtype=float)
        known = np.isfinite(seen)
        self._measured = int(known.sum())
        camera = np.diff(seen)
        # the camera's link angles unwrapped along the body, so a joint never sees a 2 pi jump
        camera = np.angle(np.exp(1j * camera))
        prior, var, source = self.joint_prior(t_s, offset_rad)
        if source == "reference" and not self.use_reference:
            var = 1e6  # only where the camera has no joint angle
            source = "camera"
        joints = fuse_joints(camera, self.sources.camera_rad**2, prior, var)
        if source == "telemetry":
            self._take_disagreement(camera - prior)
        self._source = source
        self.frames_by_source[source] = self.frames_by_source.get(source, 0) + 1
        if known.any():
            theta = place_on_seen_links(links_from_joints(joints, 0.0), seen)
            if not known.all():
                # the links read on both sides of an unread one fix its joints' sum: solve for
                # every link at once instead of taking the prior's two joints as they are
                link_var = 0.5 * self.sources.camera_rad**2  # a joint is two links' difference
                theta = fill_unread_links(theta, seen, prior, var, link_var)
        else:
            theta = links_from_joints(joints, self._last_heading())
        if self._x:
            # unwrap against the previous frame, so rates never see a 2 pi jump
            prev = self._x[-1][: self.model.n_links]
            theta = prev + np.angle(np.exp(1j * (theta - prev)))
        self._t.append(float(t_s))
        self._x.append(np.concatenate([theta, np.asarray(com_m, dtype=float)]))
        if self.history is not None:
            self.history.append((float(t_s), self._x[-1]))

    def _take_disagreement(self, diff: FloatArray) -> None:
        """Add a frame's camera-minus-telemetry joint angles to the running mean (NaN: unseen)."""
        seen = np.isfinite(diff)
        first = seen & (self._disagreement_frames == 0)
        w = self.sources.adapt_weight
        d2 = np.where(seen, np.square(np.nan_to_num(diff)), 0.0)
        self._disagreement = np.where(
            first, d2, np.where(seen, (1 - w) * self._disagreement + w * d2, self._disagreement))
        self._disagreement_frames = self._disagreement_frames + seen

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
        return BodyEstimate(float(t[-1]), state, self._measured, self._source)

    def summary(self) -> dict[str, object]:
        """For the take: frames by joint-angle source, Telemetry taken and ignored (by reason).

        Returns
        -------
        dict
        """
        return {"frames_by_joint_source": dict(self.frames_by_source),
                "camera_telemetry_disagreement_rad": [
                    round(float(v), 4) for v in self.disagreement_rad()],
                "telemetry_taken": self.telemetry.taken,
                "telemetry_ignored": dict(self.telemetry.ignored),
                "telemetry_unused_frames": dict(self.telemetry.unused)}

    def latest_pose(self) -> FloatArray | None:
        """The newest frame's link angles and centre of mass (no rate fit), (N + 2,)."""
        return self._x[-1].copy() if self._x else None


@dataclass
class CurrentWindow:
    """A stretch of the camera track the twin is compared over (:class:`CurrentEstimator`).

    Attributes
    ----------
    start, end : BodyEstimate
        The estimates at its first and last frame.
    waypoint_m : (float, float)
        The one waypoint the robot steered to throughout.
    guide : tuple of float or None
        The run loop's guidance state at ``start`` (leg start, ILOS integral).
    assumed_m_s : ndarray, shape (2,)
        The estimate when the window closed: the twin predicts in it.
    """

    start: BodyEstimate
    end: BodyEstimate
    waypoint_m: tuple[float, float]
    guide: tuple[float, ...] | None = None
    assumed_m_s: FloatArray = None  # type: ignore[assignment]

    @property
    def span_s(self) -> float:
        """Length of the window."""
        return self.end.t_s - self.start.t_s


def steady_towards(pose: FloatArray, waypoint_m: tuple[float, float], limit_rad: float) -> bool:
    """Whether the robot at ``pose`` (x, y, heading) faces its waypoint within ``limit_rad``.

    Pure pursuit steers by the bearing error, wrapped to (-pi, pi]: with the waypoint near
    behind, the side it turns to flips with a tiny change of pose, so the twin and the robot
    may turn opposite ways (docs/planning.md, "The current's windows").
    """
    bearing = math.atan2(waypoint_m[1] - pose[1], waypoint_m[0] - pose[0])
    return abs(float(wrap_angle(bearing - float(pose[2])))) <= limit_rad


@dataclass
class CurrentEstimator:
    """The water's unknown current, from the camera track against the twin's prediction.

    Over each window the twin predicts where the centre of mass goes from the window's first
    estimated state, in the current the planner assumes plus the estimate ``a`` of the moment;
    the camera says where it went. In a uniform current the twin's body drifts with the water
    (drag and added mass act on the velocity relative to it), so the track drifts from the
    prediction at the velocity of the current the twin lacks: ``c = a + drift`` is the window's
    sample of the current, and the estimate moves by ``gain`` times ``c`` less the estimate
    (kept within ``max_m_s``), so windows compared in any order each count once. A robot that
    swims slower or faster than its coefficients say shows up the same way, along its heading
    (docs/planning.md says what that costs).

    The comparison holds only while the twin swims the manoeuvre the robot swam, so a window
    (:meth:`track`) covers frames on which the robot steers to one waypoint that it faces within
    ``max_bearing_rad``: it ends at the last such frame before the robot reaches the waypoint,
    turns towards one beside or behind it, or gets new waypoints (:meth:`drop`), or after
    ``window_s``; shorter than ``min_window_s``, it is not compared. Across a waypoint the twin
    and the robot accept it at different moments, and in a turn towards a waypoint behind the
    body they may turn opposite ways: on the development runs such windows drifted by up to
    0.14 m/s in still water the twin knew (docs/planning.md, "The current's windows").

    Attributes
    ----------
    window_s : float
        Longest comparison window.
    gain : float
        Fraction of a window's sample taken into the estimate.
    max_m_s : float
        Largest speed the estimate may reach.
    min_window_s : float
        Shortest window compared.
    max_bearing_rad : float
        Largest bearing error of the waypoint within a window.
    value_m_s : ndarray, shape (2,)
        The estimate, added to the planner's current.
    history : list of dict
        Every update: time, window start, drift velocity, estimate.
    """

    window_s: float = 3.0
    gain: float = 0.6
    max_m_s: float = 0.08
    min_window_s: float = 1.5
    max_bearing_rad: float = math.radians(60.0)
    value_m_s: FloatArray = None  # type: ignore[assignment]
    history: list[dict] = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        if self.value_m_s is None:
            self.value_m_s = np.zeros(2)
        if self.history is None:
            self.history = []
        self._open: CurrentWindow | None = None

    def track(self, est: BodyEstimate, pose: FloatArray, waypoint_m: tuple[float, float] | None,
              guide: tuple[float, ...] | None = None) -> CurrentWindow | None:
        """Take one frame into the windows; return a window that closed and is to be compared.

        Parameters
        ----------
        est : BodyEstimate
            The frame's body estimate.
        pose : ndarray (3,)
            The guidance's filtered (x, y, heading): what the robot steers by.
        waypoint_m : (float, float) or None
            The waypoint the robot steers to (None: none left).
        guide : tuple, optional
            The run loop's guidance state at this frame (kept with a window that starts here).

        Returns
        -------
        CurrentWindow or None
            A window of at least ``min_window_s`` that ended, with ``assumed_m_s`` set.
        """
        steady = waypoint_m is not None and steady_towards(pose, waypoint_m,
                                                           self.max_bearing_rad)
        window, closed = self._open, None
        if window is not None:
            same = steady and tuple(waypoint_m) == window.waypoint_m  # type: ignore[arg-type]
            if not same or est.t_s - window.start.t_s >= self.window_s:
                if same:
                    window.end = est
                closed = window if window.span_s >= self.min_window_s - 1e-9 else None
                self._open = window = None
            else:
                window.end = est
        if window is None and steady:
            wp = (float(waypoint_m[0]), float(waypoint_m[1]))  # type: ignore[index]
            self._open = CurrentWindow(est, est, wp, guide)
        if closed is not None:
            closed.assumed_m_s = self.value_m_s.copy()
        return closed

    def drop(self) -> None:
        """Forget the open window (the robot was given new waypoints)."""
        self._open = None

    def update(self, t_s: float, predicted_m: FloatArray, measured_m: FloatArray,
               span_s: float, assumed_m_s: FloatArray | None = None) -> FloatArray:
        """Take one window's comparison into the estimate.

        Parameters
        ----------
        t_s : float
            End of the window.
        predicted_m, measured_m : ndarray, shape (2,)
            Where the twin put the centre of mass and where the camera saw it.
        span_s : float
            Length of the window.
        assumed_m_s : ndarray (2,), optional
            The estimate the twin predicted in (default: the present one).

        Returns
        -------
        ndarray, shape (2,)
            The new estimate.
        """
        drift = (np.asarray(measured_m, float) - np.asarray(predicted_m, float)) / span_s
        assumed = self.value_m_s if assumed_m_s is None else np.asarray(assumed_m_s, float)
        sample = assumed + drift  # this window's own measure of the current
        value = self.value_m_s + self.gain * (sample - self.value_m_s)
        speed = float(math.hypot(*value))
        if speed > self.max_m_s:
            value = value * (self.max_m_s / speed)
        self.value_m_s = value
        self.history.append({"t_s": round(float(t_s), 3),
                             "t_start_s": round(float(t_s - span_s), 3),
                             "drift_m_s": [round(float(v), 4) for v in drift],
                             "sample_m_s": [round(float(v), 4) for v in sample],
                             "current_m_s": [round(float(v), 4) for v in value]})
        return value
