"""``eelbot estimate-bench``: measure the estimator against its targets and write the figures.

The measurements are :func:`eelhost.benchmarks.estimator_accuracy.estimator_report`'s; results go
to stdout, and with ``--write`` to a markdown file (``docs/estimation_benchmarks.md``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from eelhost.benchmarks.estimator_accuracy import estimator_report
from eelhost.commands import COMMANDS
from eelhost.commands.common import (
    COUNT,
    SEED,
    add_current_option,
    add_write_option,
    write_report,
)
from eelhost.commands.dataset import plant_help
from eelhost.commands.joint_models_option import add_joint_models_option
from eelhost.commands.report import law_names
from eelhost.data.plants import PLANTS
from eelhost.errors import UserError

WRITE_DEFAULT = "docs/estimation_benchmarks.md"


@COMMANDS.add("estimate-bench", "measure the estimator against its targets")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "estimate-bench",
        help=COMMANDS.description("estimate-bench"),
        description="Measure the estimator against its targets and write the figures.",
    )
    p.add_argument("--work", default="out/estimate-bench", help="folder for generated datasets")
    add_write_option(p, WRITE_DEFAULT)
    p.add_argument(
        "--ga-generations", type=COUNT, default=130, help="GA generations (the paper's 130)"
    )
    p.add_argument("--skip-ga", action="store_true", help="leave out the GA comparison")
    p.add_argument(
        "--tanks",
        metavar="NAME,...",
        help="measure only these tanks (default: all): bundled, clean, or test plants (eelbot "
        "dataset --plant): " + ", ".join(sorted(PLANTS)),
    )
    p.add_argument(
        "--coverage",
        type=COUNT,
        metavar="SEEDS",
        help="instead: measure the report's interval coverage over SEEDS synthetic tanks (a bare "
        "--write then writes docs/estimation_coverage.md)",
    )
    p.add_argument(
        "--bands",
        metavar="PLANT,...",
        help="instead: measure the report's 95 %% prediction bands' coverage of held-out "
        "positions on these test plants (docs/estimation_coverage.md): " + plant_help(),
    )
    p.add_argument("--motions", default="straight", metavar="MOTION,...",
                   help="with --coverage: the motions each tank records and fits (default: "
                   "straight; straight,turning: both, the tank's one current held by each fit, "
                   "as eelbot report gives the intervals)")
    p.add_argument("--choose", action="store_true",
                   help="with --bands: the report's model comparison on (as by default), the "
                   "bands of the model it chooses (without it: the robot file's model)")
    p.add_argument("--robot", help="the robot file the datasets declare (default: the paper's; "
                   "--tanks: the same recordings under either bundled file; --coverage: the "
                   "model fitted to the same recordings; --bands: the robot the plants are "
                   "recorded from)")
    p.add_argument("--replicates", type=COUNT, default=8,
                   help="bootstrap refits (--coverage, --bands)")
    p.add_argument("--seed", type=SEED, default=0, help="seed of the datasets and the fits")
    add_current_option(p)  # one setting for every tank
    add_joint_models_option(p)
    p.add_argument("--laws", type=law_names, metavar="LAW,...",
                   help="fluid laws the comparison tries on every tank (default: the report's)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    if args.motions != "straight" and not args.coverage:
        raise UserError("--motions: goes with --coverage SEEDS (the motions each tank fits)")
    if args.choose and not args.bands:
        raise UserError("--choose: goes with --bands PLANT,... (the bands of the chosen model)")
    if args.bands:
        from eelhost.benchmarks.estimator_coverage import bands_markdown, measure_bands

        names = args.bands.split(",")
        unknown = [n for n in names if n not in PLANTS]
        if unknown:
            raise UserError(f"--bands: {PLANTS.unknown_message(unknown[0])}")
        bands = measure_bands(names, Path(args.work), args.robot, args.seed, args.replicates,
                              say=lambda line: print(line, flush=True), compare=args.choose)
        print(bands_markdown(bands, f"eelbot estimate-bench --bands {args.bands}"
                             + (f" --robot {args.robot}" if args.robot else "")
                             + (" --choose" if args.choose else "")
                             + f" --seed {args.seed}"))
        return 0
    if args.coverage:
        from eelhost.benchmarks.estimator_coverage import coverage_markdown, measure_coverage

        tank = args.tanks or "bundled"
        plant = None if tank == "bundled" else PLANTS.get(tank)
        if tank != "bundled" and plant is None:
            raise UserError(f"--coverage takes one tank in --tanks: bundled or a plant, got "
                            f"{tank!r}; known plants: {', '.join(sorted(PLANTS))}")
        motions = tuple(args.motions.split(","))
        if not motions or any(m not in ("straight", "turning") for m in motions) or len(
                set(motions)) < len(motions):
            raise UserError(f"--motions: straight, turning or straight,turning, got "
                            f"{args.motions!r}")
        cov = measure_coverage(args.coverage, args.seed, args.replicates,
                               say=lambda line: print(line, flush=True), plant=plant,
                               robot_file=args.robot, motions=motions)
        text = "# Estimation: interval coverage\n\n" + coverage_markdown(
            cov, f"eelbot estimate-bench --coverage {args.coverage} --seed {args.seed} "
            f"--replicates {args.replicates}" + (f" --tanks {tank}" if plant else "")
            + (f" --robot {args.robot}" if args.robot else "")
            + (f" --motions {args.motions}" if motions != ("straight",) else ""),
            "bundled noise" if plant is None else f"plant {tank}")
        print(text)
        if args.write:
            out = "docs/estimation_coverage.md" if args.write == WRITE_DEFAULT else args.write
            write_report(out, text)
            print(f"wrote {out}")
        return 0
    text = estimator_report(
        Path(args.work),
        seed=args.seed,
        ga_generations=args.ga_generations,
        ga=not args.skip_ga,
        progress=lambda line: print(line, flush=True),
        only=tuple(args.tanks.split(",")) if args.tanks else None,
        fit_current=args.fit_current,
        joint_models=args.joint_models,
        laws=args.laws,
        robot_file=args.robot,
    )
    if write_report(args.write, text):
        print(f"wrote {args.write}")  # the tables went to stdout as they were measured
    return 0
