"""What ``eelbot run --plan WORLD`` needs from the planner: the plan, the navigator, the URI.

docs/planning.md ("Execution and replanning") is the long form. :func:`plan_for_run` plans in the
world from its start (refusing with :class:`eelhost.planning.planner.PlanRefused`, which the CLI
reports with exit 2), and returns the plan's waypoints for the run loop with a
:class:`eelhost.planning.replan.TankReplanner`, which replans beside the loop when the robot leaves
the corridor, stops it on contact or when no safe continuation exists, and ends the run when the
goal test holds. For a ``sim://`` robot it puts the virtual robot at the world's start in the
world's current (``start=`` and ``current=`` of the URI) unless the URI already says where; a
``serial://`` robot must be placed at the start by hand.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qsl, urlencode, urlsplit

from eelhost.planning.geometry import FloatArray
from eelhost.planning.planner import Outcome, Planner, PlanRefused, laws_of, plan_with_laws
from eelhost.planning.replan import (
    CALM_REPLAN_BUDGET_S,
    EARLY_BUDGET_S,
    ESCAPE_FLOOR_M,
    ESCAPE_RAMP_S,
    GOAL_APPROACH_CLEARANCE_M,
    REPLAN_BUDGET_S,
    STOP_BRAKE_S,
    TankReplanner,
)
from eelhost.planning.search import Actions, SearchSettings
from eelhost.planning.uncertainty import CoefficientModel, default_model
from eelhost.planning.world import Current, World
from eelsim.control import Gait
from eelsim.guidance import PURSUIT, GuidanceLaw
from eelsim.model import SwimmerModel
from eelsim.robot import Robot
from eelsim.scenario import PATH_GAIT

RECOVERY_ACTIONS = Actions(distances_m=(0.3, 0.5),
                           bearings_deg=(-120.0, -90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0, 120.0))
"""The recovery replan's action set: the planner's legs plus turns of 90 and 120 degrees
(docs/planning.md, "The recovery replan"). Shorter legs than 0.3 m are no use: the waypoint is
accepted 0.15 m before it, too soon for the next control update."""

RECOVERY_EXPANSIONS = 48
"""The recovery search's expansions (six batches of 8): bounds its processor time."""

RECOVERY_REPAIRS = 1
"""The recovery's re-searches after a failed check (the planner's default is 4)."""


class NoPlanFound(PlanRefused):
    """The planner searched and found no plan that passes its check (exit 2 with the reason)."""


@dataclass
class RunPlan:
    """A plan ready for the run loop.

    Attributes
    ----------
    waypoints_m : list of (float, float)
    navigator : TankReplanner
    uri : str
        The robot's URI (for ``sim://``: with the world's start and current).
    outcome : Outcome
    guidance : GuidanceLaw
        The law the plan was searched and checked with (the planner's ``options.guidance``):
        the run loop must steer with it (``RunConfig.guidance``).
    start_guide : (x, y, I_x, I_y) or None
        The guidance state the plan was searched from (``Plan.start_guide``): the run loop's
        first leg starts there (``RunConfig.start_guide``).
    """

    waypoints_m: list[tuple[float, float]]
    navigator: TankReplanner
    uri: str
    outcome: Outcome
    guidance: GuidanceLaw = PURSUIT
    start_guide: tuple[float, float, float, float] | None = None


def sim_uri_for_world(uri: str, world: World) -> str:
    """A ``sim://`` URI with the world's start and current added where it gives none.

    Parameters
    ----------
    uri : str
    world : World

    Returns
    -------
    str
        ``uri`` unchanged for any other scheme.
    """
    parts = urlsplit(uri)
    if parts.scheme != "sim":
        return uri
    query = parse_qsl(parts.query, keep_blank_values=True)
    keys = {k for k, _ in query}
    s = world.start
    if "start" not in keys:
        query.append(("start", f"{s.position_m[0]:g},{s.position_m[1]:g},{s.heading_deg:g}"))
    if "current" not in keys:
        c = world.current
        query.append(("current", f"{c.speed_m_s:g},{c.direction_deg:g}"))
    # built by hand: urlunsplit drops the "//" of a URI without a host
    return f"sim://{parts.netloc}{parts.path}?{urlencode(query, safe=',:')}"


