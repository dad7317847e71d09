"""What a backend simulates and returns: prepared experiments, their simulations, the interface.

:func:`prepare` turns an experiment into what every backend runs: its task, run for T_max =
``tmax_factor`` times the recorded span so that a slightly slow candidate is not flagged too slow by
the clock's noise (but ended at its goal once the last state compared is simulated), with the
sample times of the fitness, seen through the camera the recording declares (frame rate, median
filter causal or centred; docs/data.md). A backend (:class:`SimulationBackend`) runs every
(candidate, experiment) pair and returns a :class:`Simulated`; the
:class:`~eelhost.estimation.evaluate.Evaluator` scores it. The backends:
:class:`~eelhost.estimation.batch_backend.BatchBackend` (the batched kernel, optionally spread
over a Dask cluster, :mod:`eelhost.estimation.cluster`) and
:class:`~eelhost.estimation.reference_backend.ReferenceBackend` (the readable closed loop).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from eelhost.data.experiments import Experiment
from eelhost.estimation.fitness import sample_times
from eelhost.estimation.space import ParameterSpace
from eelsim.camera import observation_steps, observed_positions
from eelsim.closed_loop import LoopOptions
from eelsim.flags import Failure
from eelsim.robot import Robot
from eelsim.scenario import Scenario
from eelsim.timing import LoopTiming

TMAX_FACTOR = 1.5
# The paper's stated time-stamp uncertainty, s: what a recording that declares none is read to
# have (``Experiment.timestamp_jitter_s``), and so the validation's clock search there.
ALIGN_S = 0.1
ALIGN_STEP_S = 0.01


def declared_clock_bound_s(exp: Experiment) -> float:
    """Half-width of the validation's clock-offset search for a recording: what it declares.

    The camera's ``timestamp_jitter_s`` (docs/data.md; ``ALIGN_S`` where it declares none): the
    bound is a statement about the recording's clock, so a hardware-triggered camera that
    declares 0 is compared on its own clock only (docs/estimation.md, "Validation").
    """
    return exp.timestamp_jitter_s


def clock_shifts(align_s: float) -> np.ndarray:
    """The candidate clock offsets within +-``align_s``, ``ALIGN_STEP_S`` apart (just 0 for 0)."""
    half = int(round(align_s / ALIGN_STEP_S))
    return np.arange(-half, half + 1) * ALIGN_STEP_S


@dataclass(frozen=True)
class PreparedExperiment:
    """One experiment ready to simulate.

    Attributes
    ----------
    experiment : Experiment
    scenario : Scenario
        The task with duration T_max.
    options : LoopOptions
        Loop timing and camera as recorded (no jitter: its realisation is unknown).
    times_s : ndarray
        Sample times.
    exp_positions_m : ndarray, shape (n, 2)
        The experiment's centre of mass at the sample times.
    shifts_s : ndarray, shape (M,)
        Candidate clock offsets of the recording (just 0 without alignment).
    shifted_positions_m : ndarray, shape (M, n, 2)
        The experiment's centre of mass at ``times_s + shift`` for each shift.
    state_steps : ndarray of int
        The physics steps whose simulated states are needed.
    observe : bool
        Compare the simulation as the camera saw it (frames, median filter) rather than its true
        centre of mass.
    last_time_s : float
        The recording's last frame time (a centred median holds no frame after it).
    """

    experiment: Experiment
    scenario: Scenario
    options: LoopOptions
    times_s: np.ndarray
    exp_positions_m: np.ndarray
    shifts_s: np.ndarray
    shifted_positions_m: np.ndarray
    state_steps: np.ndarray
    observe: bool = True
    last_time_s: float | None = None

    def positions(self, states: np.ndarray, n_links: int) -> tuple[np.ndarray, np.ndarray]:
        """Simulated centre of mass and heading at the sample times from states at ``state_steps``.

        Parameters
        ----------
        states : ndarray, shape (C, S, 2 N + 4)
            NaN where a run had already ended.
        n_links : int

        Returns
        -------
        positions : ndarray, shape (C, n, 2)
        heading : ndarray, shape (C, n)
        """
        dt = self.options.timing.dt_s
        at = np.searchsorted(self.state_steps, np.round(self.times_s / dt).astype(np.int64))
        heading = states[:, at, :n_links].mean(axis=-1)
        if not self.observe:
            return states[:, at, n_links : n_links + 2], heading
        # The camera's frames and median filter, but not its pixel rounding: rounding would make the
        # objective piecewise constant (finite differences, the least-squares polish, the bootstrap
        # and the identifiability Jacobian would all see zero slopes); in the recording it is a
        # zero-mean +-half-pixel noise that needs no reproducing.
        smooth_camera = dataclasses.replace(self.options.camera, pixel_m=0.0)
        com = states[:, :, n_links : n_links + 2]
        pos = observed_positions(
            self.times_s, self.state_steps, com, states[:, :, -2:], smooth_camera, dt,
            self.last_time_s,
        )
        # a run that ended before the last state needed (its later rows are NaN) has no camera
        # view there
        pos[np.isnan(com).any(axis=(1, 2))] = np.nan
        return pos, heading

    def scenario_in(self, current_m_s: np.ndarray) -> Scenario:
        """The task in a tank with an ambient current ``current_m_s`` (v_x, v_y, m/s).

        It adds to the current the experiment declares.
        """
        return self.scenario.with_added_current((current_m_s[0], current_m_s[1]))


def prepare(
    exp: Experiment,
    n_samples: int,
    dt_s: float = 0.01,
    tmax_factor: float = TMAX_FACTOR,
    align_s: float = 0.0,
    observe: bool = True,
    servo_limits: bool = False,
) -> PreparedExperiment:
    """Prepare an experiment for simulation with ``n_samples`` sample times.

    With ``align_s`` > 0 the recording's unknown clock offset is treated as a nuisance parameter:
    the experiment is also sampled at ``times + shift`` for shifts in [-align_s, align_s] (0.01 s
    apart), and the error of a simulation is its smallest over the shifts. Only the densely recorded
    experiment is shifted, so this costs no extra simulation.

    With ``observe`` (the default) the simulation is compared as the experiment's camera would
    have seen it (:func:`eelsim.camera.observed_positions` with the camera the recording declares:
    the same frames and median filter, causal or centred), not by its true centre of mass, so that
    the camera's filter lag is not blamed on the coefficients.

    With ``servo_limits`` the PD joints' torques are clipped to the servos' torque-speed line
    (``LoopOptions.servo_limits``; docs/model.md section 4): a plant known to run on that line,
    such as a test plant's own robot swum as the floor of ``eelbot estimate-bench``.
    """
    t0, t1 = exp.span_s
    times = sample_times(t0, t1, n_samples, dt_s)
    tmax = float(np.ceil(tmax_factor * t1 / dt_s)) * dt_s
    shifts = clock_shifts(align_s)
    camera = exp.recording_camera()
    timing = LoopTiming(
        dt_s=dt_s,
        control_period_s=float(exp.timing.get("control_period_s", 0.3)),
        extra_delay_s=float(exp.timing.get("extra_delay_s", 0.0)),
    )
    state_steps = np.union1d(
        np.round(times / dt_s).astype(np.int64),
        observation_steps(times, camera, dt_s, t1) if observe else np.zeros(0, dtype=np.int64),
    )
    # A run ends at T_max, or at its goal once the last state compared has been reached: after
    # both, nothing it does can count (see Simulated.counted_failure), so it need not be run.
    last_s = float(state_steps[-1]) * dt_s
    return PreparedExperiment(
        experiment=exp,
        scenario=exp.scenario.model_copy(update={"duration_s": tmax, "min_duration_s": last_s}),
        options=LoopOptions(timing=timing, camera=camera, servo_limits=servo_limits,
                            stop_at_goal=True),
        times_s=times,
        exp_positions_m=exp.position_at(times),
        shifts_s=shifts,
        shifted_positions_m=np.stack([exp.position_at(times + d) for d in shifts]),
        state_steps=state_steps,
        observe=observe,
        last_time_s=t1,
    )


@dataclass
class Simulated:
    """Simulations of C candidates on E experiments.

    Attributes
    ----------
    positions_m : ndarray, shape (C, E, n, 2)
        Centre of mass at the sample times (NaN where a run failed before them).
    heading_rad : ndarray, shape (C, E, n)
        Heading at the sample times (NaN likewise).
    failure : ndarray of int, shape (C, E)
        :class:`eelsim.flags.Failure` codes.
    distance_left_m : ndarray, shape (C, E)
    arrival_time_s : ndarray, shape (C, E)
        When the last waypoint was reached (NaN: never).
    failure_time_s : ndarray, shape (C, E)
        When the failure was detected (NaN: none).
    steps : ndarray of int, shape (C, E)
        RK4 steps each run took.
    """

    positions_m: np.ndarray
    heading_rad: np.ndarray
    failure: np.ndarray
    distance_left_m: np.ndarray
    arrival_time_s: np.ndarray
    failure_time_s: np.ndarray
    steps: np.ndarray

    def take(self, rows: slice) -> Simulated:
        """The simulations of some candidates (rows of every array)."""
        return Simulated(*(getattr(self, f.name)[rows] for f in dataclasses.fields(self)))

    def counted_failure(self, prepared: Sequence[PreparedExperiment]) -> np.ndarray:
        """Failure codes that count against a candidate, shape (C, E).

        A run continues past the recording so that a slightly slow candidate can still arrive;
        a failure after both its arrival and the last sample time (e.g. circling the last waypoint
        until a joint reaches its stop) happens where there is no data and does not count.
        """
        out = self.failure.copy()
        for j, p in enumerate(prepared):
            after_data = (self.failure_time_s[:, j] > p.times_s[-1]) & (
                self.arrival_time_s[:, j] <= self.failure_time_s[:, j]
            )
            late = after_data & (self.failure[:, j] != int(Failure.TOO_SLOW))
            out[late, j] = int(Failure.NONE)
        return out


class SimulationBackend(Protocol):
    """Runs every (candidate, experiment) pair of an evaluation.

    An :class:`~eelhost.estimation.evaluate.Evaluator` holds one and hands it the candidates'
    robots and parameter vectors; the backend never needs the evaluator.
    """

    def simulate(
        self,
        robots: Sequence[Robot],
        prepared: Sequence[PreparedExperiment],
        parameters: np.ndarray,
        space: ParameterSpace,
    ) -> Simulated:
        """Simulate every prepared experiment for every candidate.

        Parameters
        ----------
        robots : sequence of Robot
            Each candidate's robot (its joint parameters; the same object when none are fitted).
        prepared : sequence of PreparedExperiment
        parameters : ndarray, shape (C, K)
            Candidates, vectors of ``space``.
        space : ParameterSpace

        Returns
        -------
        Simulated
        """
        ...

    def fresh(self) -> SimulationBackend:
        """The same backend with nothing learned from earlier calls (for another space)."""
        ...
