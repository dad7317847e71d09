"""Replay a closed-loop benchmark's replans offline through the planner.

docs/planning.md, "Session 10's development figures: the replans' search".

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
the planner. ``--fine-tiers planner,approach,recovery`` turns the finer-action fallback
(``Planner(fine_fallback=True)``) on for those tiers (default: none, as ``eelbot run`` builds
them since the fallback was turned off; session 10's replays used ``approach,recovery``).

Usage: ``nice .venv/bin/python scripts/replay_replans.py OUT [OUT ...] --chain --deadline 1``
(development seeds only).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import time
from pathlib import Path

import numpy as np

from eelhost.planning.planner import Outcome, Planner
from eelhost.planning.replan import GOAL_APPROACH_CLEARANCE_M
from eelhost.planning.search import SearchSettings
from eelhost.planning.tank import (
    RECOVERY_ACTIONS,
    RECOVERY_EXPANSIONS,
    RECOVERY_REPAIRS,
    with_extra_current,
)
from eelhost.planning.uncertainty import default_model
from eelhost.planning.worlds import generate_world
from eelsim.robot import load_robot

log = logging.getLogger("replay_replans")


def main() -> None:
    """Replay the replans and print one JSON line each, then the count found."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("outs", nargs="+", help="folders of eelbot run --bench --out")
    ap.add_argument("--deadline", type=float, default=None, help="processor seconds per replan")
    ap.add_argument("--chain", action="store_true", help="the goal approach and the recovery too")
    ap.add_argument("--fine-tiers", default="",
                    help="tiers with the finer-action fallback (comma-separated; '' for none)")
    ap.add_argument("--all", action="store_true", help="every replan, not only the failed ones")
    ap.add_argument("--seeds", default="", help="only these seeds (comma-separated)")
    a = ap.parse_args()
    tiers = {t for t in a.fine_tiers.split(",") if t}
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
            first = Planner(world, robot, model, **opts)  # type: ignore[arg-type]
            first.clock = time.process_time
            if a.deadline is not None:
                first.plan()  # measures the check's cost, as the tank's first plan does
            for e in replans:
                extra = np.subtract(e["current_m_s"], first.world.current_m_s)
                water = with_extra_current(world, extra)
                near = water.model_copy(update={"clearance_m": 0.0})
                margin = first.body_half_width_m + GOAL_APPROACH_CLEARANCE_M

                def planner(name: str, w=water, opts=opts, **settings) -> Planner:  # noqa: ANN001, ANN003
                    extra_opts = {"repairs": RECOVERY_REPAIRS} if name == "recovery" else {}
                    p = Planner(w, robot, model, fine_fallback=name in tiers,  # type: ignore[arg-type]
                                settings=dataclasses.replace(SearchSettings(), **settings)
                                if settings else None, **opts, **extra_opts)
                    p.clock = time.process_time
                    return p

                state = np.asarray(e["start_state"], dtype=float)
                main_planner = planner("planner")
                step = int(round(e["t_start_s"] / main_planner.twin.dt_s))
                c0 = time.process_time()
                deadline = None if a.deadline is None else c0 + a.deadline

                def left(deadline: float | None = deadline) -> bool:
                    return deadline is None or time.process_time() < deadline

                outcome: Outcome = main_planner.plan(state, step, deadline_s=deadline)
                tier = "planner"
                if a.chain and not outcome.found and outcome.status == "exhausted" and left():
                    approach = planner("approach", near, margin_m=margin).plan(
                        state, step, deadline_s=deadline)
                    if approach.found:
                        outcome, tier = approach, "approach"
                if (a.chain and not outcome.found and outcome.status not in (
                        "blocked_start", "out_of_time") and left()):
                    rescue = planner("recovery", near, margin_m=margin, actions=RECOVERY_ACTIONS,
                                     max_expansions=RECOVERY_EXPANSIONS).plan(
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
