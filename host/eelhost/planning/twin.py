"""Closed-loop runs of the twin that start from any state at any time (docs/planning.md, "The twin").

The planner swims every manoeuvre from the state the previous one left: the body's shape, speed,
turn and the gait's phase, not from a fresh straight robot at rest. ``eelsim.batch`` always starts
a run from the scenario's straight robot at rest with the gait at phase 0; this module starts it
from a given state at a given time of the task by changing two inputs of the prepared batch
(:class:`eelsim.batch.BatchSpec`) before it runs:

- ``initial_state``, one row per run;
- the gait phase: joint j's reference is A_j sin(omega t + (j - 1) beta) (docs/model.md
  section 4), and the kernel keeps cos and sin of (j - 1) beta per run; adding omega t0 to those
  angles runs the gait as if the run had started at t0.

A run restarted at a step that is a whole number of control periods and camera frames into the
task sees its control updates and camera frames at the same times as the task's own run, so it
reproduces that run except for its first offset, which it computes from a median filter holding
one frame instead of five (a few millimetres over a manoeuvre; ``test_planning_twin`` checks it
against an uninterrupted run). With the integral line-of-sight guidance the restart also needs the
guidance's own state (where the present leg starts, the integral vector: docs/model.md section 4):
:meth:`Twin.run` takes it per run and :class:`Runs` returns it at every sample. The twin has no public way to do this (yet); this module is the one
place that relies on the batch's row layout (``eelsim.batch.codegen.make_layout``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from numpy.typing import NDArray

from eelsim.batch import DEFAULT_LANES, BatchSpec, codegen, run_spec
from eelsim.closed_loop import LoopOptions
from eelsim.control import Gait
from eelsim.fluid import FluidCoefficients
from eelsim.model import SwimmerModel
from eelsim.robot import Robot
from eelsim.scenario import Scenario

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def restart_period_steps(options: LoopOptions) -> int:
    """Smallest step count that is a whole number of control periods and of camera frames.

    Runs restarted at multiples of it see their control updates and frames when an uninterrupted
    run would (0.3 s, 30 steps, with the tank's timing).

    Parameters
    ----------
    options : LoopOptions

    Returns
    -------
    int
        0 when no multiple up to 100 control periods fits (the restarts are then approximate).
    """
    timing = options.timing
    frame = Fraction(options.camera.fps).limit_denominator(10_000)
    for k in range(1, 101):
        steps = k * timing.period_steps
        frames = steps * Fraction(timing.dt_s).limit_denominator(1_000_000) * frame
        if frames.denominator == 1:
            return steps
    return 0


@dataclass(frozen=True)
class Runs:
    """What a batch of restarted runs produced (R runs, S samples).

    Attributes
    ----------
    stride : int
        Physics steps between samples; sample s is at local step s * stride.
    states : ndarray, shape (R, S, 2 N + 4)
        Sampled states, NaN after a run ended.
    arrival_step : ndarray of int, shape (R,)
        Local step at which the last waypoint was accepted (the step whose interval holds the
        camera frame that accepted it), -1 if never.
    final_step : ndarray of int, shape (R,)
        Local step at which the run stopped.
    reasons : list of str
        The twin's failure flag of each run ("" when none; a run that did not reach its last
        waypoint in time is flagged too slow).
    integral_s : ndarray, shape (R, S, 2)
        The guidance's ILOS integral vector at each sample, before that step's control update
        (zero with pure pursuit; NaN after a run ended): with the sampled state, what a run
        restarted there starts from.
    """

    stride: int
    states: FloatArray
    arrival_step: IntArray
    final_step: IntArray
    reasons: list[str]
    integral_s: FloatArray

    def guidance_state(self, run: int, sample: int,
                       leg_start_m: tuple[float, float]) -> tuple[float, float, float, float]:
        """The guidance state to restart run ``run`` at sample ``sample`` (:meth:`Twin.run`).

        Parameters
        ----------
        run, sample : int
        leg_start_m : (x, y)
            Where the leg being swum at that sample starts (the waypoint before the one steered
            to, or the run's own first-leg start).

        Returns
        -------
        (x, y, I_x, I_y)
        """
        g = self.integral_s[run, sample]
        return (float(leg_start_m[0]), float(leg_start_m[1]), float(g[0]), float(g[1]))


class Twin:
    """The robot's closed loop in a uniform current, run in batches from any state.

    Parameters
    ----------
    robot : Robot
    coefficients : sequence of FluidCoefficients
        The coefficient sets a run may use (by index).
    gait : Gait
        Gait and heading gain.
    options : LoopOptions
        Loop timing and camera (the tank's); runs stop at their last waypoint.
    current_m_s : (float, float)
        Current velocity.
    acceptance_radius_m : float
        Waypoint acceptance radius of the guidance.
    threads : int or None
        Threads of the batched kernel.
    swimmer : SwimmerModel, optional
        The robot's model (:meth:`eelsim.model.SwimmerModel.from_robot`), built once by the
        command and handed on (docs/architecture.md, "The planning room"); built from ``robot``
        on first use when not given. Its body is the planner's and the check's, and the batch's
        step check reads it (``BatchSpec.build``'s ``models``).
    """

    def __init__(
        self,
        robot: Robot,
        coefficients: Sequence[FluidCoefficients],
        gait: Gait,
        options: LoopOptions,
        current_m_s: tuple[float, float],
        acceptance_radius_m: float = 0.15,
        threads: int | None = 1,
        swimmer: SwimmerModel | None = None,
    ) -> None:
        if not coefficients:
            raise ValueError("the twin needs at least one coefficient set")
        self.robot = robot
        self.coefficients = list(coefficients)
        self.gait = gait
        self.options = dataclasses.replace(options, stop_at_goal=True)
        self.current_m_s = (float(current_m_s[0]), float(current_m_s[1]))
        self.acceptance_radius_m = float(acceptance_radius_m)
        self.threads = threads
        self._model = swimmer
        self.dt_s = self.options.timing.dt_s
        self.restart_steps = restart_period_steps(self.options)
        self.n_links = robot.n_links
        self._layout = codegen.make_layout(robot.n_links, DEFAULT_LANES, robot.fluid_law)
        self._speed = math.hypot(*self.current_m_s)
        self._direction_deg = (
            math.degrees(math.atan2(self.current_m_s[1], self.current_m_s[0])) if self._speed else 0
        )

    @property
    def model(self) -> SwimmerModel:
        """The robot's model: the one handed in, else built from the robot once."""
        if self._model is None:
            self._model = SwimmerModel.from_robot(self.robot)
        return self._model

    def scenario(
        self,
        waypoints: Sequence[tuple[float, float]],
        duration_s: float,
        start: tuple[float, float, float] = (0.0, 0.0, 0.0),
        current_m_s: tuple[float, float] | None = None,
    ) -> Scenario:
        """The scenario of a run from rest: the gait, the waypoints, the current.

        Parameters
        ----------
        waypoints : sequence of (x, y)
        duration_s : float
            T_max.
        start : (x, y, heading_rad)
            Start pose of the straight robot at rest.
        current_m_s : (float, float), optional
            This run's current velocity (default: the twin's).

        Returns
        -------
        Scenario
        """
        g = self.gait
        speed, direction = self._speed, self._direction_deg
        if current_m_s is not None:
            speed = math.hypot(*current_m_s)
            direction = math.degrees(math.atan2(current_m_s[1], current_m_s[0])) if speed else 0.0
        return Scenario.swimming(
            g,
            name="planning",
            waypoints_m=[(float(x), float(y)) for x, y in waypoints],
            acceptance_radius_m=self.acceptance_radius_m,
            current_speed_m_s=speed,
            current_direction_deg=direction,
            duration_s=duration_s,
            start_position_m=(float(start[0]), float(start[1])),
            start_heading_deg=math.degrees(start[2]),
        )

    def _rows(self, name: str, size: int) -> slice:
        first = self._layout.work[name] - self._layout.work["geometry"]
        return slice(first, first + size)

    def run(
        self,
        waypoints: Sequence[Sequence[tuple[float, float]]],
        duration_s: float | Sequence[float],
        states: FloatArray | None = None,
        start_steps: Sequence[int] | IntArray | None = None,
        coefficient_index: Sequence[int] | IntArray | None = None,
        stride: int = 3,
        starts: Sequence[tuple[float, float, float]] | None = None,
        currents: Sequence[tuple[float, float]] | None = None,
        guidance: Sequence[Sequence[float]] | None = None,
        phase_rad: Sequence[float] | None = None,
    ) -> Runs:
        """Run R closed-loop manoeuvres at once.

        Parameters
        ----------
        waypoints : sequence of R waypoint lists
        duration_s : float or sequence of R floats
            Time limit of each run (from its own start).
        states : ndarray, shape (R, 2 N + 4), optional
            Start states (default: straight at rest at ``starts``).
        start_steps : sequence of R ints, optional
            The step of the task at which each run starts (its gait phase); restarts are exact at
            multiples of :attr:`restart_steps`. Default 0.
        coefficient_index : sequence of R ints, optional
            Which coefficient set each run uses (default 0).
        stride : int
            Steps between samples.
        starts : sequence of R (x, y, heading_rad), optional
            Start poses of runs from rest (ignored where ``states`` is given).
        currents : sequence of R (vx, vy), optional
            Each run's current velocity, m/s (default: the twin's for every run); the planner's
            check swims its draws of the water this way, many currents in one batch.
        guidance : sequence of R (x, y, I_x, I_y), optional
            Each run's guidance state at its start (``eelsim.batch.BatchSpec.guidance_state``):
            where the leg to its first waypoint starts and the ILOS integral vector, as the run
            it continues left them (:meth:`Runs.guidance_state`). Default: the first leg from
            the first filtered pose, the integral zero. Only the ILOS law reads it.
        phase_rad : sequence of R floats, optional
            Each run's gait phase in place of the gait's own ``phase_rad`` (the braked robots of
            the planner's arrival stops, each frozen at its own phase; docs/planning.md, "The
            arrival's stop in the check"). Default: the gait's for every run.

        Returns
        -------
        Runs
        """
        r = len(waypoints)
        durations = np.broadcast_to(np.asarray(duration_s, dtype=float), (r,))
        poses = list(starts) if starts is not None else [(0.0, 0.0, 0.0)] * r
        flows = list(currents) if currents is not None else [None] * r
        scenarios = [self.scenario(w, float(d), p, c)
                     for w, d, p, c in zip(waypoints, durations, poses, flows, strict=True)]
        index = (np.zeros(r, dtype=np.int64) if coefficient_index is None
                 else np.asarray(coefficient_index, dtype=np.int64))
        coeffs = [self.coefficients[i] for i in index]
        spec = BatchSpec.build(self.robot, scenarios, coeffs, self.options, 0, models=self.model)
        changes: dict = {}
        if states is not None:
            changes["initial_state"] = np.asarray(states, dtype=float).reshape(r, -1).copy()
        g = self.gait
        t0 = (np.zeros(r) if start_steps is None
              else np.asarray(start_steps, dtype=float) * self.dt_s)
        own = (np.full(r, g.phase_rad) if phase_rad is None
               else np.asarray(phase_rad, dtype=float))
        if np.any(t0 != 0) or np.any(own != 0.0):
            # the kernel's gait phase is omega t + (j - 1) beta from its own t = 0: a run started
            # later, or a gait with a phase of its own (a braked robot's frozen one), carries the
            # difference in the per-joint phase rows
            params = spec.params.copy()
            n = self.n_links
            phase = (np.arange(n - 1)[None, :] * g.beta_rad
                     + g.omega_rad_s * t0[:, None] + own[:, None])
            params[:, self._rows("cos_beta", n - 1)] = np.cos(phase)
            params[:, self._rows("sin_beta", n - 1)] = np.sin(phase)
            changes["params"] = params
        if guidance is not None:
            changes["guidance_state"] = np.asarray(guidance, dtype=float).reshape(r, 4).copy()
        if changes:
            spec = dataclasses.replace(spec, **changes)
        longest = int(spec.total_steps.max())
        res = run_spec(spec, sample_steps=np.arange(0, longest + 1, stride), threads=self.threads)
        arrival = np.where(
            np.isfinite(res.arrival_time_s),
            np.ceil(res.arrival_time_s / self.dt_s - 1e-6),
            -1,
        ).astype(np.int64)
        integral = (res.integral_s if res.integral_s is not None
                    else np.zeros((r, res.states.shape[1], 2)))
        return Runs(stride, res.states, arrival, res.final_step.astype(np.int64),
                    [res.reason(i) for i in range(r)], integral)
