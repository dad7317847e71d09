"""Steady swimming speed of the twin over the paper's gait grid (used to calibrate the defaults).

The robot starts straight at rest and swims under the closed loop towards a waypoint far ahead (so
it never arrives and never turns); the steady speed is the centre of mass's displacement over the
second half of the run divided by its duration, which averages over whole gait cycles well enough
(the half-run spans more than ten cycles at every gait of the grid).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.fluid import FluidCoefficients
from eelsim.robot import Robot
from eelsim.scenario import GRID_AMPLITUDES_RAD, GRID_OMEGAS_RAD_S, grid_scenario


def steady_speed(
    robot: Robot,
    amplitude_rad: float,
    omega_rad_s: float,
    duration_s: float = 20.0,
    coefficients: FluidCoefficients | None = None,
) -> tuple[float, bool]:
    """Steady forward speed of one gait and whether it swam head first.

    Parameters
    ----------
    robot : Robot
    amplitude_rad, omega_rad_s : float
        The gait (beta = 1.04 rad, straight-motion gain).
    duration_s : float
        Length of the run.
    coefficients : FluidCoefficients, optional
        Overrides the robot's coefficients.

    Returns
    -------
    speed_m_s : float
        Mean speed over the second half of the run (NaN if the run failed).
    head_first : bool
        True when the robot moved along the direction its head points to.
    """
    far = grid_scenario("straight", amplitude_rad, omega_rad_s).model_copy(
        update={"duration_s": duration_s, "waypoints_m": [(100.0, 0.0)]}
    )
    res = simulate_closed_loop(
        robot, far, LoopOptions(stop_at_goal=False), coefficients=coefficients
    )
    if res.failure.name not in ("NONE", "TOO_SLOW"):
        return float("nan"), False
    n = robot.n_links
    p, t = res.states[:, n : n + 2], res.t_s
    half = t >= t[-1] / 2
    disp = p[-1] - p[half][0]
    speed = float(np.linalg.norm(disp) / (t[-1] - t[half][0]))
    heading = float(np.mean(res.states[half][:, :n]))
    head_first = float(np.dot(disp, [np.cos(heading), np.sin(heading)])) > 0
    return speed, head_first


def grid_speeds(
    robot: Robot,
    duration_s: float = 20.0,
    coefficients: FluidCoefficients | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """Steady speeds over the 4 x 4 grid, shape (4 amplitudes, 4 frequencies), m/s.

    Backward or failed swimming is reported as NaN. ``progress(done, total)`` is called after
    each gait.
    """
    out = np.empty((len(GRID_AMPLITUDES_RAD), len(GRID_OMEGAS_RAD_S)))
    for i, a in enumerate(GRID_AMPLITUDES_RAD):
        for j, w in enumerate(GRID_OMEGAS_RAD_S):
            v, forward = steady_speed(robot, a, w, duration_s, coefficients)
            out[i, j] = v if forward else float("nan")
            if progress is not None:
                progress(i * len(GRID_OMEGAS_RAD_S) + j + 1, out.size)
    return out


def speed_table_markdown(speeds: np.ndarray, body_length_m: float) -> str:
    """Format a grid of speeds as a markdown table (m/s and BL/s)."""
    head = "| A (rad) \\ omega (rad/s) | " + " | ".join(f"{w:g}" for w in GRID_OMEGAS_RAD_S) + " |"
    rule = "|---" * (len(GRID_OMEGAS_RAD_S) + 1) + "|"
    rows = [head, rule]
    for i, a in enumerate(GRID_AMPLITUDES_RAD):
        cells = [f"{v:.4f} ({v / body_length_m:.3f})" for v in speeds[i]]
        rows.append(f"| {a:g} | " + " | ".join(cells) + " |")
    return "\n".join(rows)
