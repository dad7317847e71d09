"""The batched kernel on a Dask cluster against one machine: ``python -m eelhost.benchmarks.cluster_speed``.

A generation of the bundled dataset (``--candidates`` x its 4 straight training experiments,
:meth:`~eelhost.estimation.evaluate.Evaluator.fitness` with the batched kernel) is timed

- in this process, as eelbot runs without a cluster, with the kernel on one core (a one-core
  machine: the unit the cluster rows are compared with) and on all cores;
- on a local Dask cluster of one worker process, then of ``--workers`` processes, each worker
  standing for a machine of one core (one task at a time, the kernel on one thread), the
  generation cut into blocks of candidates
  (:func:`~eelhost.estimation.batch_backend.simulate_batch_spread`);
- on the cluster of ``--workers`` processes over TLS (a throwaway certificate), as a remote
  cluster is reached.

Each case is timed alone, the cases in alternation, ``--repeats`` times after a warm-up (which
loads each worker's kernel); the fitness values are checked equal to the in-process ones. A machine
of C cores can show the scale-out of up to C one-core workers; across machines each worker has its
own cores. ``--write`` puts the report in docs/benchmarks.md between its markers, keeping the rest
of the page.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from eelhost.machine import cpu_model, load_average

BEGIN = "<!-- cluster: begin (written by python -m eelhost.benchmarks.cluster_speed --write) -->"
END = "<!-- cluster: end -->"
ONE = "in process, 1 core"
SINGLE = "cluster, 1 worker x 1 core"
DATASET = Path(__file__).resolve().parents[3] / "datasets" / "paper_virtual_tank"


def _candidates(truth: np.ndarray, count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return truth * rng.uniform(0.7, 1.3, size=(count, truth.size))


class _Timed:
    """A task function that also returns the CPU time it took and the worker process's id."""

    def __init__(self, function: Callable) -> None:
        self.function = function

    def __call__(self, job: Any) -> tuple[Any, float, int]:
        start = time.process_time()
        out = self.function(job)
        return out, time.process_time() - start, os.getpid()


class _TimedMap:
    """A cluster map that records each call's CPU time per worker process.

    Load-independent: what each worker computed, not how long it waited.
    """

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.blocks = inner.blocks
        self.per_call: list[dict[int, float]] = []
        self.tasks: list[list[float]] = []  # each call's blocks' CPU times

    def share(self, value: Any) -> Any:
        return self.inner.share(value)

    def __call__(self, function: Callable, jobs: Any) -> list[Any]:
        results = self.inner(_Timed(function), jobs)
        per: dict[int, float] = {}
        for _, cpu, pid in results:
            per[pid] = per.get(pid, 0.0) + cpu
        self.per_call.append(per)
        self.tasks.append([cpu for _, cpu, _ in results])
        return [r for r, _, _ in results]


def _time(fitness: Callable[[np.ndarray], np.ndarray], cands: np.ndarray) -> tuple[float, np.ndarray]:
    start = time.perf_counter()
    f = fitness(cands)
    return time.perf_counter() - start, f


