"""The closed-loop planning benchmark: generated worlds planned, then swum over ``sim://``.

docs/planning.md ("Closed-loop benchmark") is the long form. For each world of
:func:`eelhost.planning.worlds.generate_world` on a seed range:

1. the planner plans from the world's start, as ``eelbot run --plan`` does (with the same
   coefficient model); a world without a plan is counted with the planner's status;
2. the plan is executed by ``eelbot run --plan``'s own code (:func:`eelhost.field.take.run_take`
   with the :class:`eelhost.planning.replan.TankReplanner`) over ``sim://`` at ``speed=0``, the
   synthetic camera filming the world's tank, and the planner's wall time passing on the virtual
   robot's clock while it replans. The virtual robot's water is not the planner's: its
   coefficients are one draw of :meth:`eelhost.planning.uncertainty.CoefficientModel.draw`
   (the straight fit's), and an unknown current of uniform speed up to ``unknown_current_m_s``
   in a uniform random direction is added to the world's; both from a generator seeded with the
   world's seed;
3. the run is judged from the virtual robot's true state at every physics step, with geometry
   written here, independently of the planner's (:func:`true_clearance_m`: each link a stadium
   of its own length and width, shapely's exact distances to the discs, polygons and walls):
   the swimming run up to the run loop's decision to stop, and apart from it the stop (the
   brake, the Stop's answer, and the glide after the take, :func:`glide_on`).

Results go to ``<out>/results.jsonl`` one world per line as each finishes, so a killed benchmark
resumes where it stopped.
"""

from __future__ import annotations

import json
import logging
import math
import statistics
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from eelhost.errors import UserError
from eelhost.field.runloop import BRAKE_S, RunConfig
from eelhost.field.session import TakeNotes
from eelhost.field.take import TakeRequest, run_take
from eelhost.planning.geometry import FloatArray
from eelhost.planning.planner import AUTO_GUIDANCE, PlanRefused
from eelhost.planning.replan import CALM_REPLAN_BUDGET_S, REPLAN_BUDGET_S
from eelhost.planning.state_estimate import body_error_m, error_summary_mm
from eelhost.planning.tank import plan_for_run
from eelhost.planning.uncertainty import CoefficientModel
from eelhost.planning.world import CircleObstacle, World
from eelhost.planning.worlds import generate_world
from eelhost.vision.synthetic import TankView
from eelhost.xil.virtual_robot import DT_US, VirtualRobot
from eelsim.control import Gait
from eelsim.model import SwimmerModel
from eelsim.robot import Robot
from eelsim.scenario import PATH_GAIT

log = logging.getLogger(__name__)

UNKNOWN_CURRENT_M_S = 0.02
"""Largest speed of the current the planner is not told of."""

COAST_AUDIT_S = 30.0
"""Longest the body is swum on after the take ends, its gait stopped, for the contact audit.

Why: the take ends when the firmware acknowledges the final Stop, but a straight body glides a
long way and the water carries it (docs/planning.md, "Closed-loop benchmark": the coast)."""

COAST_REST_M_S = 0.02
"""The coast ends once the body's centre of mass moves slower than this through the water: the
glide is over, and what carries the body on is the current (the unknown current's bound)."""


