"""Compile the batched-kernel variants the test suite uses, two at a time, before pytest runs.

Why: each variant (links x fluid law x joint model x stage) takes about 30 s to compile on first
use, and pytest, one process, would compile the 13 of them one after another (about 7 of its
12 minutes from a fresh clone). Compiled here in parallel into the kernel disk cache
(``eelsim.batch.kernel_cache_dir``), pytest loads them in well under a second each. A variant
missing from this list is still compiled by the test that needs it; the list only saves time.
"""

from __future__ import annotations

import sys
import time
from concurrent.futures import ProcessPoolExecutor

# (links, stage, fluid law, bundled robot file): what sim/tests and host/tests run
VARIANTS = [
    (n, "c", "morison", robot) for n in (3, 6, 8)
    for robot in ("paper_robot.toml", "servo_robot.toml")
] + [
    (6, "c", law, robot) for law in ("galilean", "linear_quadratic")
    for robot in ("paper_robot.toml", "servo_robot.toml")
] + [
    (6, "c", "reynolds", "paper_robot.toml"),
    (6, "numba", "morison", "paper_robot.toml"),
    (6, "numba", "morison", "servo_robot.toml"),
]


def _warm(variant: tuple[int, str, str, str]) -> str:
    from eelsim.batch import stage_backend, warm_up

    n, stage, law, robot = variant
    if stage == "c" and stage_backend() != "c":
        return f"{variant}: no C compiler, the numba stage is used"
    seconds = warm_up(n_links=n, stage=stage, law=law, robot_file=robot)
    return f"N = {n}, {stage} stage, {law}, {robot}: {seconds:.0f} s"


def main() -> int:
    """Compile every variant, two processes at a time; print a line per variant."""
    jobs = int(sys.argv[1]) if len(sys.argv) > 1 else 2
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        for line in pool.map(_warm, VARIANTS):
            print(f"kernels: {line}", flush=True)
    print(f"kernels: {len(VARIANTS)} variants ready in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
