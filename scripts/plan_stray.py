"""How far the check's runs stray beyond the body the search swept (docs/planning_history.md, "A geometric ceiling").

For each world: the search's first plan (the check off), swum leg by leg as the check swims it
with the fits as fitted (the searched run) and in the check's draws of the water
(:meth:`eelhost.planning.planner.Planner.waters`, attempt 0). A draw's *stray* is the largest
distance of any of its body centre-line points (every 5th physics step) from the centre-line
points the searched run swept (a k-d tree over the searched run's points, 4 per link, every
step: the points are at most 20 mm apart along the body, so the stray is over-stated by at most
10 mm). A draw's *gap loss* is how much closer to anything its body comes than the searched
run's did (the smallest body gap of the searched run less the draw's): the check passes a plan
when its searched gap exceeds every draw's loss. The *sweep* is how far the searched run's
body reaches beside its own centre of mass's path. Prints, per world, the draws' stray quartiles and 90th percentile, and over all draws.

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
    loss_all: list[float] = []
    loss_max: list[float] = []
    gaps: list[float] = []
    sweeps: list[float] = []
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
        # the body's own sweep: how far the searched run's body reaches beside its centre of
        # mass's path (the tail's swing, and the body's ends in the turns)
        # (the first and last 15 % of the run left out, where the head and the tail reach
        # past the path's ends)
        n = planner.model.n_links
        k = len(runs[0].states)
        path = cKDTree(runs[0].states[:, n : n + 2])
        middle = body_points(planner.model, runs[0].states[int(0.15 * k) : int(0.85 * k) : 5],
                             per_link=4).reshape(-1, 2)
        sweep = float(path.query(middle)[0].max())
        sweeps.append(sweep)
        strays = []
        # how much closer to anything the draw's body comes than the searched run's did
        losses = [runs[0].min_clearance_m - run.min_clearance_m for run in runs[1:]]
        loss_all.extend(losses)
        loss_max.append(max(losses))
        gaps.append(runs[0].min_clearance_m)
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
              + " ".join(f"{v:.0f}" for v in q) + f" mm; searched body gap "
              f"{runs[0].min_clearance_m * 1000:.0f} mm, draws' gap loss median "
              f"{np.median(losses) * 1000:.0f} max {max(losses) * 1000:.0f} mm; body sweep beside "
              f"the path {sweep * 1000:.0f} mm", flush=True)
    for name, values in (("passing draws", everything), ("failing draws", failing),
                         ("all draws", everything + failing)):
        if values:
            q = np.percentile(values, [25, 50, 75, 90]) * 1000
            print(f"{name} ({len(values)}): stray 25/50/75/90 %: "
                  + " ".join(f"{v:.0f}" for v in q) + " mm")
    if loss_all:
        q = np.percentile(loss_all, [25, 50, 75, 90]) * 1000
        print("gap loss over all draws 25/50/75/90 %: " + " ".join(f"{v:.0f}" for v in q)
              + " mm; per plan, the largest of its draws': median "
              f"{np.median(loss_max) * 1000:.0f} mm, range {min(loss_max) * 1000:.0f}-"
              f"{max(loss_max) * 1000:.0f} mm; searched body gaps median "
              f"{np.median(gaps) * 1000:.0f} mm; body sweep beside the searched path: median "
              f"{np.median(sweeps) * 1000:.0f} mm, range {min(sweeps) * 1000:.0f}-"
              f"{max(sweeps) * 1000:.0f} mm")


if __name__ == "__main__":
    main()