@dataclass
class WorldResult:
    """One world of the benchmark.

    Attributes
    ----------
    seed : int
    planned : bool
        The planner returned a plan that passed its check.
    status : str
        The planner's status (``found`` or why not).
    reason : str
        How the run ended (``arrived``, ``contact``, ``no_safe_continuation``, ``duration``, ...);
        ``""`` without a plan.
    detail : str
    reached : bool
        The run ended in the goal.
    min_clearance_m : float or None
        Smallest true gap between the body and an obstacle or wall (independent geometry).
    contact : bool
        The true body overlapped an obstacle or wall at some step.
    failsafe_reports : int
        Telemetry reports of FAILSAFE during the run.
    replans, failed_replans : int
    replan_wall_s : list of float
        Wall time of each replan, from its request to its plan.
    replan_delay_s : list of float
        Robot's time from each replan's request to its plan being switched in.
    replan_cpu_s : list of float
        Processor time of each replan (its thread's), failed ones included.
    plan_wall_s, plan_cpu_s : float
        The first plan's wall and processor time.
    t_end_s : float
        Robot's time at the end of the run.
    planned_goal_s : float or None
        When the plan expected the goal.
    water : dict
        The virtual robot's coefficients and unknown current.
    guidance : str
        The guidance law of the planner and the run loop (``pursuit``, ``ilos``,
        ``pursuit_ff``), or ``auto``: the law chosen per plan (``plan_guidance``).
    failed_replan_statuses : list of str
        The status of each failed replan (``out_of_time``: its budget ran out first).
    replan_budget_s : float or None
        Each replan's wall-clock budget (None: none).
    shift_repairs : int
        Replans switched in that were shift repairs of the present plan (docs/planning.md, "The
        shift repair"; counted in ``replans`` too).
    retries_before_contact : int
        Replans asked for at once after a failed one, instead of a stop, because the predicted
        contact was far enough ahead (docs/planning.md, "Retried before contact").
    estimate_error_mm : dict
        The camera's body estimate (each frame's, what the contact test judges) against the true
        body at the frame: the largest distance of its points
        (:func:`eelhost.planning.state_estimate.body_error_m`), median, 95th percentile and
        largest over the run's frames, mm (empty in results written before it).
    calm_budget_s : float or None
        The calm replans' budget (None: off, or results written before it).
    calm_replans, calm_found, calm_cut : int
        Calm replans (asked for in a moved current estimate, given the calm budget), those that
        found a plan, and those cut short for an urgent replan (docs/planning.md, "Calm replans
        get more time, and an urgent replan cuts them short").
    early_replans, early_found, early_cut : int
        The same for the early replans (docs/planning.md, "An earlier replan"), which have a
        longer budget too but are not calm ones.
    restarts, pauses : int
        Restarts from rest made, and pauses (stops of the gait for one) (docs/planning.md, "A
        restart from rest"; 0 in results written before it).
    coast_clearance_m : float or None
        Smallest true gap while the robot stops: from the run loop's decision to stop, through
        the brake and the glide after the Stop (:func:`glide_on`), None in results
        written before it. ``min_clearance_m`` and ``contact`` are then the swimming run's, up
        to that decision (before session 16 they ran to the Stop's answer).
    coast_contact : bool
        The true body overlapped an obstacle or wall while stopping.
    coast_s : float
        How long the glide after the Stop lasted (0 in results written before it).
    harbours : list of str
        The stops a harbour swim came before (``arrived``, ``pause``, ``stop``; docs/planning.md,
        "The harbour"), one per swim.
    harbourless : int
        Stops the twin drifted within the margin for which no harbour swim kept it.
    stations : int
        Stations held instead of such a stop (docs/planning.md, "Holding station (session
        21)"; 0 in results written before it).
    least_bad : int
        Least-bad swims instead of such a stop (docs/planning.md, "The least-bad swim (session
        24)"; 0 in results written before it).
    least_bad_none : int
        Stops the least-bad swim was judged for and no swim beat.
    plan_guidance : str or None
        The law the first plan was searched and checked with, which the run and its replans
        steered with (None: no plan, or a result from before session 20).
    corridor_ready_s, corridor_cpu_s : list of float or None
        Each replan asked for because the robot left the planned corridor and that came to an
        end (found or failed): the robot's time from its request to its answer, and its
        processor time (None where not measured); issue 28 asks for that answer within 1 s (docs/planning.md, "Targets of
        issue 28 at the tank"). None in results written before session 21.
    """

    seed: int
    planned: bool
    status: str
    reason: str = ""
    detail: str = ""
    reached: bool = False
    min_clearance_m: float | None = None
    contact: bool = False
    failsafe_reports: int = 0
    replans: int = 0
    failed_replans: int = 0
    replan_wall_s: list[float] = field(default_factory=list)
    replan_delay_s: list[float] = field(default_factory=list)
    plan_wall_s: float = 0.0
    plan_cpu_s: float = 0.0
    t_end_s: float = 0.0
    planned_goal_s: float | None = None
    water: dict = field(default_factory=dict)
    replan_cpu_s: list[float] = field(default_factory=list)
    guidance: str = "pursuit"
    failed_replan_statuses: list[str] = field(default_factory=list)
    replan_budget_s: float | None = None
    shift_repairs: int = 0
    retries_before_contact: int = 0
    estimate_error_mm: dict = field(default_factory=dict)
    calm_budget_s: float | None = None
    calm_replans: int = 0
    calm_found: int = 0
    calm_cut: int = 0
    early_replans: int = 0
    early_found: int = 0
    early_cut: int = 0
    restarts: int = 0
    pauses: int = 0
    coast_clearance_m: float | None = None
    coast_contact: bool = False
    coast_s: float = 0.0
    harbours: list[str] = field(default_factory=list)
    harbourless: int = 0
    plan_guidance: str | None = None
    stations: int = 0
    corridor_ready_s: list[float] | None = None
    corridor_cpu_s: list[float | None] | None = None
    least_bad: int = 0
    least_bad_none: int = 0


def calm_and_early(replans: list[dict], replan_budget_s: float | None
                   ) -> tuple[list[dict], list[dict]]:
    """A run's calm replans and its early ones, from the replanner's events.

    Parameters
    ----------
    replans : list of dict
        The replanner's replan events (``reason``, ``budget_s``, ``status``, ``cut_for``).
    replan_budget_s : float or None
        The run's replan budget (None: no budget, so no replan was given a calm one).

    Returns
    -------
    calm, early : list of dict
        Replans asked for in a moved current estimate that were given a longer budget than
        ``replan_budget_s`` (docs/planning.md, "Calm replans get more time"), and replans asked
        for under the early margin (docs/planning.md, "An earlier replan"), which have a longer
        budget too but are counted apart.
    """
    calm = [e for e in replans if replan_budget_s is not None and e["reason"] == "current_estimate"
            and (e.get("budget_s") or 0.0) > replan_budget_s]
    early = [e for e in replans if e["reason"] == "early_margin"]
    return calm, early


