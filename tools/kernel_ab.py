"""Paired A/B of the batched kernel: a git revision against the working tree, round by round.

Why paired: this VM's speed swings by up to a factor of two from minute to minute (contention for
the core's execution units; the clock stays at 3.15 GHz), so runs minutes apart cannot settle a
5 % question. Here both kernels run the GA generation of ``eelbot bench`` in alternation, many
rounds, and the verdict is the median of the per-round time ratios (calibration: two copies of the
same code give 1.00 +- 0.01). See docs/kernel_history.md for what it decided.

Each version runs in its own worker process, started once: the revision's ``sim/`` folder is
exported with ``git archive`` to a temporary folder and put first on the worker's ``PYTHONPATH``,
so that any two versions compare, however differently their ``eelsim.batch`` is laid out inside,
as long as both have ``eelsim.batch.BatchSpec.build`` and ``run_spec``. Each version builds the
same batch with its own code; the final states of the two are compared (they agree to rounding
when only the speed changed). Only one worker runs at a time.

Usage (from the repo root, after ``bash scripts/setup.sh``)::

    .venv/bin/python tools/kernel_ab.py [--base HEAD] [--rounds 15] [--threads 1]
        [--stage c|numba] [--base-stage c|numba] [--clock wall|cpu] [--robot servo_robot.toml]

``--stage`` compiles the generated stage of both versions that way (default: as
``eelsim.batch.stage_backend`` chooses); ``--base-stage`` another way for the base, e.g.
``--base HEAD --base-stage numba --stage c`` weighs the C stage against numba's on the same code.
``--clock cpu`` times each generation by the worker's CPU time instead of the wall clock: on a
machine loaded beyond its cores the wall clock mostly measures the wait for a core (the CPU time
still moves with the contention for caches and execution units). ``--robot`` runs another robot
file (``servo_robot.toml``: the bundled servo joints; default: the
bundled paper robot, PD joints).

The first call compiles the base's kernel (about a minute; cached afterwards in the export,
which is kept in the temporary folder under the revision's commit hash).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from eelsim import batch

_REPO = Path(__file__).resolve().parents[1]

# What a worker runs: build the GA generation with its own eelsim, run it once (compiling or
# loading the kernel) and save its final states, then time one run per line read from stdin.
_WORKER = r"""
import json, sys, time
import numpy as np
from eelsim import batch
from eelsim.closed_loop import LoopOptions
from eelsim.robot import load_robot
from eelsim.scenario import TRAINING_CORNERS, grid_scenario

runs, steps, threads, out = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
robot = load_robot(sys.argv[5] or None)
opts = LoopOptions(stop_at_goal=False)
corners = [grid_scenario("straight", a, w).model_copy(
    update={"duration_s": steps * opts.timing.dt_s}) for a, w in TRAINING_CORNERS]
candidates = robot.hydrodynamics.as_array() * np.random.default_rng(0).uniform(0.5, 1.5, (runs, 4))
spec = batch.BatchSpec.build(robot, [corners[i % 4] for i in range(runs)], candidates, opts, 0)
res = batch.run_spec(spec, threads=threads)
np.save(out, res.final_state)
print(json.dumps({"ready": True, "codes": res.reason_code.tolist()}), flush=True)
for _ in sys.stdin:
    start, start_cpu = time.perf_counter(), time.process_time()
    res = batch.run_spec(spec, threads=threads)
    wall, cpu = time.perf_counter() - start, time.process_time() - start_cpu
    print(json.dumps({"wall": wall, "cpu": cpu, "steps": float(res.final_step.sum())}),
          flush=True)
"""


def export_revision(revision: str, where: Path) -> Path:
    """The ``sim/`` folder of ``revision``, exported (once per commit) under ``where``.

    Parameters
    ----------
    revision : str
        A git revision of this repository.
    where : Path
        Folder for the exports.

    Returns
    -------
    Path
        The folder to put on ``PYTHONPATH`` (it holds the package ``eelsim``).
    """
    commit = subprocess.run(["git", "rev-parse", revision], cwd=_REPO, check=True,
                            capture_output=True, text=True).stdout.strip()
    folder = where / commit[:12]
    if not (folder / "sim" / "eelsim").is_dir():
        folder.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "archive", commit, "sim"], cwd=_REPO, check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return folder / "sim"


class Worker:
    """One version of the kernel in its own process, timing a generation when asked.

    Parameters
    ----------
    sim_folder : Path
        The folder holding that version's ``eelsim``.
    stage : str
        How its generated stage is compiled (``$EELSIM_STAGE``).
    runs, steps, threads : int
        The generation: runs, steps per run, threads.
    states_file : Path
        Where the worker saves its first run's final states.
    robot : str
        Robot file for the generation (empty: the bundled paper robot).
    """

    def __init__(self, sim_folder: Path, stage: str, runs: int, steps: int, threads: int,
                 states_file: Path, robot: str = "") -> None:
        env = dict(os.environ, PYTHONPATH=str(sim_folder), EELSIM_STAGE=stage)
        env.pop("EELSIM_KERNEL_CACHE", None)  # each version keeps its kernels beside its code
        self.process = subprocess.Popen(
            [sys.executable, "-c", _WORKER, str(runs), str(steps), str(threads), str(states_file),
             robot],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
        self.ready = self._answer()

    def _answer(self) -> dict:
        assert self.process.stdout is not None
        line = self.process.stdout.readline()
        if not line:
            raise SystemExit(f"a kernel worker ended early (exit code {self.process.wait()})")
        return json.loads(line)

    def time_once(self, clock: str = "wall") -> tuple[float, float]:
        """Run the generation once; return (seconds on ``clock``, RK4 steps)."""
        assert self.process.stdin is not None
        self.process.stdin.write("go\n")
        self.process.stdin.flush()
        answer = self._answer()
        return answer[clock], answer["steps"]

    def close(self) -> None:
        """End the worker."""
        if self.process.stdin is not None:
            self.process.stdin.close()
        self.process.wait()


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
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                        help="time on the wall clock or the worker's CPU time (a loaded machine)")
    parser.add_argument("--robot", default="",
                        help="robot file (servo_robot.toml: the bundled servo joints)")
    args = parser.parse_args()
    stage = batch.stage_backend(args.stage)
    base_stage = args.base_stage or stage
    where = Path(tempfile.gettempdir()) / "eelsim_kernel_ab"
    names = [f"{args.base} ({base_stage} stage)", f"working tree ({stage} stage)"]
    folders = [export_revision(args.base, where), _REPO / "sim"]
    scratch = Path(tempfile.mkdtemp(prefix="eelsim_kernel_ab_"))
    files = [scratch / f"final_{i}.npy" for i in range(2)]
    workers = [Worker(folder, st, args.runs, args.steps, args.threads, file, args.robot)
               for folder, st, file in zip(folders, (base_stage, stage), files, strict=True)]
    try:
        finals = [np.load(file) for file in files]
        gap = float(np.nanmax(np.abs(finals[1] - finals[0])))
        same_flags = workers[0].ready["codes"] == workers[1].ready["codes"]
        print(f"final states differ by at most {gap:.1e}; same flags: {same_flags}")
        walls = np.zeros((args.rounds, 2))
        steps = 0.0
        for i in range(args.rounds):
            for j in ((0, 1) if i % 2 == 0 else (1, 0)):
                walls[i, j], steps = workers[j].time_once(args.clock)
    finally:
        for worker in workers:
            worker.close()
        shutil.rmtree(scratch, ignore_errors=True)
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
