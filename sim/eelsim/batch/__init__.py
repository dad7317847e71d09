"""Fast batched closed-loop rollouts: many runs of the twin in one call, on all cores.

This is the fast path of the physics and control stack whose readable reference is
:func:`eelsim.closed_loop.simulate_closed_loop`; the tests (``sim/tests/test_batch.py``) check that
both agree to 1e-9 (states at sample times, arrival times, flags, failure times), for N = 3, 6
and 8.

Use
---
>>> from eelsim.batch import run_batch
>>> res = run_batch(robot, [scenario_a, scenario_b], coefficients=[[0.008, 0.776, 0.618, 0.007],
...                 [0.009, 0.978, 1.169, 0.001]], sample_times_s=[0.0, 5.0, 10.0])
>>> res.states.shape          # (runs, samples, 2 N + 4)
>>> res.arrival_time_s, res.failure, res.reason(0)

Every per-run input (robot, scenario, coefficients, seed) may be a single value, shared by all
runs, or a sequence with one entry per run. Robots may differ in gains, limits and per-link values
but must have the same number of links and fluid law. Loop options (timing, camera, servo model,
stopping rule) are shared by the batch.

The modules, one job each
-------------------------
- ``api``: :func:`run_batch`, :func:`run_spec` and the decoded :class:`BatchResult`;
- ``packing``: :class:`BatchSpec` (per-run inputs as arrays, the kernel's parameter rows, the
  seeded random draws, the camera's frame table), :func:`block_order`, :func:`plain_runs`;
- ``loading``: the stage's compiler (:func:`stage_backend`), the kernel cache folder, the kernel
  module's text and its import (:func:`kernel_module`, :func:`warm_up`);
- ``codegen``: the generated part (RK4 stage, collision screen, condition bound) and its row
  layout; the fluid law writes its own forces into it (:mod:`eelsim.fluid`);
- ``c_stage``: the generated stage translated to C and compiled by the machine's C compiler;
- ``kernel_template``: the driver (control updates, checks, camera, commits), read as text;
- ``records``: the records the kernel takes (runs, frames, loop settings, outputs) and its codes;
- ``kernels``: the package the generated modules are imported from.

How it is fast
--------------
Runs are grouped in blocks of ``lanes`` runs that advance in lock step, with the per-run data laid
out as structure of arrays (one row of ``lanes`` numbers per quantity). The right-hand side of the
dynamics is generated as straight-line code for the robot's N (``eelsim.batch.codegen``) inside
one loop over the lanes, which LLVM vectorises (4 runs per AVX2 instruction); the accelerations
come from an O(N) articulated-body recursion rather than the dense mass matrix, and the RK4 sums,
the finiteness checks and the condition-number bound at control updates are generated code too.
Blocks are spread over the cores by numba's threads, each taking the next block from a shared
counter when it finishes one (longest blocks first, so that the cores end together). The kernel
module is generated once per (N, lanes, stage, fluid law, joint model) and compiled once: numba
caches it on disk (next to the package in ``__pycache__``, or in ``$EELSIM_KERNEL_CACHE``) for
every later process. With the C stage, the numba part (the driver) is one module per (N, lanes)
that every fluid law and joint model shares (``loading.driver_module``): a variant is then its C
library, compiled in 2-3 s, and the driver's 30 s are paid once per N.

The generated RK4 stage (about 85 % of a step) is by default translated to C and compiled by the
machine's C compiler (``eelsim.batch.c_stage``), whose schedule of its long straight-line loops
runs about 15 % faster than LLVM's here; numba compiles the same generated text when there is no
C compiler, or when ``stage="numba"`` / ``$EELSIM_STAGE=numba`` asks for it
(:func:`stage_backend`). Both agree to rounding (tested).

Randomness follows the reference exactly: for each run, ``np.random.default_rng(seed)`` draws
first the control update schedule (:meth:`eelsim.timing.LoopTiming.update_steps`), then one heading
noise sample per camera frame when ``heading_noise_rad > 0``. These draws are made in Python
(``packing``); the kernel is deterministic.

Memory: per run, only the requested samples, the final state and the flags are kept; the full
state history is stored only with ``record_full=True``.
"""

from eelsim.batch.api import BatchResult, run_batch, run_spec, steps_per_second
from eelsim.batch.loading import (
    DEFAULT_LANES,
    STAGE_ENV,
    STAGES,
    kernel_cache_dir,
    kernel_module,
    kernel_source,
    load_kernel_source,
    stage_backend,
    warm_up,
)
from eelsim.batch.packing import BatchSpec, block_order, plain_runs
from eelsim.batch.records import Reason

__all__ = [
    "DEFAULT_LANES",
    "STAGES",
    "STAGE_ENV",
    "BatchResult",
    "BatchSpec",
    "Reason",
    "block_order",
    "kernel_cache_dir",
    "kernel_module",
    "kernel_source",
    "load_kernel_source",
    "plain_runs",
    "run_batch",
    "run_spec",
    "stage_backend",
    "steps_per_second",
    "warm_up",
]