def plan_for_run(
    world: World,
    robot: Robot,
    uri: str,
    gait: Gait = PATH_GAIT,
    coefficients: CoefficientModel | None = None,
    acceptance_radius_m: float = 0.15,
    planner_options: dict[str, Any] | None = None,
    swimmer: SwimmerModel | None = None,
    replan_budget_s: float | None = REPLAN_BUDGET_S,
    calm_budget_s: float | None = CALM_REPLAN_BUDGET_S,
    early_margin_m: float | None = None,
    early_budget_s: float | None = EARLY_BUDGET_S,
    escape: bool = False,
    restarts: int = 0,
    harbour: bool = True,
    stop_brake_s: float = STOP_BRAKE_S,
    station: bool = False,
    least_bad: bool = True,
) -> RunPlan:
    """Plan in a world for ``eelbot run --plan`` (module docstring).

    Parameters
    ----------
    world : World
    robot : Robot
    uri : str
        The robot's link URI.
    gait : Gait
        The gait the run will use (the planner swims the same).
    coefficients : CoefficientModel, optional
        Default: the robot file's coefficients with the default uncertainty.
    acceptance_radius_m : float
        The run loop's acceptance radius (the planner's twin must use the same).
    planner_options : dict, optional
        More keyword arguments of :class:`Planner` (the benchmark's ``unknown_current_m_s``,
        ``guidance``: the law the robot steers with), for the first plan and every replan.
        ``guidance`` may be a tuple of laws (``planner.AUTO_LAWS``): the first plan is searched
        with each in turn until one passes its check (``planner.plan_with_laws``), and the run
        and every replan keep that one (``RunPlan.guidance``).
    swimmer : SwimmerModel, optional
        The model of the robot the planner swims, built once by the command
        (:meth:`CoefficientModel.swimmer_for`; built here when not given) and handed to the
        first plan's planner and every replan's.
    replan_budget_s : float or None
        Each replan's wall-clock budget from its request (``TankReplanner``; docs/planning.md,
        "The replan's deadline"); None: no deadline.
    calm_budget_s : float or None
        The budget of a replan asked for in a moved current estimate while the robot is on its
        plan, which a more urgent replan cuts short (``TankReplanner``; docs/planning.md, "Calm
        replans get more time"); None: the ``replan_budget_s`` as every other replan's.
    early_margin_m : float or None
        A look-ahead whose capsule comes this near (but not within its own margin) asks for an
        early replan whose failure keeps the plan (``TankReplanner``; docs/planning.md, "An
        earlier replan"); None (the default): off; ``replan.EARLY_MARGIN_M`` is the value developed,
        which gained no goal on unseen seeds.
    early_budget_s : float or None
        The early replans' budget (``TankReplanner``); None: the ``replan_budget_s``.
    escape : bool
        Replans from a start inside the check's margin use the escape (``TankReplanner``'s
        ``escape_planner_for``; docs/planning.md, "An escape from inside the margin"); off by
        default (``eelbot run --escape``).
    restarts : int
        Restarts from rest a run may make (``TankReplanner``'s ``max_restarts``; docs/planning.md,
        "A restart from rest"); 0: off (``eelbot run --restarts`` gives 2).
    harbour : bool
        Before a stop whose drift would touch, swim to where it stays clear
        (``TankReplanner``'s ``harbour``; docs/planning.md, "The harbour"); on by default.
    stop_brake_s : float
        The run loop's brake before its final Stop (``TankReplanner``'s ``stop_brake_s``).
    station : bool
        Where the stop would drift into something and no harbour keeps clear, swim into the
        current instead (before the hold) (``TankReplanner``'s ``station_keeping``; docs/planning.md, "Holding
        station (session 21)"); off by default (``eelbot run --station``).
    least_bad : bool
        Where the stop would drift into something with no harbour, station or hold, swim a
        short swim towards a better stop while there is one (``TankReplanner``'s ``least_bad``;
        docs/planning.md, "The least-bad swim (session 24)"); on by default
        (``eelbot run --no-least-bad``: off).

    Returns
    -------
    RunPlan

    Raises
    ------
    PlanRefused
        The planner refused the world, or found no plan that passes its check.
    """
    model = coefficients or default_model(robot)
    options = {**(planner_options or {}),
               "swimmer": swimmer if swimmer is not None else model.swimmer_for(robot)}
    laws = laws_of(options.pop("guidance", PURSUIT))

    def planner_with(law: GuidanceLaw) -> Planner:
        made = Planner(world, robot, model, gait, guidance=law, **options)
        if abs(made.twin.acceptance_radius_m - acceptance_radius_m) > 1e-9:
            raise PlanRefused("acceptance_radius",
                              f"--radius {acceptance_radius_m:g}: the planner swims with "
                              f"{made.twin.acceptance_radius_m:g} m")
        return made

    # the guidance chosen per plan when several laws are given (docs/planning_history.md, "A guidance
    # law chosen per plan"): the first whose plan passes its check
    planner, outcome = plan_with_laws(planner_with, laws)
    # the law of the plan, as the planner filled it in (a feed-forward's known current and
    # speed): every replan's planner plans with the law the run loop steers with, and no replan
    # changes it (the twin's predictions from the running plan are made with that law)
    options["guidance"] = planner.options.guidance
    if not outcome.found:
        raise NoPlanFound(outcome.status, f"{world.name}: {outcome.message}")
    tiers = replan_planners(planner, world, robot, model, gait, options)
    navigator = TankReplanner(tiers.planner_for, planner, outcome, gait,
                              goal_planner_for=tiers.goal_planner_for,
                              recovery_planner_for=tiers.recovery_planner_for,
                              replan_budget_s=replan_budget_s,
                              calm_budget_s=calm_budget_s,
                              early_margin_m=early_margin_m,
                              early_budget_s=early_budget_s,
                              escape_planner_for=tiers.escape_planner_for if escape else None,
                              rest_escape_planner_for=tiers.escape_planner_for,
                              max_restarts=restarts, harbour=harbour,
                              stop_brake_s=stop_brake_s, station_keeping=station,
                              least_bad=least_bad)
    return RunPlan(outcome.plan.waypoints_m, navigator, sim_uri_for_world(uri, world), outcome,
                   planner.options.guidance, outcome.plan.start_guide)


