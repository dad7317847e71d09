"""Scenarios: what the robot is asked to do (gait, waypoints, current, time limit).

The paper's experiments are available by name (docs/model.md section 7):

- ``straight_A<A>_w<omega>`` and ``turning_A<A>_w<omega>`` for the 4 x 4 gait grid
  (A in 0.61, 0.69, 0.78, 0.87 rad; omega in 2.7, 3.1, 3.5, 3.9 rad/s; beta = 1.04 rad), a waypoint
  1.40 m away at 0 or 30 degrees, k_theta 0.1 (straight) or 0.37 (turning);
- ``straight`` and ``turning``: the fastest gait of each;
- ``path1`` and ``path2``: the multi-waypoint paths, path 2 in a 0.03 m/s current towards 180 deg.

A scenario can also be read from a TOML file (see ``docs/scenarios.md``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from eelsim.control import Gait
from eelsim.tomlfile import read_toml, validation_message

Finite = Annotated[float, Field(allow_inf_nan=False, strict=True)]  # "1" or true refused
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False, strict=True)]

GRID_AMPLITUDES_RAD = (0.61, 0.69, 0.78, 0.87)
GRID_OMEGAS_RAD_S = (2.7, 3.1, 3.5, 3.9)
GRID_BETA_RAD = 1.04
TRAINING_CORNERS = ((0.61, 2.7), (0.61, 3.9), (0.87, 2.7), (0.87, 3.9))
K_THETA_STRAIGHT = 0.1
K_THETA_TURNING = 0.37
WAYPOINT_DISTANCE_M = 1.40
TURNING_ANGLE_DEG = 30.0
PATH_GAIT = Gait(0.87, 3.9, GRID_BETA_RAD, 0.37)


class ScenarioError(ValueError):
    """An unknown scenario name or an invalid scenario file."""


class Scenario(BaseModel):
    """One closed-loop task.

    Attributes
    ----------
    name : str
        Identifier.
    amplitude_rad, omega_rad_s, beta_rad, k_theta : float
        Gait parameters G_p.
    waypoints_m : list of (x, y)
        Waypoints, visited in order.
    acceptance_radius_m : float
        A waypoint counts as reached within this distance (0.15 m in the paper).
    current_speed_m_s, current_direction_deg : float
        Uniform steady current: speed and the direction it flows towards.
    duration_s : float
        T_max: the run ends here, flagged too slow if the last waypoint was not reached.
    min_duration_s : float
        Where reaching the last waypoint ends a run (``LoopOptions.stop_at_goal``), it does so
        only from this time on (default 0: at once). Estimation sets it to the last time it
        compares with a recording, so that no run goes on once nothing it does can count.
    start_position_m : (x, y)
        Initial centre of mass.
    start_heading_deg : float
        Initial heading of the straight robot at rest.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = "custom"
    amplitude_rad: Positive
    omega_rad_s: Positive
    beta_rad: Finite = GRID_BETA_RAD
    k_theta: Finite
    waypoints_m: list[tuple[Finite, Finite]] = Field(min_length=1)
    acceptance_radius_m: Positive = 0.15
    current_speed_m_s: Annotated[float, Field(ge=0, allow_inf_nan=False, strict=True)] = 0.0
    current_direction_deg: Finite = 0.0
    duration_s: Positive = 60.0
    min_duration_s: Annotated[float, Field(ge=0, allow_inf_nan=False, strict=True)] = 0.0
    start_position_m: tuple[Finite, Finite] = (0.0, 0.0)
    start_heading_deg: Finite = 0.0

    @classmethod
    def swimming(cls, gait: Gait, **task: Any) -> Scenario:
        """The task ``task`` (the other fields, by name) swum with ``gait``'s parameters G_p.

        Parameters
        ----------
        gait : Gait
            A, omega, beta and k_theta.
        **task
            Any other field of the scenario (name, waypoints, current, start, durations).

        Returns
        -------
        Scenario
        """
        return cls(amplitude_rad=gait.amplitude_rad, omega_rad_s=gait.omega_rad_s,
                   beta_rad=gait.beta_rad, k_theta=gait.k_theta, **task)

    @property
    def gait(self) -> Gait:
        """The gait parameters as a :class:`~eelsim.control.Gait`."""
        return Gait(self.amplitude_rad, self.omega_rad_s, self.beta_rad, self.k_theta)

    def total_steps(self, dt_s: float) -> int:
        """The run's last step: floor(T_max / dt)."""
        return int(math.floor(self.duration_s / dt_s + 1e-9))

    def goal_steps(self, dt_s: float) -> int:
        """The first step at which reaching the goal may end the run: ceil(min_duration / dt)."""
        return int(math.ceil(self.min_duration_s / dt_s - 1e-9))

    @property
    def current_m_s(self) -> tuple[float, float]:
        """Current velocity vector v_c."""
        a = math.radians(self.current_direction_deg)
        return (self.current_speed_m_s * math.cos(a), self.current_speed_m_s * math.sin(a))

    def with_added_current(self, extra_m_s: tuple[float, float]) -> Scenario:
        """The task in water whose current also has ``extra_m_s`` (v_x, v_y) added to it.

        Uniform currents add as vectors (docs/model.md): estimation adds a tank's fitted
        ambient current to the one an experiment declares. Returns ``self`` when nothing is
        added, so that runs without current keep the kernel's sweep without current terms.
        """
        dx, dy = float(extra_m_s[0]), float(extra_m_s[1])
        if dx == 0.0 and dy == 0.0:
            return self
        vx, vy = self.current_m_s
        vx, vy = vx + dx, vy + dy
        return self.model_copy(update={
            "current_speed_m_s": math.hypot(vx, vy),
            "current_direction_deg": math.degrees(math.atan2(vy, vx)),
        })