def true_clearance_m(world: World, model: SwimmerModel, states: FloatArray) -> FloatArray:
    """The true body's gap to the nearest obstacle or wall at each state (negative: overlap).

    Written apart from the planner's check (which uses the link centre lines and the largest half
    width): each link i is a stadium of length 2 l_i and width 2 b_i around its centre
    (docs/model.md section 1: centre p + G cos(theta), p + G sin(theta)), built and measured
    with shapely; a disc's gap is the distance to its centre less its radius, a polygon's the
    exact distance (at most minus the link's half width when they overlap), a wall's the distance of the stadium's extent to the wall.

    Parameters
    ----------
    world : World
    model : SwimmerModel
    states : ndarray, shape (K, 2 N + 4)

    Returns
    -------
    ndarray, shape (K,)
    """
    k = len(states)
    n = model.n_links
    half_l, b = np.asarray(model.half_length_m), np.asarray(model.half_axis_horizontal_m)
    gaps = np.full(k, np.inf)
    for i in range(0, k, 2000):
        chunk = states[i : i + 2000]
        theta = chunk[:, :n]
        px, py = chunk[:, n], chunk[:, n + 1]
        cx = px[:, None] + np.cos(theta) @ model.geometry.T
        cy = py[:, None] + np.sin(theta) @ model.geometry.T
        reach = np.maximum(half_l - b, 1e-6)  # the stadium's core segment: its length less the caps
        ax, ay = cx - reach * np.cos(theta), cy - reach * np.sin(theta)
        bx, by = cx + reach * np.cos(theta), cy + reach * np.sin(theta)
        coords = np.stack([np.stack([ax, ay], -1), np.stack([bx, by], -1)], axis=-2)
        cores = shapely.linestrings(coords.reshape(-1, 2, 2))
        width = np.broadcast_to(b, theta.shape).ravel()
        best = np.full(cores.shape, np.inf)
        w, h = world.tank.size_m
        # walls: the core's extreme coordinates plus the cap radius
        xs, ys = coords[..., 0].reshape(-1, 2), coords[..., 1].reshape(-1, 2)
        best = np.minimum.reduce([best, xs.min(1) - width, w - xs.max(1) - width,
                                  ys.min(1) - width, h - ys.max(1) - width])
        for o in world.obstacles:
            if isinstance(o, CircleObstacle):
                d = shapely.distance(cores, shapely.points(*o.centre_m)) - o.radius_m - width
            else:
                poly = shapely.polygons(np.asarray(o.vertices_m, dtype=float))
                d = shapely.distance(cores, poly) - width
                # a core that meets the polygon overlaps it by at least the link's half width
                inside = shapely.intersects(cores, poly)
                d[inside] = -width[inside]
            best = np.minimum(best, d)
        gaps[i : i + 2000] = best.reshape(len(chunk), n).min(axis=1)
    return gaps


def water_for(seed: int, model: CoefficientModel,
              unknown_current_m_s: float = UNKNOWN_CURRENT_M_S) -> dict:
    """The virtual robot's water for a world: a coefficient draw and an unknown current.

    Parameters
    ----------
    seed : int
        The world's seed (the generator's).
    model : CoefficientModel
    unknown_current_m_s : float

    Returns
    -------
    dict
        ``coefficients`` (the law's order) and ``unknown_current_m_s`` (vx, vy).
    """
    rng = np.random.default_rng([seed, 28])
    coefficients = model.draw(rng, "straight").as_array()
    speed = unknown_current_m_s * float(rng.uniform())
    angle = float(rng.uniform(0.0, 2.0 * math.pi))
    return {"coefficients": [float(c) for c in coefficients],
            "unknown_current_m_s": [speed * math.cos(angle), speed * math.sin(angle)]}


