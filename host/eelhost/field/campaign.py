"""A campaign plan: the protocol of experiments run one after another into a dataset.

By default the paper's protocol (docs/model.md section 7): the 4 x 4 gait grid (A in 0.61, 0.69,
0.78, 0.87 rad; omega in 2.7, 3.1, 3.5, 3.9 rad/s; beta 1.04 rad) times straight and turning runs
(a waypoint 1.40 m from the start, straight ahead or 30 degrees to the left; k_theta 0.1 and
0.37), the four corner gaits for training and the other twelve for testing. A plan file (TOML)
changes any of it; every key is optional::

    name = "tank-day-1"
    motions = ["straight", "turning"]
    amplitudes_rad = [0.61, 0.69, 0.78, 0.87]
    omegas_rad_s = [2.7, 3.1, 3.5, 3.9]
    beta_rad = 1.04
    repeats = 1
    train = [[0.61, 2.7], [0.61, 3.9], [0.87, 2.7], [0.87, 3.9]]  # the rest are test gaits
    start = [0.0, 0.0, 0.0]            # x, y (m), heading (deg) where each take starts
    distance_m = 1.4
    turning_angle_deg = 30.0
    k_theta_straight = 0.1
    k_theta_turning = 0.37
    radius_m = 0.15
    duration_s = 60.0                  # a take stops after this long if not arrived
    rest_s = 60.0                      # between takes with a real robot (the water settles)
    control_period_s = 0.3

:func:`plan_takes` lists the takes (motion-major, then amplitude, then frequency, then repeat),
each with its name (``straight_A0.61_w2.7``, ``_r2`` and on for repeats) and waypoint.
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    field_validator,
)

from eelhost.errors import UserError
from eelhost.wire.limits import gait_value_problem
from eelsim.scenario import (
    GRID_AMPLITUDES_RAD,
    GRID_BETA_RAD,
    GRID_OMEGAS_RAD_S,
)

__all__ = ["CampaignPlan", "PlanError", "Take", "load_plan", "plan_takes", "take_done"]

GOOD_ENDS = ("arrived", "duration")  # a take that ended otherwise is run again


class PlanError(UserError, ValueError):
    """A campaign plan that cannot be used; the message names the file and the key."""


def _corners(amplitudes: list[float], omegas: list[float]) -> list[list[float]]:
    return [[a, w] for a in (min(amplitudes), max(amplitudes)) for w in (min(omegas), max(omegas))]


class CampaignPlan(BaseModel):
    """The protocol (see the module docstring for the keys and the paper's defaults)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    name: str = "paper protocol"
    motions: list[str] = Field(default_factory=lambda: ["straight", "turning"], min_length=1)
    amplitudes_rad: list[float] = Field(default_factory=lambda: list(GRID_AMPLITUDES_RAD),
                                        min_length=1)
    omegas_rad_s: list[float] = Field(default_factory=lambda: list(GRID_OMEGAS_RAD_S),
                                      min_length=1)
    beta_rad: float = GRID_BETA_RAD
    repeats: int = Field(1, ge=1)
    train: list[list[float]] | None = None
    start: list[float] = Field(default_factory=lambda: [0.0, 0.0, 0.0], min_length=3,
                               max_length=3)
    distance_m: float = Field(1.4, gt=0)
    turning_angle_deg: float = 30.0
    k_theta_straight: float = 0.1
    k_theta_turning: float = 0.37
    radius_m: float = Field(0.15, gt=0)
    duration_s: float = Field(60.0, gt=0)  # the slowest turning gaits need more than 40 s
    rest_s: float = Field(60.0, ge=0)
    control_period_s: float = Field(0.3, gt=0)

    @field_validator("amplitudes_rad", "omegas_rad_s", "beta_rad")
    @classmethod
    def _gaits_the_robot_accepts(cls, v: list[float] | float, info: ValidationInfo):
        # the same ranges as run --gait (eelhost.wire.limits): a plan is refused before its first
        # take, not when the robot refuses a gait half-way through the campaign
        name = {"amplitudes_rad": "amplitude_rad", "omegas_rad_s": "omega_rad_s"}.get(
            info.field_name or "", "beta_rad")
        for value in v if isinstance(v, list) else [v]:
            problem = gait_value_problem(name, value)
            if problem:
                raise ValueError(problem)
        return v

    @field_validator("motions")
    @classmethod
    def _known_motions(cls, v: list[str]) -> list[str]:
        for m in v:
            if m not in ("straight", "turning"):
                raise ValueError(f"motion {m!r}: expected straight or turning")
        return v

    def train_gaits(self) -> list[tuple[float, float]]:
        """The training gaits: the plan's ``train``, or the grid's four corners."""
        pairs = self.train if self.train is not None else _corners(self.amplitudes_rad,
                                                                   self.omegas_rad_s)
        return [(round(a, 6), round(w, 6)) for a, w in pairs]


@dataclass(frozen=True)
class Take:
    """One run of the campaign.

    Attributes
    ----------
    name : str
        File stem in the dataset.
    motion : str
        ``straight`` or ``turning``.
    amplitude_rad, omega_rad_s, beta_rad, k_theta : float
        The gait and the heading gain.
    waypoint_m : (float, float)
        The target.
    split : str
        ``train`` or ``test``.
    repeat : int
        1, 2, ...
    """

    name: str
    motion: str
    amplitude_rad: float
    omega_rad_s: float
    beta_rad: float
    k_theta: float
    waypoint_m: tuple[float, float]
    split: str
    repeat: int


def load_plan(path: str | Path | None) -> CampaignPlan:
    """Read a plan file (None: the paper's protocol).

    Raises
    ------
    PlanError
        Naming the file and the key of anything wrong.
    """
    if path is None:
        return CampaignPlan.model_validate({})
    try:
        data = tomllib.loads(Path(path).read_text())
    except OSError as err:
        raise PlanError(f"{path}: cannot read the plan: {err.strerror}") from None
    except tomllib.TOMLDecodeError as err:
        raise PlanError(f"{path}: not valid TOML: {err}") from None
    try:
        plan = CampaignPlan.model_validate(data)
    except ValidationError as err:
        e = err.errors()[0]
        loc = ".".join(str(p) for p in e["loc"])
        raise PlanError(f"{path}: {loc}: {e['msg']}") from None
    grid = {(round(a, 6), round(w, 6)) for a in plan.amplitudes_rad for w in plan.omegas_rad_s}
    for gait in plan.train_gaits():
        if gait not in grid:
            raise PlanError(f"{path}: train: {list(gait)} is not a gait of the grid")
    return plan


def plan_takes(plan: CampaignPlan) -> list[Take]:
    """Every take of the plan, in the order they are run."""
    x0, y0, heading_deg = plan.start
    train = set(plan.train_gaits())
    takes = []
    for motion in plan.motions:
        angle = 0.0 if motion == "straight" else math.radians(plan.turning_angle_deg)
        bearing = math.radians(heading_deg) + angle
        waypoint = (x0 + plan.distance_m * math.cos(bearing), y0 + plan.distance_m * math.sin(bearing))
        k_theta = plan.k_theta_straight if motion == "straight" else plan.k_theta_turning
        for a in plan.amplitudes_rad:
            for w in plan.omegas_rad_s:
                split = "train" if (round(a, 6), round(w, 6)) in train else "test"
                for r in range(1, plan.repeats + 1):
                    name = f"{motion}_A{a:.2f}_w{w:.1f}" + (f"_r{r}" if plan.repeats > 1 else "")
                    takes.append(Take(name, motion, a, w, plan.beta_rad, k_theta,
                                      (round(waypoint[0], 6), round(waypoint[1], 6)), split, r))
    return takes


def take_done(folder: str | Path, name: str) -> bool:
    """Whether the take ``name`` in ``folder`` is finished: closed, and arrived or ran its time.

    A take cut short (killed: never closed; or stopped by a signal, lost from view, link lost) is
    not done, and a resumed campaign runs it again.
    """
    path = Path(folder) / f"{name}.json"
    try:
        meta: dict[str, Any] = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return False
    recording = meta.get("source", {}).get("recording", {}) if isinstance(meta, dict) else {}
    return (isinstance(recording, dict) and recording.get("complete") is True
            and recording.get("reason") in GOOD_ENDS and Path(folder, f"{name}.csv").exists())