def grid_scenario(motion: str, amplitude_rad: float, omega_rad_s: float) -> Scenario:
    """A straight or turning experiment of the paper for one gait of the grid.

    Parameters
    ----------
    motion : {"straight", "turning"}
    amplitude_rad, omega_rad_s : float
        The gait.

    Returns
    -------
    Scenario
    """
    if motion not in ("straight", "turning"):
        raise ScenarioError(f"motion must be 'straight' or 'turning', got {motion!r}")
    angle = 0.0 if motion == "straight" else math.radians(TURNING_ANGLE_DEG)
    waypoint = (WAYPOINT_DISTANCE_M * math.cos(angle), WAYPOINT_DISTANCE_M * math.sin(angle))
    return Scenario(
        name=f"{motion}_A{amplitude_rad:.2f}_w{omega_rad_s:.1f}",
        amplitude_rad=amplitude_rad,
        omega_rad_s=omega_rad_s,
        k_theta=K_THETA_STRAIGHT if motion == "straight" else K_THETA_TURNING,
        waypoints_m=[waypoint],
    )


def paper_grid(motion: str) -> list[Scenario]:
    """All 16 experiments of one motion type, amplitude-major order."""
    return [grid_scenario(motion, a, w) for a in GRID_AMPLITUDES_RAD for w in GRID_OMEGAS_RAD_S]


def _path(name: str, waypoints: list[tuple[float, float]], speed: float, direction: float):
    return Scenario.swimming(
        PATH_GAIT,
        name=name,
        waypoints_m=waypoints,
        current_speed_m_s=speed,
        current_direction_deg=direction,
    )


def named_scenarios() -> dict[str, Scenario]:
    """Every scenario available by name."""
    out: dict[str, Scenario] = {}
    for motion in ("straight", "turning"):
        for s in paper_grid(motion):
            out[s.name] = s
        out[motion] = grid_scenario(motion, 0.87, 3.9).model_copy(update={"name": motion})
    out["path1"] = _path("path1", [(0.43, 0.25), (0.93, 0.25), (1.37, 0.50)], 0.0, 0.0)
    out["path2"] = _path("path2", [(0.35, 0.20), (0.69, 0.40), (1.07, 0.40)], 0.03, 180.0)
    return out


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Return a named scenario, or read one from a TOML file.

    Parameters
    ----------
    name_or_path : str or Path
        A name from :func:`named_scenarios` or the path of a ``.toml`` file.

    Returns
    -------
    Scenario

    Raises
    ------
    ScenarioError
        For an unknown name or an invalid file (naming the file and the key).
    """
    names = named_scenarios()
    key = str(name_or_path)
    if key in names:
        return names[key]
    path = Path(key)
    if not path.suffix == ".toml":
        raise ScenarioError(
            f"unknown scenario {key!r}: give a .toml file or one of "
            f"{', '.join(sorted(n for n in names if '_A' not in n))} or e.g. straight_A0.61_w2.7"
        )
    data = read_toml(path, ScenarioError, "scenario file")
    data.setdefault("name", path.stem)
    try:
        return Scenario.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(
            validation_message(str(path), err, "scenario", show_values=False)
        ) from None