def run_world(seed: int, robot: Robot, model: CoefficientModel, gait: Gait = PATH_GAIT,
              unknown_current_m_s: float = UNKNOWN_CURRENT_M_S,
              planner_options: dict[str, Any] | None = None,
              swimmer: SwimmerModel | None = None,
              replan_budget_s: float | None = REPLAN_BUDGET_S,
              record_to: Path | None = None,
              calm_budget_s: float | None = CALM_REPLAN_BUDGET_S,
              early_margin_m: float | None = None, escape: bool = False,
              restarts: int = 0, brake_s: float = BRAKE_S, harbour: bool = True,
              station: bool = False, least_bad: bool = True) -> WorldResult:
    """Plan one generated world and swim the plan over ``sim://`` (module docstring).

    Parameters
    ----------
    seed : int
    robot : Robot
    model : CoefficientModel
    gait : Gait
    unknown_current_m_s : float
    planner_options : dict, optional
        More keyword arguments of the planner (``--check-unknown-current``).
    swimmer : SwimmerModel, optional
        The model of the robot the planner swims, built once by the command
        (:meth:`CoefficientModel.swimmer_for`; built per world when not given). The virtual
        robot builds its own: it is the water, not the planner.
    replan_budget_s : float or None
        Each replan's wall-clock budget (:func:`eelhost.planning.tank.plan_for_run`).
    record_to : Path, optional
        Write the run's planning record there (the take's ``source.planning``: every plan and
        replan with its start state, status and message), to replay failing replans offline.
    calm_budget_s : float or None
        The calm replans' budget (:func:`eelhost.planning.tank.plan_for_run`).
    early_margin_m : float or None
        The early replans' margin (:func:`eelhost.planning.tank.plan_for_run`); None: off.
    escape : bool
        Replans from inside the check's margin use the escape
        (:func:`eelhost.planning.tank.plan_for_run`); off by default.
    restarts : int
        Restarts from rest a run may make (``TankReplanner``'s ``max_restarts``;
        docs/planning.md, "A restart from rest").
    brake_s : float
        The brake before the final Stop (``RunConfig.brake_s``; 0: none).
    harbour : bool
        Swim to where a stop stays clear before it (:func:`eelhost.planning.tank.plan_for_run`).
    station : bool
        Hold station instead of a stop the current carries into something
        (:func:`eelhost.planning.tank.plan_for_run`).
    least_bad : bool
        Swim the least-bad swim instead of a stop the current carries into something, while it
        beats the stop (:func:`eelhost.planning.tank.plan_for_run`); on by default.

    Returns
    -------
    WorldResult
    """
    world = generate_world(seed)
    water = water_for(seed, model, unknown_current_m_s)
    law = _law_name(planner_options)
    vx, vy = np.add(model.in_tank(world).current_m_s, water["unknown_current_m_s"])
    speed, direction = math.hypot(vx, vy), math.degrees(math.atan2(vy, vx))
    s = world.start
    uri = (f"sim://?speed=0&seed={seed}&coefficients="
           + ",".join(f"{c:.6g}" for c in water["coefficients"])
           + f"&current={speed:.6f},{direction:.3f}"
           + f"&start={s.position_m[0]:g},{s.position_m[1]:g},{s.heading_deg:g}")
    wall0, cpu0 = time.perf_counter(), time.process_time()
    try:
        planned = plan_for_run(world, robot, uri, gait, model, planner_options=planner_options,
                               swimmer=swimmer, replan_budget_s=replan_budget_s,
                               calm_budget_s=calm_budget_s, early_margin_m=early_margin_m,
                               escape=escape, restarts=restarts, harbour=harbour,
                               stop_brake_s=brake_s, station=station, least_bad=least_bad)
    except PlanRefused as err:
        return WorldResult(seed, False, err.status, detail=str(err), water=water,
                           plan_wall_s=time.perf_counter() - wall0,
                           plan_cpu_s=time.process_time() - cpu0, guidance=law)
    plan_wall, plan_cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    nav = planned.navigator
    cost = planned.outcome.plan.cost_s
    # the run loop steers with the law the plan was searched and checked with, from its start
    config = RunConfig(gait, planned.waypoints_m, duration_s=2.0 * cost + 30.0, brake_s=brake_s,
                       guidance=planned.guidance, start_guide=planned.start_guide)
    nav.estimator.history = []  # every frame's estimated body, for its error against the truth
    with tempfile.TemporaryDirectory() as tmp:
        request = TakeRequest(robot, config, str(Path(tmp) / "take"), TakeNotes(planned.uri),
                              "synthetic:clean", navigator=nav,
                              camera_view=TankView.covering(world.tank.size_m), trace_plant=True)
        result = run_take(request)
    out = result.outcome
    if result.signals:  # the take was stopped by a signal: so is the benchmark, unrecorded
        raise KeyboardInterrupt(f"{', '.join(result.signals)} received")
    vr = result.virtual_robot
    assert vr is not None and vr.trace is not None
    # the swimming run ends where the loop decided to stop; the brake and the Stop's answer after
    # it belong to the stop, judged with the glide after the take
    taken = len(vr.trace)
    decided = max(taken - round(out.stopping_s / (DT_US * 1e-6)), 1)
    glide_on(vr)
    coast_s = (len(vr.trace) - taken) * DT_US * 1e-6
    states = np.asarray(vr.trace)
    gaps = true_clearance_m(world, vr.model, states)
    trace, clear, stopping = states[:decided], gaps[:decided], gaps[decided - 1 :]
    estimate_error = estimate_error_mm(vr.model, nav.estimator.history, trace)
    if record_to is not None:
        record_to.parent.mkdir(parents=True, exist_ok=True)
        record_to.write_text(json.dumps({"seed": seed, "outcome": out.reason,
                                         "detail": out.detail, **nav.record()}))
    replans = [e for e in nav.events if e["kind"] == "replan"]
    calm, early = calm_and_early(replans, replan_budget_s)
    corridor = [e for e in replans
                if e.get("reason") == "left_corridor" and e.get("t_ready_s") is not None]
    return WorldResult(
        seed, True, "found", out.reason, out.detail, out.reason == "arrived",
        float(clear.min()), bool(clear.min() < 0.0), out.failsafe_reports,
        sum(e["status"] == "found" for e in replans),
        sum(e["status"] != "found" for e in replans),
        [e["wall_s"] for e in replans],
        [e["t_switch_s"] - e["t_request_s"] for e in replans if "t_switch_s" in e],
        plan_wall, plan_cpu, out.t_end_s, cost, water,
        [e["cpu_s"] for e in replans if e["cpu_s"] is not None], law,
        [e["status"] for e in replans if e["status"] != "found"], replan_budget_s,
        sum(e["message"].startswith("shift repair:") and "t_switch_s" in e for e in replans),
        nav.retries_before_contact, estimate_error, calm_budget_s if replan_budget_s else None,
        len(calm), sum(e["status"] == "found" for e in calm),
        sum("cut_for" in e for e in calm), len(early), sum(e["status"] == "found" for e in early),
        sum("cut_for" in e for e in early), nav.restarts,
        sum(e["kind"] == "halt" for e in nav.events), float(stopping.min()),
        bool(stopping.min() < 0.0), coast_s,
        [e["reason"] for e in nav.events if e["kind"] == "harbour" and e["status"] == "harbour"],
        sum(e["kind"] == "harbour" and e["status"] == "none" for e in nav.events),
        planned.guidance.name,
        sum(e["kind"] == "station" and e["status"] == "held" for e in nav.events),
        corridor_ready_s=[e["t_ready_s"] - e["t_request_s"] for e in corridor],
        corridor_cpu_s=[e["cpu_s"] for e in corridor],
        least_bad=sum(e["kind"] == "least_bad" and e["status"] == "swum" for e in nav.events),
        least_bad_none=sum(e["kind"] == "least_bad" and e["status"] == "none"
                           for e in nav.events))


