"""Machine-code view of the batched kernel's stage: its lane loops and llvm-mca's cycles.

For each vector loop of the generated stage: its size, its stack accesses (register spills) and
llvm-mca's estimate of its cycles per iteration (one iteration = one AVX2 vector of 4 runs).

Usage (from the repo root, after ``bash scripts/setup.sh``)::

    .venv/bin/python tools/kernel_loops.py [--links 6] [--lanes 16] [--cpu znver3]
        [--stage c|numba]

``--stage`` picks whose machine code: the C compiler's (the default when there is one, as in
``eelsim.batch.stage_backend``) or numba's.

Needs ``llvm-mca`` on the PATH (Debian/Ubuntu package ``llvm``); without it the loops are still
listed. This is how the work on the kernel was steered (docs/kernel_history.md): llvm-mca's
cycles for the loops of a stage came within about 10 % of the measured time of a stage on this
machine's Zen 3 cores, and told a latency-bound loop (cycles well above the block throughput)
from a throughput-bound one.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numba
import numpy as np

from eelsim import batch
from eelsim.batch import c_stage, codegen, loading

_LABEL = re.compile(r"^(\.?[\w.$]+):")
_JUMP = re.compile(r"^\s+j\w+\s+(\.?[\w.$]+)")


def stage_assembly(n_links: int, lanes: int, stage: str) -> str:
    """Assembly of the generated stage, the C compiler's or numba's.

    Numba's is compiled afresh (numba does not show cached code).
    """
    if stage == "c":
        source = codegen.generate_stage_source(codegen.make_layout(n_links, lanes))
        library, _ = c_stage.build(source, loading.C_FUNCTIONS, batch.kernel_cache_dir())
        flags = [f for f in c_stage.C_FLAGS if f not in ("-shared", "-fPIC")]
        return subprocess.run([c_stage.find_compiler() or "cc", *flags, "-S", "-o", "-",
                               str(library.with_suffix(".c"))],
                              capture_output=True, text=True, check=True).stdout
    k = batch.kernel_module(n_links, lanes, "numba")
    fresh = numba.njit(fastmath=k._FASTMATH, error_model="numpy", boundscheck=False)(
        k._stage.py_func
    )
    work = np.zeros((k.WORK_ROWS + k.OUT_ROWS) * lanes)
    fresh(work, 0.0, 0.0, 1.0, True, False, 1e-3, True, True, False)
    return fresh.inspect_asm(fresh.signatures[0])


def vector_loops(asm: str) -> list[list[str]]:
    """Bodies of the loops (backward jumps) that are mostly 256- or 512-bit instructions."""
    lines = asm.splitlines()
    labels = {m.group(1): i for i, text in enumerate(lines) if (m := _LABEL.match(text))}
    loops, seen = [], set()
    for i, text in enumerate(lines):
        m = _JUMP.match(text)
        if not m or m.group(1) not in labels or labels[m.group(1)] >= i:
            continue
        start = labels[m.group(1)]
        body = [t for t in lines[start + 1 : i] if t.startswith("\t") and not t.startswith("\t.")]
        vector = sum("ymm" in t or "zmm" in t for t in body)  # AVX2 or AVX-512 registers
        if start in seen or vector < 0.5 * max(1, len(body)):
            continue
        seen.add(start)
        loops.append(body)
    return loops


def mca(body: list[str], cpu: str) -> tuple[float, float] | None:
    """(cycles per iteration, block reciprocal throughput) from llvm-mca, or None without it."""
    tool = shutil.which("llvm-mca")
    if tool is None:
        return None
    with tempfile.NamedTemporaryFile("w", suffix=".s", delete=False) as f:
        f.write("\n".join(body) + "\n")
    report = subprocess.run([tool, f"-mcpu={cpu}", "-iterations=50", f.name],
                            capture_output=True, text=True, check=True).stdout
    Path(f.name).unlink()
    total = re.search(r"Total Cycles:\s+(\d+)", report)
    throughput = re.search(r"Block RThroughput:\s+([\d.]+)", report)
    if total is None or throughput is None:
        raise RuntimeError(f"{tool} printed no cycle count for {cpu}:\n{report}")
    return int(total.group(1)) / 50, float(throughput.group(1))


def main() -> int:
    """Print one line per vector loop of the stage."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--links", type=int, default=6)
    parser.add_argument("--lanes", type=int, default=batch.DEFAULT_LANES)
    parser.add_argument("--cpu", default="znver3",
                        help="llvm-mca -mcpu (default znver3; code built for AVX-512 needs a "
                        "model that has it, e.g. skylake-avx512)")
    parser.add_argument("--stage", choices=("c", "numba"), default=None,
                        help="whose code: the C compiler's or numba's (default: as the kernel)")
    args = parser.parse_args()
    stage = batch.stage_backend(args.stage)
    loops = vector_loops(stage_assembly(args.links, args.lanes, stage))
    if shutil.which("llvm-mca") is None:
        print("llvm-mca not found (apt install llvm): listing the loops only", file=sys.stderr)
    total = 0.0
    for number, body in enumerate(loops, 1):
        spills = sum("(%rsp)" in t for t in body)
        line = f"loop {number}: {len(body)} instructions, {spills} stack accesses"
        estimate = mca(body, args.cpu)
        if estimate:
            total += estimate[0]
            line += f", {estimate[0]:.0f} cycles per iteration (throughput bound {estimate[1]:.0f})"
        print(line)
    if total:
        print(f"sum over the loops: {total:.0f} cycles per vector of 4 runs "
              "(each stage runs some of them: rotated or full angles, stages 1-3 or the last)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
