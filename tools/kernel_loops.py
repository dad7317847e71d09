"""Machine-code view of the batched kernel's stage: its lane loops and llvm-mca's cycles.

For each lane loop of the generated stage: its size, its stack accesses (register spills) and
llvm-mca's estimate of its cycles per iteration (one iteration = one vector of runs: 4 with
AVX2, 8 with AVX-512).

Usage (from the repo root, after ``bash scripts/setup.sh``)::

    .venv/bin/python tools/kernel_loops.py [--links 6] [--lanes 16] [--cpu CPU]
        [--stage c|numba] [--joints pd|servo]

``--stage`` picks whose machine code: the C compiler's (the default when there is one, as in
``eelsim.batch.stage_backend``) or numba's. With the C compiler's, every loop is named by the
title the generator gives it (a marker is put before each loop in the C text, and the machine
code between two markers is that loop's); numba's code lists its vector loops by number.
``--joints`` picks the joint model whose stage is generated (PD: the articulated-body
recursion; servo: the prescribed-shape balance). ``--cpu`` is llvm-mca's processor model
(default: skylake-avx512 when this machine has AVX-512, else znver3).

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
from eelsim.batch import c_stage, codegen
from eelsim.joints import JOINT_MODELS, get_joint_model

_LABEL = re.compile(r"^(\.?[\w.$]+):")
_JUMP = re.compile(r"^\s+j\w+\s+(\.?[\w.$]+)")
_BRANCH = re.compile(r"^\s+(j\w+|ret|call)\b")


def named_loops(n_links: int, lanes: int, joints: str) -> list[tuple[str, list[str]]]:
    """(title, instructions) of each lane loop of the C-compiled stage, in the generator's order.

    A marker (an empty ``asm`` statement) goes before each ``for`` of the C text; the machine
    code from one marker to the next in the assembly is that loop's (GCC may fully unroll a
    loop of few vectors, so backward jumps do not find them all). Jumps are left out: llvm-mca
    times the straight-line body.
    """
    layout = codegen.make_layout(n_links, lanes, joints=get_joint_model(joints))
    source = codegen.generate_stage_source(layout)
    titles = ["clear the RK4 accumulator (stage 1)", "clear the pivot flags (stage 1)"]
    titles += [text.strip()[len("# ---- "):] for text in source.splitlines()
               if text.strip().startswith("# ---- ") and " generated for " not in text
               and not text.strip().startswith("# ---- 1. angles")]
    marked, count = [], 0
    for text in c_stage.c_source(source, ("_stage",), "STAGE").splitlines():
        if "for (int64_t" in text:
            marked.append(f'__asm__ volatile("#LOOP{count}");')
            count += 1
        marked.append(text)
    compiler = c_stage.find_compiler() or "cc"
    flags = [f for f in c_stage.compile_flags(compiler) if f not in ("-shared", "-fPIC")]
    with tempfile.TemporaryDirectory() as folder:
        c_file = Path(folder) / "stage.c"
        c_file.write_text("\n".join(marked) + "\n")
        asm = subprocess.run([compiler, *flags, "-S", "-o", "-", str(c_file)],
                             capture_output=True, text=True, check=True).stdout
    lines = asm.splitlines()
    at = {int(m.group(1)): i for i, text in enumerate(lines)
          if (m := re.search(r"#LOOP(\d+)", text))}
    end_of_function = next(i for i, text in enumerate(lines) if ".cfi_endproc" in text)
    out = []
    for k in sorted(at):
        later = [i for i in at.values() if i > at[k]] + [end_of_function]
        body = [text for text in lines[at[k] + 1 : min(later)]
                if text.startswith("\t") and not text.startswith("\t.")
                and not _BRANCH.match(text) and not text.strip().startswith("#")]
        out.append((titles[k] if k < len(titles) else f"loop {k}", body))
    return out


def stage_assembly(n_links: int, lanes: int, stage: str) -> str:
    """Assembly of the generated stage, the C compiler's or numba's.

    Numba's is compiled afresh (numba does not show cached code).
    """
    if stage == "c":
        source = codegen.generate_stage_source(codegen.make_layout(n_links, lanes))
        library, _ = c_stage.build(source, ("_stage",), batch.kernel_cache_dir())  # the stage alone
        compiler = c_stage.find_compiler() or "cc"
        flags = [f for f in c_stage.compile_flags(compiler) if f not in ("-shared", "-fPIC")]
        return subprocess.run([compiler, *flags, "-S", "-o", "-",
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


def _default_cpu() -> str:
    """llvm-mca's model for this machine's vector width: AVX-512 or AVX2."""
    try:
        flags = Path("/proc/cpuinfo").read_text()
    except OSError:
        return "znver3"
    return "skylake-avx512" if "avx512f" in flags else "znver3"


def main() -> int:
    """Print one line per lane loop of the stage."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--links", type=int, default=6)
    parser.add_argument("--lanes", type=int, default=batch.DEFAULT_LANES)
    parser.add_argument("--cpu", default=None,
                        help="llvm-mca -mcpu (default: skylake-avx512 on a machine with "
                        "AVX-512, else znver3)")
    parser.add_argument("--stage", choices=("c", "numba"), default=None,
                        help="whose code: the C compiler's (loops named) or numba's (numbered; "
                        "default: as the kernel)")
    parser.add_argument("--joints", choices=sorted(JOINT_MODELS), default="pd",
                        help="the joint model whose stage is generated (pd)")
    args = parser.parse_args()
    cpu = args.cpu or _default_cpu()
    stage = batch.stage_backend(args.stage)
    if stage == "c":
        loops = named_loops(args.links, args.lanes, args.joints)
    else:
        if args.joints != "pd":
            raise SystemExit("--joints: numba's code is listed for the PD stage only")
        found = vector_loops(stage_assembly(args.links, args.lanes, stage))
        loops = [(f"vector loop {i}", body) for i, body in enumerate(found, 1)]
    if shutil.which("llvm-mca") is None:
        print("llvm-mca not found (apt install llvm): listing the loops only", file=sys.stderr)
    print(f"{args.joints} joints, stage by {stage}, llvm-mca -mcpu={cpu}")
    for title, body in loops:
        spills = sum("(%rsp)" in t or "(%rbp)" in t for t in body)
        line = f"{title[:70]:70s} {len(body):5d} instructions, {spills:3d} stack accesses"
        estimate = mca(body, cpu) if body else None
        if estimate:
            line += f", {estimate[0]:5.0f} cycles (throughput bound {estimate[1]:.0f})"
        print(line)
    print("cycles: per iteration of the loop, one vector of runs (each stage runs some of the "
          "loops: rotated or full angles, plain or not, stages 1-3 or the last)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
