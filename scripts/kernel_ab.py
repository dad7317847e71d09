"""Paired A/B of the batched kernel: a git revision against the working tree, in one process.

Why paired: this VM's speed swings by up to a factor of two from minute to minute (contention for
the core's execution units; the clock stays at 3.15 GHz), so runs in separate processes, or
minutes apart, cannot settle a 5 % question. Here both kernels run the GA generation of
``eelbot bench`` in alternation, many rounds, and the verdict is the median of the per-round
time ratios (calibration: two copies of the same code give 1.00 +- 0.01). See
docs/kernel_history.md for what it decided.

Usage (from the repo root, after ``bash scripts/setup.sh``)::

    .venv/bin/python scripts/kernel_ab.py [--base HEAD] [--rounds 15] [--threads 1]
        [--stage c|numba] [--base-stage c|numba]

``--stage`` compiles the generated stage of both versions that way (default: as
``eelsim.batch.stage_backend`` chooses); ``--base-stage`` another way for the base, e.g.
``--base HEAD --base-stage numba --stage c`` weighs the C stage against numba's on the same code.

The first call compiles both kernels (about a minute each; cached afterwards beside the
package's own kernel, ``eelsim.batch.kernel_cache_dir``). The two versions must lay out the per-run parameter rows
(``work`` rows) alike, since the batch is built once, by the working tree's ``eelsim.batch``.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType

import numpy as np

from eelhost.commands.bench import TRAINING_CORNERS
from eelhost.commands.common import robot_and_coefficients
from eelsim import batch
from eelsim.closed_loop import LoopOptions
from eelsim.scenario import grid_scenario

_REPO = Path(__file__).resolve().parents[1]
_TEMPLATE = "sim/eelsim/_batch_kernel.py"
_GENERATOR = "sim/eelsim/_batch_codegen.py"


def _text_at(revision: str | None, path: str) -> str:
    """The file's text at ``revision`` (None: the working tree)."""
    if revision is None:
        return (_REPO / path).read_text()
    return subprocess.run(["git", "show", f"{revision}:{path}"], cwd=_REPO, check=True,
                          capture_output=True, text=True).stdout


def import_path(path: Path, name: str) -> ModuleType:
    """Import the Python file ``path`` as module ``name`` (registered, as dataclasses need)."""
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def kernel_at(revision: str | None, n_links: int, lanes: int, where: Path,
              stage: str) -> ModuleType:
    """Build and import the kernel module of ``revision`` (None: the working tree).

    Parameters
    ----------
    revision : str or None
        A git revision of this repository.
    n_links, lanes : int
        The kernel's N and block size.
    where : Path
        Directory for the revision's generator module.
    stage : str
        ``"c"`` or ``"numba"``: how the generated stage is compiled.

    Returns
    -------
    module
        With ``run_blocks`` and the row constants, as ``eelsim.batch.kernel_module`` returns.
    """
    generator_text = _text_at(revision, _GENERATOR)
    template = _text_at(revision, _TEMPLATE)
    key = hashlib.sha1((generator_text + template).encode()).hexdigest()[:12]
    path = where / f"gen_{key}.py"
    if not path.exists() or path.read_text() != generator_text:
        path.write_text(generator_text)
    generator = import_path(path, f"kernel_ab_gen_{key}")
    if generator.make_layout(n_links, lanes).work != batch._batch_codegen.make_layout(
            n_links, lanes).work:
        raise SystemExit(f"{revision or 'working tree'} lays out the work rows differently from "
                         "the working tree's eelsim.batch; this comparison cannot build one batch "
                         "for both")
    source = batch._kernel_source(n_links, lanes, template=template, generator=generator,
                                  stage=stage)
    suffix = "_c" if stage == "c" else ""
    return batch.load_kernel_source(f"kernel_ab_{key}_n{n_links}_l{lanes}{suffix}", source)


def main() -> int:
    """Run the comparison and print one line per version."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default="HEAD", help="git revision to compare against")
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--runs", type=int, default=600)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--stage", choices=("c", "numba"), default=None)
    parser.add_argument("--base-stage", choices=("c", "numba"), default=None)
    args = parser.parse_args()
    stage = batch.stage_backend(args.stage)
    base_stage = args.base_stage or stage

    robot, coeffs = robot_and_coefficients(argparse.Namespace(robot=None, coefficients=None))
    opts = LoopOptions(stop_at_goal=False)
    corners = [grid_scenario("straight", a, w).model_copy(
        update={"duration_s": args.steps * opts.timing.dt_s}) for a, w in TRAINING_CORNERS]
    candidates = coeffs.as_array() * np.random.default_rng(0).uniform(0.5, 1.5, (args.runs, 4))
    spec = batch.BatchSpec.build(robot, [corners[i % 4] for i in range(args.runs)],
                                 candidates, opts, 0)
    lanes = batch.DEFAULT_LANES
    where = Path(tempfile.gettempdir()) / "eelsim_kernel_ab"
    where.mkdir(exist_ok=True)
    names = [f"{args.base} ({base_stage} stage)", f"working tree ({stage} stage)"]
    modules = [kernel_at(args.base, spec.n_links, lanes, where, base_stage),
               kernel_at(None, spec.n_links, lanes, where, stage)]
    results = [batch.run_spec(spec, threads=args.threads, kernel=module)  # compiles on first use
               for module in modules]
    gap = float(np.nanmax(np.abs(results[1].final_state - results[0].final_state)))
    same_flags = np.array_equal(results[0].reason_code, results[1].reason_code)
    print(f"final states differ by at most {gap:.1e}; same flags: {same_flags}")

    walls = np.zeros((args.rounds, 2))
    for i in range(args.rounds):
        for j in ((0, 1) if i % 2 == 0 else (1, 0)):
            start = time.perf_counter()
            res = batch.run_spec(spec, threads=args.threads, kernel=modules[j])
            walls[i, j] = time.perf_counter() - start
    steps = float(res.final_step.sum())
    ratio = walls[:, 1] / walls[:, 0]
    for j, name in enumerate(names):
        best, median = walls[:, j].min(), float(np.median(walls[:, j]))
        print(f"{name}: best {args.threads * best / steps * 1e9:.0f} ns per step and core, "
              f"median {args.threads * median / steps * 1e9:.0f}")
    q1, q2, q3 = np.percentile(ratio, [25, 50, 75])
    print(f"working tree / {args.base}: median time ratio {q2:.3f} (quartiles {q1:.3f}-{q3:.3f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
