"""``eelbot estimate``: fit the hydrodynamic coefficients to a dataset's training experiments."""

from __future__ import annotations

import argparse
from pathlib import Path

from eelhost.commands import COMMANDS
from eelhost.commands.common import add_fit_options, fit_settings
from eelhost.data.experiments import load_dataset
from eelhost.estimation.coefficients_file import write_coefficients
from eelhost.estimation.pipeline import fit_motion
from eelhost.files import check_output_folder
from eelhost.progress import Progress


@COMMANDS.add("estimate", "fit the robot file's fluid-law coefficients to a dataset")
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "estimate",
        help=COMMANDS.description("estimate"),
        description="Fit the coefficients to the training experiments (minimax of "
        "position + 5 x velocity error at 7 samples, the paper's protocol).",
    )
    p.add_argument("dataset", help="dataset folder (with manifest.toml)")
    p.add_argument(
        "--motion",
        choices=["straight", "turning", "both", "joint"],
        default="both",
        help="separate straight and turning fits (both, the paper's), one of them, or "
        "one joint set for the robot",
    )
    g = p.add_argument_group("Dask cluster (docs/cli.md, \"Security\": a cluster can run code here)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="spread the simulations over a Dask cluster: tls://host:8786 (with "
                   "certificates), or tcp:// on this machine")
    g.add_argument("--tls-ca-file", metavar="PEM",
                   help="certificate authority of the cluster's certificates (default: the Dask "
                   "config's distributed.comm.tls.ca-file)")
    g.add_argument("--tls-cert", metavar="PEM", help="this client's certificate (default: the "
                   "Dask config's distributed.comm.tls.client.cert)")
    g.add_argument("--tls-key", metavar="PEM", help="this client's private key, if not in "
                   "--tls-cert")
    g.add_argument("--insecure", action="store_true",
                   help="allow plain tcp:// to another machine (anyone who can reach the "
                   "scheduler can then run code here)")
    p.add_argument(
        "--out", default="out/estimate", help="folder for coefficients.json and checkpoints"
    )
    p.add_argument(
        "--allow-incomplete",
        action="store_true",
        help="use recordings that were never closed (killed runs); refused by default",
    )
    add_fit_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    check_output_folder(args.out)  # checkpoints and coefficients go there: said before the fit
    dataset = load_dataset(args.dataset, allow_incomplete=args.allow_incomplete)
    settings = fit_settings(args)
    motions = ("straight", "turning") if args.motion == "both" else (args.motion,)
    map_function = None
    if args.scheduler:
        from eelhost.estimation.cluster import TLSFiles, dask_map

        tls = TLSFiles(args.tls_ca_file, args.tls_cert, args.tls_key)
        map_function = dask_map(args.scheduler, tls=tls, insecure=args.insecure)
    fits = {}
    for motion in motions:
        total = settings.generations if settings.method == "ga" else None
        with Progress(f"{motion} ({settings.method})", total, "gen") as bar:

            def progress(gen: int, best: float, sims: int, bar: Progress = bar) -> None:
                bar.set_postfix(best=f"{best:.4g}", sims=sims)
                bar.set(gen)

            res, ev = fit_motion(
                dataset,
                motion,
                settings,
                Path(args.out),
                args.resume,
                progress,
                map_function=map_function,
            )
        fits[motion] = res
        print(
            f"{motion}: fitness {res.fitness:.4f}, {res.evaluations} candidates, "
            f"{res.simulations} simulations"
            + (f" (candidates: {res.search_evaluations} in the search, --budget "
               f"{settings.budget}; {res.evaluations - res.search_evaluations} in the polishes)"
               if res.search_evaluations is not None else "")
            + ", "
            + " ".join(f"{name} {value:.4g}" for name, value in res.space.as_dict(res.values).items())
            + (f" (ambient current {res.model.current_text()})" if res.space.current else "")
        )
    if map_function is not None:
        map_function.close()
    path = write_coefficients(Path(args.out) / "coefficients.json", fits, robot=dataset.robot)
    print(f"wrote {path}")
    return 0
