"""Paired A/B of the generated RK4 stage alone, compiled as C and driven from C.

Why: the GA generation (``tools/kernel_ab.py``) mixes the stage with the driver, the camera and
numba's threads; to ask what bounds the stage itself (a wrong-maths variant, another GCC option,
another block size) this script compiles each variant's stage with a small C loop that runs whole
RK4 steps on one block (four stages, then the commit of the new state) and times them in
alternation in one process, on one buffer, by the thread's CPU time (on a machine loaded beyond
its cores the wall clock mostly measures the wait for a core). The verdict is the median of the per-round time
ratios to the first variant (two copies of the same code: 0.99-1.00). See docs/kernel_history.md,
session 5, for what it decided.

Usage (from the repo root, after ``bash scripts/setup.sh``)::

    .venv/bin/python tools/stage_ab.py [--rounds 41] [--steps 1500] [--joints MODEL] NAME=SPEC ...

SPEC is ``[FLAGS][@GENERATOR][%LANES]``: compiler options (default: the kernel's own,
``-O3 -march=native`` and, on an AVX-512 CPU GCC does not know, ``c_stage.AVX512_TUNING``), a copy
of ``eelsim/batch/codegen.py`` to generate the stage with (default: the working tree's) and the
runs per block (default 16). For example::

    python tools/stage_ab.py base= mine=@/tmp/my_codegen.py \
        unrolled='-O3 -march=native -funroll-loops'

The state starts from random angles and rates with the bundled robot's per-run parameters; the
final states of the variants are printed against the first's (a correct variant differs by
rounding only). Libraries and C files go to a temporary folder.
"""

from __future__ import annotations

import argparse
import ctypes
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType

import numpy as np

from eelhost.estimation.joint_fit import joint_fit, joint_model_name
from eelsim import batch
from eelsim.batch import c_stage, codegen
from eelsim.closed_loop import LoopOptions
from eelsim.joints import JOINT_MODELS, get_joint_model
from eelsim.robot import BUNDLED_ROBOTS, load_robot
from eelsim.scenario import TRAINING_CORNERS, grid_scenario

N_LINKS = 6
DT_S = 0.01
# the variant's FLAGS replace these of the kernel's flags (by default, the kernel's own)
_TUNING = ("-O3", "-march=native", *(f for f in c_stage.compile_flags("gcc")
                                     if f in c_stage.AVX512_TUNING))
_BASE_FLAGS = [f for f in c_stage.C_FLAGS if f not in _TUNING]

# whole RK4 steps as the kernel's driver calls the stage (eelsim/batch/kernel_template.py), without the
# checks: y = x, four stages (rotating sin/cos except every 16th step's first), x = xn
_DRIVER = r"""
void bench(double *restrict work, int64_t steps, double dt) {
    const int64_t ns = %(ns)d, lanes = %(lanes)d, wx = %(wx)d, wxn = %(wxn)d;
    for (int64_t i = 0; i < steps; i++) {
        double t = i * dt, half = 0.5 * dt;
        for (int st = 0; st < 4; st++) {
            double ts = st == 0 ? t : st == 3 ? t + dt : t + half;
            double a = st == 0 || st == 1 ? half : st == 2 ? dt : 0.0;
            double wk = st == 0 || st == 3 ? 1.0 : 2.0;
            if (st == 0) for (int64_t k = 0; k < ns * lanes; k++) work[k] = work[wx * lanes + k];
            STAGE_stage(work, ts, a, wk, st == 0, st == 3, dt / 6.0, st > 0 || i %% 16 != 0,
                  st == 1 || st == 3, 1);
        }
        for (int64_t k = 0; k < ns * lanes; k++) work[wx * lanes + k] = work[wxn * lanes + k];
    }
}
"""