def measure(workers: int = 2, candidates: int = 150, repeats: int = 5, seed: int = 0) -> dict:
    """Time one generation on one machine and on local clusters; return the figures.

    Parameters
    ----------
    workers : int
        Worker processes of the larger cluster.
    candidates : int
        Candidates per generation (150: the paper's GA).
    repeats : int
        Timed generations per case.
    seed : int
        Seed of the candidates.

    Returns
    -------
    dict
        Per case: the times (s); and the setting.
    """
    import distributed
    import numba

    from eelhost.data.experiments import load_dataset
    from eelhost.estimation.cluster import TLSFiles, dask_map
    from eelhost.estimation.evaluate import Evaluator

    ds = load_dataset(DATASET)
    exps = ds.train["straight"]
    truth = ds.truth["straight"].as_array()
    cands = _candidates(truth, candidates, seed)
    local = Evaluator(ds.robot, exps, backend="batch", space=None)
    cores = os.cpu_count() or 1
    reference = local.fitness(cands)  # warm-up: loads the kernel here
    sec = distributed.Security.temporary()
    folder = Path(tempfile.mkdtemp(prefix="eelbot-tls-"))
    (folder / "cert.pem").write_text(sec.tls_client_cert)
    (folder / "key.pem").write_text(sec.tls_client_key)
    files = TLSFiles(str(folder / "cert.pem"), str(folder / "cert.pem"), str(folder / "key.pem"))
    clusters = {
        SINGLE: distributed.LocalCluster(
            n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0",
            silence_logs=40, env={"NUMBA_NUM_THREADS": "1"}),
        f"cluster, {workers} workers x 1 core": distributed.LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
            silence_logs=40, env={"NUMBA_NUM_THREADS": "1"}),
        f"cluster, {workers} workers x 1 core, TLS": distributed.LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
            silence_logs=40, protocol="tls://", security=sec, env={"NUMBA_NUM_THREADS": "1"}),
    }
    def one_core(c: np.ndarray) -> np.ndarray:
        previous = numba.get_num_threads()
        numba.set_num_threads(1)  # this thread's kernel calls only
        try:
            return local.fitness(c)
        finally:
            numba.set_num_threads(previous)

    cases: dict[str, Callable[[np.ndarray], np.ndarray]] = {
        ONE: one_core, f"in process, {cores} cores": local.fitness}
    maps = []
    timed: dict[str, _TimedMap] = {}
    try:
        for name, lab in clusters.items():
            spread = dask_map(lab.scheduler_address, tls=files if "TLS" in name else None)
            maps.append(spread)
            timed[name] = _TimedMap(spread)
            ev = Evaluator(ds.robot, exps, backend="batch", map_function=timed[name])
            if not np.array_equal(ev.fitness(cands), reference):  # warm-up, and the check
                raise RuntimeError(f"{name}: fitness differs from one machine's")
            cases[name] = ev.fitness
        times: dict[str, list[float]] = {name: [] for name in cases}
        cpu: dict[str, list[tuple[float, float]]] = {name: [] for name in cases}  # all, busiest
        for _ in range(repeats):
            for name, fitness in cases.items():
                start = time.process_time()
                dt, f = _time(fitness, cands)
                own = time.process_time() - start
                if not np.array_equal(f, reference):
                    raise RuntimeError(f"{name}: fitness differs from one machine's")
                times[name].append(dt)
                if name in timed:
                    per = timed[name].per_call[-1]
                    cpu[name].append((sum(per.values()), max(per.values())))
                else:
                    cpu[name].append((own, own))
    finally:
        blocks = {name: t.tasks[1:] for name, t in timed.items()}  # the warm-up's left out
        for spread in maps:
            spread.close()
        for lab in clusters.values():
            lab.close()
    return {"times": times, "cpu": cpu, "blocks": blocks, "workers": workers, "candidates": candidates,
            "experiments": len(exps), "cores": cores, "repeats": repeats,
            "runs": candidates * len(exps), "load": load_average(), "processor": cpu_model()}


