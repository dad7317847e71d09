"""How far the check's runs stray beyond the body the search swept (docs/planning.md, "A geometric ceiling").

For each world: the search's first plan (the check off), swum leg by leg as the check swims it
with the fits as fitted (the searched run) and in the check's draws of the water
(:meth:`eelhost.planning.planner.Planner.waters`, attempt 0). A draw's *stray* is the largest
distance of any of its body centre-line points (every 5th physics step) from the centre-line
points the searched run swept (a k-d tree over the searched run's points, 4 per link, every
step: the points are at most 20 mm apart along the body, so the stray is over-stated by at most
10 mm). Prints, per world, the draws' stray quartiles and 90th percentile, and over all draws.

Usage: ``nice .venv/bin/python scripts/plan_stray.py --seed 8000 --worlds 6 [--guidance ilos]``
(development seeds 8000-8299 only).
"""

from __future__ import annotations

import argparse
import logging

import numpy as np
from scipy.spatial import cKDTree

from eelhost.planning.body import body_points
from eelhost.planning.planner import PLANNING_GUIDANCE, Planner
from eelhost.planning.uncertainty import WaterDraw, default_model
from eelhost.planning.worlds import generate_world
from eelsim.guidance import PURSUIT
from eelsim.robot import load_robot


def main() -> None:
    """Print the strays of the check's draws for a range of development worlds."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=8000)
    parser.add_argument("--worlds", type=int, default=6)
    parser.add_argument("--draws", type=int, default=60)
    parser.add_argument("--guidance", choices=["pursuit", "ilos"], default="pursuit")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    robot = load_robot()
    coefficients = default_model(robot)
    law = PLANNING_GUIDANCE if args.guidance == "ilos" else PURSUIT
    everything: list[float] = []
    failing: list[float] = []
    for seed in range(args.seed, args.seed + args.worlds):
        world = generate_world(seed)
        planner = Planner(world, robot, coefficients, draws=args.draws, seed=seed, check=False,
                          guidance=law)
        outcome = planner.plan()
        if not outcome.found:
            print(f"{world.name}: no searched plan ({outcome.status})")
            continue
        nominal = WaterDraw("fits", coefficients.fits["straight"], coefficients.fits["turning"],
                            (0.0, 0.0))
        runs = planner.swim_waters(outcome.plan, [nominal, *planner.waters(0)])
        swept = body_points(planner.model, runs[0].states, per_link=4).reshape(-1, 2)
        tree = cKDTree(swept)
        strays = []
        for run in runs[1:]:
            pts = body_points(planner.model, run.states[::5], per_link=4).reshape(-1, 2)
            d = float(tree.query(pts)[0].max())
            strays.append(d)
            (everything if run.ok else failing).append(d)
        q = np.percentile(strays, [25, 50, 75, 90]) * 1000
        bad = sum(not r.ok for r in runs[1:])
        print(f"{world.name}: {len(outcome.plan.legs)} legs, searched clearance "
              f"{min(leg.min_clearance_m for leg in outcome.plan.legs) * 1000:.0f} mm, "
              f"{bad} of {len(runs) - 1} draws fail; stray 25/50/75/90 %: "
              + " ".join(f"{v:.0f}" for v in q) + " mm", flush=True)
    for name, values in (("passing draws", everything), ("failing draws", failing),
                         ("all draws", everything + failing)):
        if values:
            q = np.percentile(values, [25, 50, 75, 90]) * 1000
            print(f"{name} ({len(values)}): stray 25/50/75/90 %: "
                  + " ".join(f"{v:.0f}" for v in q) + " mm")


if __name__ == "__main__":
    main()
