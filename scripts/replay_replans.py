"""Replay a closed-loop benchmark's replans offline through the planner.

docs/planning_history.md, "Session 10's development figures: the replans' search".

Reads ``<out>/planning/<seed>.json`` of ``eelbot run --bench --out <out>`` (each replan's start
state, start time, water and outcome) and plans again from every replan start that failed at the
tank (or was found only by the recovery or the shift repair; ``--all``: every replan), in the
replan's water, pure pursuit, the check told of no unknown current (as ``--check-unknown-current
0``). ``--chain`` runs the replanner's tiers after the planner as ``TankReplanner`` does: the goal
approach's planner (the body's half width plus 10 mm, the world's clearance 0) when the search
was exhausted, then the recovery's (its sharper turns, 48 expansions, one repair) unless the
planner ran out of time; the shift repair is not replayed. ``--deadline S`` gives each replan
a deadline S seconds of *processor* time after it starts, the planners' clocks reading
``time.process_time`` (each world's first plan is planned first, so the check's measured cost
is known as at the tank): on the loaded machine a wall-clock budget measures the load as much as
the planner. The tiers are ``eelbot run``'s own (:func:`eelhost.planning.tank.replan_planners`).

Usage: ``nice .venv/bin/python scripts/replay_replans.py OUT [OUT ...] --chain --deadline 1``
(development seeds only).
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

import numpy as np

from eelhost.planning.planner import Outcome, Planner
from eelhost.planning.tank import replan_planners
from eelhost.planning.uncertainty import default_model
from eelhost.planning.worlds import generate_world
from eelsim.robot import load_robot
from eelsim.scenario import PATH_GAIT

log = logging.getLogger("replay_replans")


def main() -> None:
    """Replay the replans and print one JSON line each, then the count found."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outs", nargs="+", help="folders of eelbot run --bench --out")
    ap.add_argument("--deadline", type=float, default=None, help="processor seconds per replan")
    ap.add_argument("--chain", action="store_true", help="the goal approach and the recovery too")
    ap.add_argument("--all", action="store_true", help="every replan, not only the failed ones")
    ap.add_argument("--seeds", default="", help="only these seeds (comma-separated)")
    a = ap.parse_args()
    robot = load_robot()
    model = default_model(robot)
    swimmer = model.swimmer_for(robot)
    found = total = 0
    for out in a.outs:
        for path in sorted(Path(out, "planning").glob("*.json")):
            rec = json.loads(path.read_text())
            seed = int(rec["seed"])
            if a.seeds and str(seed) not in a.seeds.split(","):
                continue
            replans = [e for e in rec["plans"] if e["kind"] == "replan" and e["start_state"]]
            if not a.all:
                replans = [e for e in replans if e["status"] != "found" or e["message"].startswith(
                    ("recovery", "shift repair"))]
            if not replans:
                continue
            world = generate_world(seed)
            opts = {"unknown_current_m_s": 0.0, "swimmer": swimmer}
            first = Planner(world, robot, model, PATH_GAIT, **opts)  # type: ignore[arg-type]
            first.clock = time.process_time
            if a.deadline is not None:
                first.plan()  # measures the check's cost, as the tank's first plan does
            tiers = replan_planners(first, world, robot, model, PATH_GAIT, opts)

            def timed(p: Planner) -> Planner:
                p.clock = time.process_time
                return p

            for e in replans:
                extra = np.subtract(e["current_m_s"], first.world.current_m_s)
                state = np.asarray(e["start_state"], dtype=float)
                main_planner = timed(tiers.planner_for(extra))
                step = int(round(e["t_start_s"] / main_planner.twin.dt_s))
                c0 = time.process_time()
                deadline = None if a.deadline is None else c0 + a.deadline

                def left(deadline: float | None = deadline) -> bool:
                    return deadline is None or time.process_time() < deadline

                outcome: Outcome = main_planner.plan(state, step, deadline_s=deadline)
                tier = "planner"
                if a.chain and not outcome.found and outcome.status == "exhausted" and left():
                    approach = timed(tiers.goal_planner_for(extra)).plan(
                        state, step, deadline_s=deadline)
                    if approach.found:
                        outcome, tier = approach, "approach"
                if (a.chain and not outcome.found and outcome.status not in (
                        "blocked_start", "out_of_time") and left()):
                    rescue = timed(tiers.recovery_planner_for(extra)).plan(
                        state, step, deadline_s=deadline)
                    if rescue.found:
                        outcome, tier = rescue, "recovery"
                total += 1
                found += outcome.found
                print(json.dumps({
                    "seed": seed, "t_start_s": e["t_start_s"], "reason": e["reason"],
                    "at_tank": e["status"], "status": outcome.status,
                    "tier": tier if outcome.found else None,
                    "cpu_s": round(time.process_time() - c0, 2),
                    "message": outcome.message[:160]}), flush=True)
    print(f"found {found} of {total}")


if __name__ == "__main__":
    logging.basicConfig(level=logging.WARNING)
    main()