def report(m: dict, note: str) -> str:
    """The markdown block of the figures."""
    times = m["times"]
    med = {name: statistics.median(t) for name, t in times.items()}
    best = {name: min(t) for name, t in times.items()}
    w = m["workers"]
    lines = [
        BEGIN,
        "## 5. The batched kernel on a Dask cluster",
        "",
        f"`python -m eelhost.benchmarks.cluster_speed --workers {w} --candidates "
        f"{m['candidates']} --repeats {m['repeats']} --write` on "
        f"{time.strftime('%Y-%m-%d %H:%M')} ({m['processor']}, {m['cores']} cores; load average "
        f"before: {m['load']}). {note}",
        "",
        f"A generation of {m['candidates']} candidates x {m['experiments']} straight training "
        f"experiments of the bundled dataset = {m['runs']} closed-loop runs "
        "(`Evaluator.fitness`, batched backend). Each case timed alone, the cases in alternation, "
        f"{m['repeats']} times after a warm-up; the fitness values identical in every case. A "
        "cluster worker stands for a machine of one core (its kernel on one thread); the speed-up "
        "is over the same generation in one process on one core.",
        "",
        "| case | median s | fastest s | slowest s | speed-up (medians) | speed-up (fastest) "
        "| CPU s, all workers | CPU s, busiest worker | CPU bound of the speed-up |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    cpu = {name: np.median(np.array(v), axis=0) for name, v in m["cpu"].items()}
    for name, t in times.items():
        busiest = (f"{cpu[name][1]:.2f} | {cpu[SINGLE][0] / cpu[name][1]:.2f} x"
                   if name.startswith("cluster") else "- | -")
        lines.append(f"| {name} | {med[name]:.2f} | {best[name]:.2f} | {max(t):.2f} | "
                     f"{med[ONE] / med[name]:.2f} x | {best[ONE] / best[name]:.2f} x | "
                     f"{cpu[name][0]:.2f} | {busiest} |")
    lines += [
        "",
        f"The rows '{w} workers' against '1 worker' are the scale-out: the generation's blocks "
        f"on {w} worker processes instead of one. Here the {w} workers share this machine's "
        f"{m['cores']} cores with each other and with the other load, so the ratio is at most "
        f"{min(w, m['cores'])} and the fastest repeats are the better estimate of it; on {w} "
        "machines each worker has its own cores, and the kernel on each uses all of them. The "
        "cluster rows against the in-process row on one core show the cluster's own cost "
        "(sending the candidates, the blocks' separate tails); TLS adds the encryption.",
        "",
        "The CPU columns depend much less on the load: the processor time the worker processes "
        "spent in their blocks (medians over the repeats; in process: this whole process's, its "
        "Python work around the kernel included). 'CPU bound' is the 1-worker cluster's CPU time "
        "over the busiest worker's: the speed-up on as many one-core machines as workers if "
        "sending the work cost nothing, an upper bound set by how the blocks were shared out. "
        "A block goes to whichever worker is free (2 blocks per worker and generation), so a "
        "worker the machine starves of CPU takes fewer blocks and the other more.",
        "",
    ]
    name = f"cluster, {w} workers x 1 core"
    calls = m["blocks"][name]
    largest = [max(call) / float(np.mean(call)) for call in calls]
    mean_block = float(np.median([np.mean(call) for call in calls]))
    lines += [
        f"How evenly the blocks share the work ({name}): {len(calls[0])} blocks a generation of "
        f"{m['candidates'] // len(calls[0])} candidates each, {mean_block:.2f} CPU s each (median "
        f"over the generations); the largest block of a generation took "
        f"{np.median(largest):.2f} x the blocks' mean (median; at worst {max(largest):.2f} x). "
        f"With two blocks per worker on {w} idle one-core machines the busiest would compute "
        "about twice the largest block: a bound of "
        f"{cpu[SINGLE][0] / (2 * mean_block * float(np.median(largest))):.2f} x over one such "
        "machine, less the cost of sending the work.",
        END,
    ]
    return "\n".join(lines)


def write_block(path: Path, block: str) -> None:
    """Put ``block`` between its markers in ``path`` (appended the first time)."""
    from eelhost.files import replace_marked_block

    replace_marked_block(path, BEGIN, END, block)


def keep_block(path: str | Path, text: str) -> str:
    """``text`` (a new page) with the cluster block of the page at ``path`` kept at its end.

    ``eelbot bench --write`` rewrites docs/benchmarks.md whole; this block is measured by another
    command, so the page keeps it.
    """
    old = Path(path).read_text() if Path(path).exists() else ""
    if BEGIN not in old or END not in old or BEGIN in text:
        return text
    block = BEGIN + old.split(BEGIN, 1)[1].split(END, 1)[0] + END
    return text.rstrip("\n") + "\n\n" + block + "\n"


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print (``--write``: also write) its report."""
    p = argparse.ArgumentParser(prog="python -m eelhost.benchmarks.cluster_speed",
                                description=__doc__.splitlines()[0])
    p.add_argument("--workers", type=int, default=2, help="worker processes of the cluster")
    p.add_argument("--candidates", type=int, default=150, help="candidates per generation")
    p.add_argument("--repeats", type=int, default=5, help="timed generations per case")
    p.add_argument("--note", default="", help="a note on the machine's state (load, sharing)")
    p.add_argument("--write", nargs="?", const="docs/benchmarks.md", metavar="FILE",
                   help="also write the block into FILE (bare: docs/benchmarks.md)")
    args = p.parse_args(argv)
    block = report(measure(args.workers, args.candidates, args.repeats), args.note)
    print(block)
    if args.write:
        write_block(Path(args.write), block)
        print(f"wrote {args.write}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
