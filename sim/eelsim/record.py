"""Writing a closed-loop run to disk: a CSV trajectory and a JSON metadata file beside it.

``<stem>.csv`` has one row per physics step, columns (SI units, angles in rad):

    t_s, x_m, y_m, heading_rad, vx_m_s, vy_m_s, heading_rate_rad_s,
    theta_1..theta_N, phi_1..phi_{N-1}, alpha_1..alpha_{N-1}, offset_rad, target_index

(theta: absolute link angles, link 1 = tail; phi: joint angles theta_{j+1} - theta_j; alpha: joint
references). ``<stem>.json`` holds the robot, scenario, loop options, seed, coefficients and the
outcome: failure flag, its time and reason, arrival time.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from eelsim.closed_loop import LoopOptions, RunResult
from eelsim.fluid import FluidCoefficients
from eelsim.robot import Robot
from eelsim.scenario import Scenario


def trajectory_columns(n_links: int) -> list[str]:
    """Names of the CSV columns for a robot of ``n_links`` links."""
    return (
        ["t_s", "x_m", "y_m", "heading_rad", "vx_m_s", "vy_m_s", "heading_rate_rad_s"]
        + [f"theta_{i}" for i in range(1, n_links + 1)]
        + [f"phi_{j}" for j in range(1, n_links)]
        + [f"alpha_{j}" for j in range(1, n_links)]
        + ["offset_rad", "target_index"]
    )


def trajectory_table(result: RunResult, n_links: int) -> np.ndarray:
    """The run as a 2-D array with the columns of :func:`trajectory_columns`."""
    x = result.states
    n = n_links
    theta = x[:, :n]
    return np.column_stack(
        [
            result.t_s,
            x[:, n],
            x[:, n + 1],
            theta.mean(axis=1),
            x[:, -2],
            x[:, -1],
            x[:, n + 2 : 2 * n + 2].mean(axis=1),
            theta,
            np.diff(theta, axis=1),
            result.alpha_rad,
            result.offset_rad,
            result.target_index,
        ]
    )


def run_metadata(
    result: RunResult,
    robot: Robot,
    scenario: Scenario,
    options: LoopOptions,
    seed: int,
    coefficients: FluidCoefficients | None = None,
) -> dict[str, Any]:
    """Everything needed to reproduce and judge the run, as JSON-ready data."""
    coeffs = coefficients or robot.hydrodynamics
    return {
        "format": "eelbot-run/1",
        "robot": robot.model_dump(),
        "scenario": scenario.model_dump(),
        "options": dataclasses.asdict(options),
        "seed": seed,
        "coefficients": coeffs.model_dump(),
        "outcome": {
            "failure": result.failure.name,
            "failure_time_s": result.failure_time_s,
            "reason": result.reason,
            "arrival_time_s": result.arrival_time_s,
            "distance_left_m": result.distance_left_m,
        },
    }


def write_run(
    result: RunResult,
    robot: Robot,
    scenario: Scenario,
    options: LoopOptions,
    seed: int,
    stem: str | Path,
    coefficients: FluidCoefficients | None = None,
) -> tuple[Path, Path]:
    """Write ``<stem>.csv`` and ``<stem>.json``; return their paths.

    Parameters
    ----------
    result : RunResult
    robot, scenario, options, seed, coefficients
        What produced the run (written as metadata).
    stem : str or Path
        Output path without extension; parent folders are created.

    Returns
    -------
    (Path, Path)
        The CSV and JSON paths.
    """
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    csv_path, json_path = stem.with_suffix(".csv"), stem.with_suffix(".json")
    cols = trajectory_columns(robot.n_links)
    np.savetxt(
        csv_path,
        trajectory_table(result, robot.n_links),
        delimiter=",",
        header=",".join(cols),
        comments="",
        fmt="%.9g",
    )
    meta = run_metadata(result, robot, scenario, options, seed, coefficients)
    json_path.write_text(json.dumps(meta, indent=2) + "\n")
    return csv_path, json_path