def glide_on(robot: VirtualRobot, longest_s: float = COAST_AUDIT_S,
             rest_m_s: float = COAST_REST_M_S) -> None:
    """Step the stopped robot on after its take, its trace kept, while the body still glides.

    The take's trace ends with the final Stop's answer; the plant and the firmware (in its
    stopped state, the link closed) are stepped on here, a second at a time, until the centre of
    mass moves slower than ``rest_m_s`` through the water or ``longest_s`` has passed, so that a
    body that glides into an obstacle after a deliberate stop is judged by the same independent
    geometry (:func:`true_clearance_m` over the trace).

    Parameters
    ----------
    robot : VirtualRobot
        The take's virtual robot, with its trace on.
    longest_s : float
    rest_m_s : float
    """
    assert robot.trace is not None
    n = robot.model.n_links
    end_us = robot.now_us + round(longest_s * 1e6)
    while robot.now_us < end_us:
        robot.advance_to(min(robot.now_us + 1_000_000, end_us))
        velocity = np.asarray(robot.trace[-1][2 * n + 2 : 2 * n + 4]) - robot.current_m_s
        if float(np.hypot(*velocity)) < rest_m_s:
            break


def estimate_error_mm(model: SwimmerModel, history: list[tuple[float, FloatArray]] | None,
                      trace: FloatArray) -> dict[str, float]:
    """The estimated bodies' error against the plant's trace at each frame's time.

    The trace holds the plant's state at every physics step k dt from the gait's start, the
    frames' clock (:class:`eelhost.xil.virtual_robot.VirtualRobot`); each frame is compared with
    the step nearest its time.

    Parameters
    ----------
    model : SwimmerModel
        The virtual robot's model (the true body).
    history : list of (t, pose) or None
        :attr:`BodyStateEstimator.history`.
    trace : ndarray, shape (K, 2 N + 4)

    Returns
    -------
    dict
        :func:`eelhost.planning.state_estimate.error_summary_mm`.
    """
    if not history:
        return error_summary_mm(np.zeros(0))
    dt = DT_US * 1e-6
    steps = np.clip(np.rint(np.array([t for t, _ in history]) / dt).astype(int), 0, len(trace) - 1)
    poses = np.array([pose for _, pose in history])
    return error_summary_mm(body_error_m(model, poses, trace[steps]))


def _law_name(planner_options: dict[str, Any] | None) -> str:
    """The name of the guidance law the planner options give (pure pursuit by default).

    ``auto`` for laws tried in turn (the guidance chosen per plan).
    """
    law = (planner_options or {}).get("guidance")
    if isinstance(law, tuple):  # the laws tried in turn: the guidance chosen per plan
        return AUTO_GUIDANCE
    return "pursuit" if law is None else str(law.name)