def _load_generator(path: str | None, name: str) -> ModuleType:
    """The generator module at ``path`` (imported as ``name``), or the working tree's."""
    if not path:
        return codegen
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise SystemExit(f"{path}: not a Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


def _build(name: str, flags: str, generator: ModuleType, lanes: int, folder: Path,
           joints: str = "pd"):
    """Compile one variant; return its library (``bench``) and its layout."""
    layout = generator.make_layout(N_LINKS, lanes, joints=get_joint_model(joints))
    if layout.work["y"] != 0:
        raise SystemExit(f"{name}: the driver here assumes the stage state's rows come first")
    source = generator.generate_stage_source(layout)
    text = c_stage.c_source(source, ("_stage",), "STAGE")
    text += _DRIVER % dict(ns=2 * N_LINKS + 4, lanes=lanes, wx=layout.work["x"],
                           wxn=layout.work["xn"])
    c_file, library = folder / f"{name}.c", folder / f"{name}.so"
    c_file.write_text(text)
    subprocess.run(["gcc", *flags.split(), *_BASE_FLAGS, "-o", str(library), str(c_file)],
                   check=True)
    lib = ctypes.CDLL(str(library))
    lib.bench.argtypes = [ctypes.c_void_p, ctypes.c_int64, ctypes.c_double]
    return lib, layout


def _initial(layout, lanes: int, seed: int, joints: str = "pd") -> np.ndarray:
    """A block's buffer: the per-run rows of the bundled robot with these joints, random states.

    The first bundled robot file whose joint model it is, else the paper's with the model's
    table (as the estimator's model comparison makes it: ``joint_fit(...).impose``).
    """
    robots = [load_robot(name) for name in BUNDLED_ROBOTS]
    robot = next((r for r in robots if joint_model_name(r) == joints), None)
    robot = robot or joint_fit(robots[0], joints).impose(robots[0])
    coeffs = robot.hydrodynamics
    corners = [grid_scenario("straight", a, w) for a, w in TRAINING_CORNERS]
    rng = np.random.default_rng(seed)
    candidates = coeffs.as_array() * rng.uniform(0.5, 1.5, size=(lanes, 4))
    spec = batch.BatchSpec.build(robot, [corners[i % 4] for i in range(lanes)], candidates,
                                 LoopOptions(stop_at_goal=False), seed)
    work = np.zeros((layout.work_rows + layout.out_rows) * lanes)
    n = N_LINKS
    for r in range(lanes):
        for p in range(spec.params.shape[1]):
            work[(layout.work["geometry"] + p) * lanes + r] = spec.params[r, p]
        x = np.concatenate([rng.normal(0, 0.3, n), [0.5, 0.1], rng.normal(0, 1.0, n), [0.1, 0.0]])
        for row in range(2 * n + 4):
            work[(layout.work["x"] + row) * lanes + r] = x[row]
    return work


def main() -> None:
    """Build the variants named on the command line, check their results, time them paired."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("variants", nargs="+", metavar="NAME=SPEC")
    parser.add_argument("--rounds", type=int, default=41)
    parser.add_argument("--steps", type=int, default=1500, help="RK4 steps per timing (16 lanes)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--joints", choices=sorted(JOINT_MODELS), default="pd",
                        help="the joint model of every variant's stage and robot (pd: the "
                        "bundled robot; servo: servo_robot.toml)")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="eelsim_stage_ab_"))
    variants = []
    buffers: dict[int, np.ndarray] = {}  # one buffer per block size, shared by its variants
    for arg in args.variants:
        name, _, spec = arg.partition("=")
        spec, _, lanes_text = spec.partition("%")
        flags, _, generator_path = spec.partition("@")
        lanes = int(lanes_text) if lanes_text else 16
        generator = _load_generator(generator_path or None, f"stage_ab_{name}")
        lib, layout = _build(name, flags or " ".join(_TUNING), generator, lanes, folder,
                             args.joints)
        init = _initial(layout, lanes, args.seed, args.joints)
        if lanes not in buffers:
            buffers[lanes] = np.zeros(init.size + 8192)  # room for variants with more rows
        buf = buffers[lanes]
        start = (-buf.ctypes.data % 64) // 8  # on a cache line, like the kernel's blocks
        variants.append((name, lib, layout, init, buf[start:start + init.size], lanes))
    finals = []
    for _name, lib, layout, init, work, lanes in variants:
        work[:] = init
        lib.bench(work.ctypes.data, 200, DT_S)
        x = work[layout.work["x"] * lanes:(layout.work["x"] + 2 * N_LINKS + 4) * lanes]
        finals.append(x.reshape(2 * N_LINKS + 4, lanes)[:, :4].copy())
    for (name, *_), final in zip(variants, finals, strict=True):
        diff = np.nanmax(np.abs(final - finals[0]))
        print(f"{name}: final state after 200 steps differs from the first's by {diff:.1e}"
              f" (finite: {np.isfinite(final).all()})")
    per_step = np.zeros((args.rounds, len(variants)))  # ns per run and step
    for i in range(args.rounds):
        order = range(len(variants)) if i % 2 == 0 else reversed(range(len(variants)))
        for j in order:
            name, lib, layout, init, work, lanes = variants[j]
            work[:] = init
            block_steps = args.steps * 16 // lanes
            t0 = time.thread_time()  # CPU time: the machine may be loaded beyond its cores
            lib.bench(work.ctypes.data, block_steps, DT_S)
            per_step[i, j] = (time.thread_time() - t0) / (block_steps * lanes) * 1e9
    for j, (name, *_) in enumerate(variants):
        ratio = per_step[:, j] / per_step[:, 0]
        print(f"{name:>12}: best {per_step[:, j].min():6.1f} ns per run and step, median"
              f" {np.median(per_step[:, j]):6.1f}; ratio to the first: median"
              f" {np.median(ratio):.3f} (quartiles {np.percentile(ratio, 25):.3f}"
              f"-{np.percentile(ratio, 75):.3f})")


if __name__ == "__main__":
    main()
