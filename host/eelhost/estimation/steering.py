"""How far a held-out experiment steers beyond the training experiments.

docs/estimation.md, "Validation", "Steering beyond the training experiments".

A fit learns the water only at the steering offsets its training experiments commanded. The
paper's turning experiments aim at one waypoint 30 deg to the left, so their offsets stay below
about k_theta x 30 deg (0.19 rad, plus the gait's own yaw); a path that turns through its
waypoints can ask for twice that, and to the right. Its prediction then extrapolates in the
offset, where candidates that fit the training gaits alike part ways, so a path's E_x says more
about the model's extrapolation than about its fit.

The offset is not recorded; it is reconstructed from the recorded poses with the paper's pursuit
law (docs/model.md section 4; :func:`eelsim.control.heading_offset`, for every frame at once): each pose passes the
controller's causal moving median over the declared ``camera.median_window`` poses
(:func:`eelsim.camera.causal_median`, the whole-recording form of the twin's ``MedianFilter``), the
target moves to the next waypoint when the filtered position is inside the acceptance circle, and
gamma = k_theta wrap(theta_ref - theta_bar). The robot is left-right symmetric, so a turn's
direction does not matter: the check compares the largest |gamma| of each held-out experiment
with the largest of every training experiment (straight and turning together).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from eelhost.data.experiments import Dataset, Experiment
from eelsim.camera import causal_median
from eelsim.control import wrap_angle

BEYOND = 1.2
"""A held-out experiment steers beyond the training when its largest |offset| exceeds the
training's largest by this factor (the gait's own yaw moves the reconstruction by a few
hundredths of a radian; a 20 % margin is well above that)."""


def commanded_offsets(exp: Experiment) -> np.ndarray | None:
    """The pursuit law's steering offset at each recorded pose, rad (None without headings).

    Parameters
    ----------
    exp : Experiment

    Returns
    -------
    ndarray, shape (K,), or None
        gamma at every frame, from the causal median of the poses up to it (module docstring).
    """
    if exp.heading_rad is None or len(exp.t_s) == 0:
        return None
    window = int(exp.camera.get("median_window", 5))
    poses = np.column_stack([exp.position_m, exp.heading_rad])
    # the controller's causal median (eelsim.camera.MedianFilter), the whole recording at once
    filtered = causal_median(poses, window)
    waypoints = np.asarray(exp.scenario.waypoints_m, dtype=float).reshape(-1, 2)
    radius = exp.scenario.acceptance_radius_m
    target = np.empty(len(poses), dtype=int)
    k_wp = 0
    for k, (x, y) in enumerate(filtered[:, :2]):
        while (k_wp < len(waypoints) - 1
               and math.hypot(x - waypoints[k_wp, 0], y - waypoints[k_wp, 1]) < radius):
            k_wp += 1
        target[k] = k_wp
    goal = waypoints[target]
    bearing = np.arctan2(goal[:, 1] - filtered[:, 1], goal[:, 0] - filtered[:, 0])
    # eelsim.control.heading_offset, for every frame at once
    return exp.scenario.k_theta * np.asarray(wrap_angle(bearing - filtered[:, 2]), dtype=float)


@dataclass
class SteeringCheck:
    """The held-out experiments that steer beyond every training experiment.

    Attributes
    ----------
    training_rad : float
        The largest |offset| of any training experiment (NaN when none has headings).
    held_out_rad : dict of str to float
        Each held-out experiment's largest |offset| (those with headings).
    """

    training_rad: float
    held_out_rad: dict[str, float]

    @property
    def beyond(self) -> dict[str, float]:
        """Held-out experiments beyond ``BEYOND`` times the training's range: name -> ratio."""
        if not np.isfinite(self.training_rad) or self.training_rad <= 0.0:
            return {}
        return {name: g / self.training_rad for name, g in self.held_out_rad.items()
                if g > BEYOND * self.training_rad}

    @property
    def beyond_rad(self) -> dict[str, float]:
        """Those experiments' largest |offset|, rad (for ``coefficients.json``)."""
        return {name: self.held_out_rad[name] for name in self.beyond}

    def warning(self) -> str | None:
        """The report's warning, None when every held-out experiment steers within the training."""
        beyond = self.beyond
        if not beyond:
            return None
        listed = ", ".join(f"{n} {self.held_out_rad[n]:.3f} rad ({r:.2f} x)"
                           for n, r in beyond.items())
        return (f"steering beyond the training experiments: {listed} against at most "
                f"{self.training_rad:.3f} rad in any training experiment (the offsets the pursuit "
                "law commanded, reconstructed from the recorded poses): their predictions "
                "extrapolate in the steering offset, which no held-out gait of the model "
                "comparison tests; record training turns that steer as hard to pin it down")


def steering_check(dataset: Dataset, held_out: Sequence[Experiment] | None = None) -> SteeringCheck:
    """Compare the held-out experiments' steering with the training experiments' (module docstring).

    Parameters
    ----------
    dataset : Dataset
    held_out : sequence of Experiment, optional
        The experiments to check (default: the dataset's held-out ones).

    Returns
    -------
    SteeringCheck
    """
    def largest(exp: Experiment) -> float | None:
        gamma = commanded_offsets(exp)
        return None if gamma is None else float(np.max(np.abs(gamma)))

    trained = [g for exps in dataset.train.values() for e in exps
               if (g := largest(e)) is not None]
    tests = dataset.held_out if held_out is None else held_out
    return SteeringCheck(max(trained, default=float("nan")),
                         {e.name: g for e in tests if (g := largest(e)) is not None})