def run_closed_loop_bench(robot: Robot, model: CoefficientModel, seeds: range, out: Path,
                          progress: Callable[[WorldResult], None] | None = None,
                          planner_options: dict[str, Any] | None = None,
                          swimmer: SwimmerModel | None = None,
                          replan_budget_s: float | None = REPLAN_BUDGET_S,
                          calm_budget_s: float | None = CALM_REPLAN_BUDGET_S,
                          early_margin_m: float | None = None,
                          escape: bool = False,
                          restarts: int = 0,
                          brake_s: float = BRAKE_S,
                          harbour: bool = True,
                          station: bool = False,
                          least_bad: bool = True,
                          ) -> list[WorldResult]:
    """Run the benchmark over ``seeds``, resuming from ``<out>/results.jsonl``.

    Parameters
    ----------
    robot : Robot
    model : CoefficientModel
    seeds : range
    out : Path
        Folder of ``results.jsonl`` (and ``planning/<seed>.json``, each run's planning record).
    progress : callable, optional
        Called with each world's result as it is finished (or read back).
    planner_options : dict, optional
        More keyword arguments of the planner.
    swimmer : SwimmerModel, optional
        The model of the robot the planner swims, handed to every world's planner (built once
        here when not given).
    replan_budget_s : float or None
        Each replan's wall-clock budget (:func:`run_world`).
    calm_budget_s : float or None
        The calm replans' budget (:func:`run_world`).
    early_margin_m : float or None
        The early replans' margin (:func:`run_world`).
    escape : bool
        The escape (:func:`run_world`).
    restarts : int
        Restarts from rest per run (:func:`run_world`).
    brake_s : float
        The brake before each run's final Stop (:func:`run_world`).
    harbour : bool
        The harbour before a stop (:func:`run_world`).
    station : bool
        Holding station instead of a stop that drifts into something (:func:`run_world`).
    least_bad : bool
        The least-bad swim instead of a stop that drifts into something (:func:`run_world`).

    Returns
    -------
    list of WorldResult

    Raises
    ------
    UserError
        ``results.jsonl`` holds worlds run with another guidance law.
    """
    out.mkdir(parents=True, exist_ok=True)
    path = out / "results.jsonl"
    done: dict[int, WorldResult] = {}
    known = {f.name for f in fields(WorldResult)}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                # keys of fields since removed (``escapes``, session 6's escape leg) are dropped
                r = WorldResult(**{k: v for k, v in json.loads(line).items() if k in known})
                done[r.seed] = r
    law = _law_name(planner_options)
    other = sorted({r.seed for r in done.values() if r.guidance != law})
    if other:
        raise UserError(f"{path}: worlds {other[0]}.. were run with another guidance law than "
                         f"{law}; use another --out")
    results = []
    if swimmer is None:
        swimmer = model.swimmer_for(robot)
    for seed in seeds:
        if seed in done:
            r = done[seed]
        else:
            r = run_world(seed, robot, model, planner_options=planner_options,
                          swimmer=swimmer, replan_budget_s=replan_budget_s,
                          record_to=out / "planning" / f"{seed}.json",
                          calm_budget_s=calm_budget_s, early_margin_m=early_margin_m,
                          escape=escape, restarts=restarts, brake_s=brake_s, harbour=harbour,
                          station=station, least_bad=least_bad)
            with path.open("a") as f:
                f.write(json.dumps(asdict(r)) + "\n")
        results.append(r)
        if progress is not None:
            progress(r)
    return results


CURRENT_BANDS_M_S = (0.02, 0.04)
"""The world's own current's bands the summary splits the plan share and the goal by: the share
falls with the current (development seeds 30500-30799: 92 %, 55 % and 31 %; docs/planning.md)."""


def by_current_line(results: list[WorldResult]) -> str:
    """Plan share and goal reached per band of the world's own current (``CURRENT_BANDS_M_S``)."""
    edges = (0.0, *CURRENT_BANDS_M_S, math.inf)
    speeds = [generate_world(r.seed).current.speed_m_s for r in results]
    parts = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        band = [r for r, v in zip(results, speeds, strict=True) if lo <= v < hi]
        planned = [r for r in band if r.planned]
        name = f"{lo:g}-{hi:g} m/s" if math.isfinite(hi) else f"from {lo:g} m/s"
        parts.append(f"{name}: planned {len(planned)} of {len(band)}, goal "
                     f"{sum(r.reached for r in planned)} of {len(planned)}")
    return "- by the world's own current: " + "; ".join(parts)