@dataclass(frozen=True)
class ReplanPlanners:
    """The replanner's three tiers, each built for a water with an estimated extra current.

    Attributes
    ----------
    planner_for : callable
        The planner in the world with the extra current added to its own.
    goal_planner_for : callable
        The goal approach's planner: its search keeps the body's half width and
        ``GOAL_APPROACH_CLEARANCE_M`` from everything, its check unchanged (docs/planning.md).
    recovery_planner_for : callable
        The recovery's planner: sharper turns (``RECOVERY_ACTIONS``), the goal approach's margin,
        a bounded search (``RECOVERY_EXPANSIONS``, ``RECOVERY_REPAIRS``); its check unchanged.
    escape_planner_for : callable
        The escape's planner: the recovery's actions and bounds, the search's margin the world's
        but ramped from the start's over ``ESCAPE_RAMP_S`` (``SearchSettings.start_ramp_s``), its
        check's margin ``ESCAPE_FLOOR_M`` (the replanner judges the ramp over the check's runs).
    """

    planner_for: Callable[[FloatArray], Planner]
    goal_planner_for: Callable[[FloatArray], Planner]
    recovery_planner_for: Callable[[FloatArray], Planner]
    escape_planner_for: Callable[[FloatArray], Planner]


def replan_planners(planner: Planner, world: World, robot: Robot, model: CoefficientModel,
                    gait: Gait, options: dict[str, Any]) -> ReplanPlanners:
    """The tiers a :class:`TankReplanner` replans with (docs/planning.md, "Execution and replanning").

    Parameters
    ----------
    planner : Planner
        The first plan's planner (its body's half width sets the goal approach's margin).
    world, robot, model, gait
        As the first plan's.
    options : dict
        The first plan's further :class:`Planner` keyword arguments (its ``settings`` are the
        base of the goal approach's and the recovery's).

    Returns
    -------
    ReplanPlanners
    """

    def planner_for(extra_m_s: FloatArray) -> Planner:
        return Planner(with_extra_current(world, extra_m_s), robot, model, gait, **options)

    def approach_planner(extra_m_s: FloatArray, repairs: int | None = None,
                         **search: Any) -> Planner:
        base = options.get("settings") or SearchSettings()
        margin = planner.body_half_width_m + GOAL_APPROACH_CLEARANCE_M
        approach = with_extra_current(world, extra_m_s).model_copy(update={"clearance_m": 0.0})
        more = {} if repairs is None else {"repairs": repairs}
        return Planner(approach, robot, model, gait, **{
            **options, **more, "settings": dataclasses.replace(base, margin_m=margin, **search)})

    def recovery_planner_for(extra_m_s: FloatArray) -> Planner:
        return approach_planner(extra_m_s, RECOVERY_REPAIRS, actions=RECOVERY_ACTIONS,
                                max_expansions=RECOVERY_EXPANSIONS)

    def escape_planner_for(extra_m_s: FloatArray) -> Planner:
        base = options.get("settings") or SearchSettings()
        world_in = with_extra_current(world, extra_m_s).model_copy(update={"clearance_m": 0.0})
        return Planner(world_in, robot, model, gait, **{
            **options, "repairs": RECOVERY_REPAIRS, "check_margin_m": ESCAPE_FLOOR_M,
            "settings": dataclasses.replace(
                base, margin_m=planner.settings.margin_m, actions=RECOVERY_ACTIONS,
                max_expansions=RECOVERY_EXPANSIONS, start_ramp_s=ESCAPE_RAMP_S)})

    return ReplanPlanners(planner_for, approach_planner, recovery_planner_for,
                          escape_planner_for)


def with_extra_current(world: World, extra_m_s: FloatArray) -> World:
    """``world`` with a current velocity added to its own.

    Parameters
    ----------
    world : World
    extra_m_s : array_like, shape (2,)

    Returns
    -------
    World
    """
    vx, vy = world.current_m_s
    vx, vy = vx + float(extra_m_s[0]), vy + float(extra_m_s[1])
    current = Current(speed_m_s=float(math.hypot(vx, vy)),
                      direction_deg=float(math.degrees(math.atan2(vy, vx))))
    return world.model_copy(update={"current": current})
