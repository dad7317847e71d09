"""``eelbot validate``: errors of fitted coefficients on a dataset's test experiments and paths."""

from __future__ import annotations

import argparse
from pathlib import Path

from eelhost.commands import COMMANDS
from eelhost.commands.common import NON_NEGATIVE, add_backend_option
from eelhost.data.experiments import load_dataset
from eelhost.estimation.coefficients_file import CoefficientsError, read_coefficients
from eelhost.estimation.runs import ALIGN_S
from eelhost.estimation.validate import table_csv, table_markdown, validate
from eelhost.files import atomic_write, check_output_folder
from eelhost.progress import phase


@COMMANDS.add("validate", "validate coefficients on held-out experiments")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "validate",
        help=COMMANDS.description("validate"),
        description="E_x and E_v (paper's mean of norms and true RMS, BL and BL/s) for "
        "every test experiment and path, as tables (markdown, CSV) and figures.",
    )
    p.add_argument("coefficients", help="coefficients.json from estimate, or the robot's coefficients as numbers (C_f,C_d,C_a,C_m)")
    p.add_argument("dataset", help="dataset folder")
    p.add_argument("--out", default="out/validate", help="folder for tables and figures")
    add_backend_option(p)
    p.add_argument(
        "--align",
        type=NON_NEGATIVE,
        default=None,
        metavar="SECONDS",
        help="also report each experiment at the clock offset of its recording that fits best, "
        "searched within +-SECONDS (default: the time-stamp uncertainty each recording declares, "
        f"camera.timestamp_jitter_s; {ALIGN_S:g} s where it declares none)",
    )
    p.add_argument(
        "--allow-other-robot",
        action="store_true",
        help="use a coefficients.json fitted on another robot than the dataset's (refused by "
        "default: its name, N or geometry differ)",
    )
    p.add_argument(
        "--allow-incomplete",
        action="store_true",
        help="use recordings that were never closed (killed runs); refused by default",
    )
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    coefficients = Path(args.coefficients)
    if coefficients.suffix == ".json" and not coefficients.is_file():
        # said before the dataset is read: reading the file needs the dataset's robot
        raise CoefficientsError(f"{coefficients}: cannot read coefficients: no such file")
    check_output_folder(args.out)  # a folder that cannot be written is said before the runs
    dataset = load_dataset(args.dataset, allow_incomplete=args.allow_incomplete)
    fitted = read_coefficients(args.coefficients, dataset.robot, args.allow_other_robot)
    tests = dataset.held_out
    for name, model in fitted.items():
        if model.current_text() is not None:
            print(f"{name}: simulated in the fitted ambient current, {model.current_text()}, "
                  "added to each experiment's declared current")
    with phase(f"validate: {len(tests)} held-out experiments in the twin"):
        runs = validate(dataset.robot, fitted, tests, backend=args.backend, align_s=args.align)
    with phase("validate: tables and figures"):
        _write_tables_and_figures(runs, Path(args.out))
    print(table_markdown([r.row for r in runs]))
    print(f"wrote {args.out}/table4.md, table4.csv and figures")
    return 0


def _write_tables_and_figures(runs: list, out: Path) -> None:
    md = table_markdown([r.row for r in runs])
    atomic_write(out / "table4.md", md + "\n")
    atomic_write(out / "table4.csv", table_csv([r.row for r in runs]))
    from eelhost.estimation.figures import plot_validation  # matplotlib: slow import

    plot_validation(runs, out)