def corridor_lines(planned: list[WorldResult]) -> list[str]:
    """The summary's line on issue 28's replan target: an answer within 1 s of leaving the corridor.

    Parameters
    ----------
    planned : list of WorldResult
        The runs of the planned worlds.

    Returns
    -------
    list of str
        One line, or none when no run recorded such replans (results written before session 21
        did not).
    """
    recorded = [r for r in planned if r.corridor_ready_s is not None]
    ready = [d for r in recorded for d in r.corridor_ready_s or []]
    if not ready:
        return []
    late = [(d, c) for r in recorded
            for d, c in zip(r.corridor_ready_s or [], r.corridor_cpu_s or [], strict=True)
            if d > 1.0]
    line = (f"- replans on leaving the corridor, answered within 1 s of the request (robot's "
            f"clock): {sum(d <= 1.0 for d in ready)} of {len(ready)}")
    if late:
        # a late answer that took little processor time waited for a core: the machine's load
        line += ("; the late ones took " + ", ".join(f"{d:.2f} s" for d, _ in late)
                 + " with " + ", ".join("?" if c is None else f"{c:.2f}" for _, c in late)
                 + " s of processor time")
    return [line]


def summary_lines(results: list[WorldResult]) -> list[str]:
    """The benchmark's figures, as markdown list items."""
    planned = [r for r in results if r.planned]
    lines = [f"- worlds: {len(results)}; with a checked plan: {len(planned)} "
             f"({100 * len(planned) / max(len(results), 1):.0f} %); without: "
             + ", ".join(f"{k} {v}" for k, v in sorted(Counter(
                 r.status for r in results if not r.planned).items())),
             by_current_line(results)]
    if not planned:
        return lines
    reached = sum(r.reached for r in planned)
    contacts = [r for r in planned if r.contact]
    lines.append(f"- goal reached: {reached} of {len(planned)} planned worlds "
                 f"({100 * reached / len(planned):.1f} %)")
    lines.append(f"- body contacts (true state, independent geometry): {len(contacts)} of "
                 f"{len(planned)} runs"
                 + (f" (seeds {', '.join(str(r.seed) for r in contacts)}; deepest "
                    f"{-min(r.min_clearance_m or 0.0 for r in contacts) * 1000:.0f} mm)"
                    if contacts else ""))
    clear = [r.min_clearance_m for r in planned if r.min_clearance_m is not None]
    if clear:
        lines.append(f"- smallest true clearance over a run: median {statistics.median(clear) * 1000:.0f}"
                     f" mm, smallest {min(clear) * 1000:.0f} mm")
    errors = [r.estimate_error_mm for r in planned if r.estimate_error_mm.get("frames")]
    if errors:
        med = {k: statistics.median(e[k] for e in errors) for k in ("p50_mm", "p95_mm", "max_mm")}
        lines.append(f"- the camera's body estimate against the true body (largest distance of "
                     f"its points in a frame): each run's median, 95th percentile and largest, "
                     f"median over {len(errors)} runs: {med['p50_mm']:.0f}, {med['p95_mm']:.0f} "
                     f"and {med['max_mm']:.0f} mm; largest in any frame "
                     f"{max(e['max_mm'] for e in errors):.0f} mm")
    coasted = [r for r in planned if r.coast_clearance_m is not None]
    if coasted:
        touched = [r for r in coasted if r.coast_contact]
        lines.append(f"- body contacts while stopping (from the decision to stop, through the "
                     f"brake and the glide after the Stop until slower than {COAST_REST_M_S:g} "
                     f"m/s through the water, at most {COAST_AUDIT_S:g} s): {len(touched)} of "
                     f"{len(coasted)} runs"
                     + (f" (seeds {', '.join(str(r.seed) for r in touched)})" if touched else "")
                     + f"; smallest clearance "
                     f"{min(r.coast_clearance_m or 0.0 for r in coasted) * 1000:.0f} mm; the "
                     f"glide after the Stop lasted {statistics.median(r.coast_s for r in coasted):.0f} s "
                     f"(median), {max(r.coast_s for r in coasted):.0f} s at most")
    failsafe = [r for r in planned if r.failsafe_reports]
    lines.append(f"- runs with the firmware in FAILSAFE: {len(failsafe)}")
    ends = Counter(r.reason for r in planned)
    lines.append("- how the runs ended: " + ", ".join(f"{k} {v}" for k, v in sorted(ends.items())))
    walls = [w for r in planned for w in r.replan_wall_s]
    lines.append(f"- replans switched in: {sum(r.replans for r in planned)}, besides"
                 f" {sum(r.failed_replans for r in planned)} that failed, in "
                 f"{sum(1 for r in planned if r.replans or r.failed_replans)} runs"
                 + (f"; wall time from request to plan: median {statistics.median(walls):.2f} s,"
                    f" largest {max(walls):.2f} s" if walls else ""))
    repaired = [r for r in planned if r.shift_repairs]
    if repaired:
        lines.append(f"- shift repairs switched in: {sum(r.shift_repairs for r in repaired)}, in "
                     f"{len(repaired)} runs ({sum(r.reached for r in repaired)} of them reached "
                     "the goal)")
    retried = [r for r in planned if r.retries_before_contact]
    if retried:
        lines.append(f"- replans retried at once before a predicted contact instead of a stop: "
                     f"{sum(r.retries_before_contact for r in retried)}, in {len(retried)} runs "
                     f"({sum(r.reached for r in retried)} of them reached the goal)")
    budgets = sorted({r.replan_budget_s for r in planned if r.replan_budget_s is not None})
    failed = Counter(s for r in planned for s in r.failed_replan_statuses)
    if budgets or failed:
        lines.append("- each replan's wall-clock budget: "
                     + (", ".join(f"{b:g} s" for b in budgets) if budgets else "none")
                     + "; failed replans by status: "
                     + (", ".join(f"{k} {v}" for k, v in sorted(failed.items())) or "none"))
    calm_budgets = sorted({r.calm_budget_s for r in planned if r.calm_budget_s is not None})
    if calm_budgets:
        lines.append(f"- calm replans (in a moved current estimate, budget "
                     f"{', '.join(f'{b:g} s' for b in calm_budgets)}): "
                     f"{sum(r.calm_replans for r in planned)}, of which "
                     f"{sum(r.calm_found for r in planned)} found a plan and "
                     f"{sum(r.calm_cut for r in planned)} were cut short for an urgent replan")
    if any(r.early_replans for r in planned):
        lines.append(f"- early replans (the look-ahead's capsule under the early margin): "
                     f"{sum(r.early_replans for r in planned)}, of which "
                     f"{sum(r.early_found for r in planned)} found a plan and "
                     f"{sum(r.early_cut for r in planned)} were cut short for an urgent replan")
    if any(r.pauses for r in planned):
        paused = [r for r in planned if r.pauses]
        lines.append(f"- pauses for a restart from rest: {sum(r.pauses for r in paused)} in "
                     f"{len(paused)} runs, restarts made {sum(r.restarts for r in paused)}; "
                     f"{sum(r.reached for r in paused)} of these runs reached the goal")
    harboured = [r for r in planned if r.harbours or r.harbourless]
    if harboured:
        kinds = Counter(k for r in harboured for k in r.harbours)
        lines.append(f"- harbour swims before a stop the twin drifted within the margin: "
                     f"{sum(len(r.harbours) for r in harboured)} in {len(harboured)} runs ("
                     + ", ".join(f"{k} {v}" for k, v in sorted(kinds.items()))
                     + f"); none found for {sum(r.harbourless for r in harboured)} stops; "
                     f"{sum(r.coast_contact for r in harboured)} of these runs touched while "
                     "stopping")
    stationed = [r for r in planned if r.stations]
    if stationed:
        lines.append(f"- stations held instead of a stop the twin drifted within the margin: "
                     f"{sum(r.stations for r in stationed)} in {len(stationed)} runs; "
                     f"{sum(r.reached for r in stationed)} of these runs reached the goal, "
                     f"{sum(r.coast_contact for r in stationed)} touched while stopping")
    swum = [r for r in planned if r.least_bad or r.least_bad_none]
    if swum:
        lines.append(f"- least-bad swims instead of a stop the twin drifted within the margin: "
                     f"{sum(r.least_bad for r in swum)} in {sum(bool(r.least_bad) for r in swum)} "
                     f"runs, none beating the stop {sum(r.least_bad_none for r in swum)} times; "
                     f"of the {len(swum)} runs judged, {sum(r.reached for r in swum)} reached "
                     f"the goal, {sum(r.contact for r in swum)} touched while swimming, "
                     f"{sum(r.coast_contact for r in swum)} while stopping")
    cpus = [c for r in planned for c in r.replan_cpu_s]
    if cpus:
        lines.append(f"- replans' processor time: median {statistics.median(cpus):.2f} s, "
                     f"largest {max(cpus):.2f} s")
    delays = [d for r in planned for d in r.replan_delay_s]
    if delays:
        lines.append(f"- robot's time from a replan's request to its plan steering: median "
                     f"{statistics.median(delays):.2f} s, largest {max(delays):.2f} s "
                     f"({sum(d <= 1.0 for d in delays)} of {len(delays)} within 1 s)")
    lines += corridor_lines(planned)
    times = [r.t_end_s / r.planned_goal_s for r in planned if r.reached and r.planned_goal_s]
    if times:
        lines.append(f"- swum time over planned time (reached runs): median "
                     f"{statistics.median(times):.2f}, largest {max(times):.2f}")
    cpu = [r.plan_cpu_s for r in results]
    lines.append(f"- first plan, processor time: median {statistics.median(cpu):.2f} s; wall "
                 f"time median {statistics.median(r.plan_wall_s for r in results):.2f} s")
    failures = [r for r in planned if not r.reached or r.contact or r.coast_contact]
    if failures:
        lines.append("- every failure:")
        lines += [f"  - seed {r.seed}: {r.reason} (true body "
                  + (f"{-(r.min_clearance_m or 0.0) * 1000:.0f} mm into an obstacle or wall"
                     if r.contact else f"{(r.min_clearance_m or 0.0) * 1000:.0f} mm clear")
                  + (f"; touched while stopping, {-(r.coast_clearance_m or 0.0) * 1000:.0f} mm "
                     "deep" if r.coast_contact else "")
                  + f"): {r.detail}" for r in failures]
    return lines
