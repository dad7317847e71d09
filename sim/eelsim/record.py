"""Writing a closed-loop run to disk: a CSV trajectory and a JSON metadata file beside it.

``<stem>.csv`` has one row per physics step, columns (SI units, angles in rad):

    t_s, x_m, y_m, heading_rad, vx_m_s, vy_m_s, heading_rate_rad_s,
    theta_1..theta_N, phi_1..phi_{N-1}, alpha_1..alpha_{N-1}, offset_rad, target_index,
    torque_1..torque_{N-1}

(theta: absolute link angles, link 1 = tail; phi: joint angles theta_{j+1} - theta_j; alpha: joint
references; torque: the torque each joint gives at the step, N m, or with the servo joint model
what the servo must give; docs/model.md section 4). ``<stem>.json`` holds the robot, scenario,
loop options, seed, coefficients and the outcome: failure flag, its time and reason, arrival
time, and the steps at which a joint's torque was outside the servo's torque-speed line
(``saturated_steps``, a warning) with the largest |torque| as a fraction of the stall torque.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np

from eelsim.closed_loop import LoopOptions, RunResult
from eelsim.files import atomic_writer
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
        + [f"torque_{j}" for j in range(1, n_links)]
    )


def trajectory_table(result: RunResult, n_links: int) -> np.ndarray:
    """The run as a 2-D array with the columns of :func:`trajectory_columns`."""
    x = result.states
    n = n_links
    theta = x[:, :n]
    torque = result.joint_torque_nm
    if torque.shape != (len(result.t_s), n - 1):  # a result made without torques
        torque = np.full((len(result.t_s), n - 1), np.nan)
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
            torque,
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
            "saturated_steps": result.saturated_steps,
            "max_torque_ratio": result.max_torque_ratio,
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
        Output path without extension; parent folders are created. Both files are written
        whole (:mod:`eelsim.files`): a failed write leaves what was there before.

    Returns
    -------
    (Path, Path)
        The CSV and JSON paths.
    """
    stem = Path(stem)
    csv_path, json_path = stem.with_suffix(".csv"), stem.with_suffix(".json")
    cols = trajectory_columns(robot.n_links)
    meta = run_metadata(result, robot, scenario, options, seed, coefficients)
    # Both files are written to temporaries and flushed before either is renamed into place: a
    # full disk leaves the earlier pair (or nothing), never a cut CSV without its JSON.
    with atomic_writer(json_path) as json_file, atomic_writer(csv_path) as csv_file:
        np.savetxt(
            csv_file,
            trajectory_table(result, robot.n_links),
            delimiter=",",
            header=",".join(cols),
            comments="",
            fmt="%.9g",
        )
        json_file.write(json.dumps(meta, indent=2) + "\n")
        csv_file.flush()
        json_file.flush()
    return csv_path, json_path
