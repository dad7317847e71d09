"""``eelbot report``: the main job: fit, validate and report on a dataset (default: bundled)."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from eelhost.commands import COMMANDS
from eelhost.commands.common import add_fit_options, fit_settings, number, registered_names
from eelhost.commands.joint_models_option import add_joint_models_option
from eelhost.data.experiments import BUNDLED_DATASET, load_dataset
from eelhost.data.virtual_tank import generate_dataset
from eelhost.errors import UserError
from eelhost.estimation.report import run_report
from eelhost.estimation.selection import default_laws
from eelhost.files import check_output_folder
from eelhost.progress import Progress
from eelsim.fluid import FLUID_LAWS


@COMMANDS.add("report", "fit straight and turning, validate, write a report folder")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "report",
        help=COMMANDS.description("report"),
        description="The whole estimation chain. Without DATASET it uses the bundled "
        "virtual-tank dataset (truth = the paper's table 3).",
    )
    p.add_argument(
        "dataset", nargs="?", help="dataset folder (default: the bundled virtual-tank dataset)"
    )
    p.add_argument("--out", default="out/report", help="report folder")
    p.add_argument("--joint", action="store_true", help="also fit one joint set for the robot")
    p.add_argument(
        "--bootstrap", type=number(int, minimum=0), default=8, help="bootstrap refits per fit (0: none)"
    )
    p.add_argument("--no-compare", action="store_true",
                   help="skip the cross-validated comparison of candidate models (the robot "
                   "file's model is fitted)")
    p.add_argument("--laws", type=law_names, metavar="LAW,...",
                   help="fluid laws the comparison tries (default: "
                   + ",".join(default_laws()) + ")")
    add_joint_models_option(p)
    p.add_argument("--keep-model", action="store_true",
                   help="report the robot file's model even when the comparison recommends "
                   "another (default: fit the recommended model and report its fits)")
    p.add_argument("--jobs", type=number(int, minimum=1), default=None, metavar="N",
                   help="worker processes of the comparison's independent fits and of the "
                   "chosen model's fits and bootstraps, one per motion (default: one per core; "
                   "1: none). The results are the same for every N")
    add_fit_options(p)
    p.set_defaults(run=run)


law_names = registered_names(FLUID_LAWS, "fluid laws")
"""``--laws``: comma-separated names of registered fluid laws."""


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    check_output_folder(args.out)  # the report's folder: said before minutes of fitting
    folder = Path(args.dataset) if args.dataset else BUNDLED_DATASET
    if args.dataset is None and not (folder / "manifest.toml").exists():
        folder = Path("out/dataset")
        print(
            f"no bundled dataset here; generating the default virtual-tank dataset in {folder} ..."
        )
        with Progress("virtual tank", 34, "experiment") as tank:
            generate_dataset(folder, seed=args.seed, progress=lambda d, _t: tank.set(d))
    dataset = load_dataset(folder)
    # the paper's separate fits, of the motion types the dataset has training experiments for
    motions = tuple(m for m in ("straight", "turning") if dataset.train.get(m))
    if not motions:
        raise UserError(f"{folder}: the manifest names no training experiments "
                        "(straight or turning) to fit")
    motions += ("joint",) if args.joint else ()
    settings = replace(fit_settings(args), jobs=args.jobs)

    bars: list[Progress] = []

    def say(text: str) -> None:  # a fit's summary comes after its progress has ended
        for bar in bars:
            bar.close()
        print(text)

    def factory(motion: str):
        bar = Progress(f"fit {motion}", unit="gen")
        bars.append(bar)

        def progress(gen: int, best: float, sims: int) -> None:
            bar.set_postfix(best=f"{best:.4g}", sims=sims)
            bar.set(gen)

        return progress

    run_report(
        dataset,
        args.out,
        motions,
        settings,
        args.bootstrap,
        args.resume,
        compare_models=not args.no_compare,
        adopt_recommended=not args.keep_model,
        laws=args.laws,
        joint_models=args.joint_models,
        say=say,
        progress_factory=factory,
    )
    return 0
