"""Coverage of the action set: which actions the robot can swim in each of 8 current directions.

docs/planning.md ("Coverage") is the long form. The search swims every action from the state the
robot is in, in the world's current, so no current direction is left without actions by
construction; what the robot can actually do still depends on the current. For a current speed,
:func:`action_coverage` swims every action of the set once per current direction relative to the
robot's heading (0, 45, ..., 315 degrees): from rest, a straight lead-in of ``lead_in_m`` and then
the action (as the search does, with the turning coefficients for turns), in open water. An action
counts when the twin accepts its waypoint within the search's time limit and raises no flag.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from eelhost.planning.search import SearchSettings
from eelhost.planning.twin import Twin
from eelhost.planning.uncertainty import CoefficientModel
from eelsim.closed_loop import LoopOptions
from eelsim.control import Gait
from eelsim.model import SwimmerModel
from eelsim.robot import Robot
from eelsim.scenario import PATH_GAIT

DIRECTIONS_DEG = tuple(45.0 * k for k in range(8))


@dataclass(frozen=True)
class Coverage:
    """Actions swum successfully per current direction, for one current speed.

    Attributes
    ----------
    current_speed_m_s : float
    directions_deg : tuple of float
        Current directions relative to the robot's heading.
    succeeded : ndarray of bool, shape (8, A)
        Per direction, per action of ``SearchSettings.actions.legs``.
    legs : list of (distance m, bearing deg)
    """

    current_speed_m_s: float
    directions_deg: tuple[float, ...]
    succeeded: np.ndarray
    legs: list[tuple[float, float]]

    @property
    def counts(self) -> list[int]:
        """Successful actions per direction."""
        return [int(v) for v in self.succeeded.sum(axis=1)]

    @property
    def complete(self) -> bool:
        """Every direction has at least one action."""
        return min(self.counts) > 0

    def line(self) -> str:
        """One line: the counts per direction."""
        cells = ", ".join(f"{d:g} deg: {c}/{len(self.legs)}"
                          for d, c in zip(self.directions_deg, self.counts, strict=True))
        return f"current {self.current_speed_m_s:g} m/s: {cells}"


def action_coverage(
    robot: Robot,
    coefficients: CoefficientModel,
    current_speed_m_s: float,
    settings: SearchSettings | None = None,
    gait: Gait = PATH_GAIT,
    options: LoopOptions | None = None,
    lead_in_m: float = 0.4,
    threads: int | None = 1,
    swimmer: SwimmerModel | None = None,
) -> Coverage:
    """Swim every action in each of 8 current directions (module docstring).

    Parameters
    ----------
    robot : Robot
    coefficients : CoefficientModel
    current_speed_m_s : float
    settings : SearchSettings, optional
        Its actions and leg time limit.
    gait : Gait
    options : LoopOptions, optional
    lead_in_m : float
    threads : int or None
    swimmer : SwimmerModel, optional
        The robot's model, built once by the command (:class:`eelhost.planning.twin.Twin`);
        built once here when not given.

    Returns
    -------
    Coverage
    """
    s = settings or SearchSettings()
    legs = s.actions.legs
    out = np.zeros((len(DIRECTIONS_DEG), len(legs)), dtype=bool)
    for i, direction in enumerate(DIRECTIONS_DEG):
        a = math.radians(direction)
        current = (current_speed_m_s * math.cos(a), current_speed_m_s * math.sin(a))
        twin = Twin(robot, coefficients.sets, gait, options or LoopOptions(), current,
                    threads=threads, swimmer=swimmer)
        swimmer = twin.model  # the next directions' twins share it
        waypoints = [[(lead_in_m, 0.0), (lead_in_m + d * math.cos(math.radians(b)),
                                         d * math.sin(math.radians(b)))] for d, b in legs]
        index = [s.actions.coefficient_index(b) for _, b in legs]
        durations = [s.leg_time_s * (lead_in_m + d + 0.3) for d, _ in legs]
        runs = twin.run(waypoints, durations, coefficient_index=index, stride=30)
        out[i] = [(not runs.reasons[j]) and runs.arrival_step[j] >= 0 for j in range(len(legs))]
    return Coverage(float(current_speed_m_s), DIRECTIONS_DEG, out, legs)
