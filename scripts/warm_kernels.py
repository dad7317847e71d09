"""Compile batched-kernel variants into the kernel disk cache, two at a time.

Each variant (links x fluid law x joint model x stage) takes 20-60 s to compile on first use.
The main job needs twenty (its fits, and the model comparison's candidates: five laws and
their lift variants, with either joint model), the test suite sixteen; compiled one after
another inside the command that needs them they were most of its
time from a fresh clone. Compiled here in parallel into the cache
(``eelsim.batch.kernel_cache_dir``), the command loads each in under a second. A variant missing
from a list is still compiled by the code that needs it: the lists only save time.

    python scripts/warm_kernels.py main [JOBS]     # scripts/setup.sh: the main job's
    python scripts/warm_kernels.py tests [JOBS]    # scripts/test.sh: the test suite's
"""

from __future__ import annotations

import sys
import time
from concurrent.futures import ProcessPoolExecutor

Variant = tuple[int, str | None, str, str]
"""(links, stage or None for the machine's default, fluid law, bundled robot file)."""

PAPER, SERVO = "paper_robot.toml", "servo_robot.toml"

# eelbot report on the bundled dataset: the fits, then the candidates of the comparison
CANDIDATES = ("morison", "galilean", "linear_quadratic", "lighthill", "resistive")
"""eelsim.fluid.candidate_laws(), written out: this script compiles in processes of its own."""
COMPARED = CANDIDATES + tuple(f"{law}_lift" for law in CANDIDATES)
"""eelhost.estimation.selection.default_laws(): the comparison's grid, each with both joints."""
MAIN: list[Variant] = [(6, None, law, robot) for robot in (PAPER, SERVO) for law in COMPARED]

# sim/tests and host/tests: 3, 6 and 8 links, every candidate law with both joint models, the
# test plants' law, and the numba stage the C stage is checked against
TESTS: list[Variant] = [(n, "c", "morison", robot) for n in (3, 6, 8) for robot in (PAPER, SERVO)]
TESTS += [(6, "c", law, robot) for law in ("galilean", "linear_quadratic") for robot in (PAPER, SERVO)]
TESTS += [(6, "c", law, PAPER) for law in ("lighthill", "resistive", "lighthill_lift")]
TESTS += [(6, "c", "reynolds", PAPER), (6, "numba", "morison", PAPER), (6, "numba", "morison", SERVO)]
# the plant-only foil law's plants swim on the servo joints (host/tests/test_plants.py)
TESTS += [(6, "c", "foil", SERVO)]


def _warm(variant: Variant) -> str:
    import eelhost.data  # noqa: F401  (registers the plant-only fluid laws, e.g. "foil")
    from eelsim.batch import stage_backend, warm_up

    n, stage, law, robot = variant
    stage = stage or stage_backend()
    if stage == "c" and stage_backend() != "c":
        stage = "numba"  # no C compiler here: the numba stage is what runs
    seconds = warm_up(n_links=n, stage=stage, law=law, robot_file=robot)
    return f"N = {n}, {stage} stage, {law}, {robot}: {seconds:.0f} s"


def main() -> int:
    """Compile the named list's variants, JOBS processes at a time; a line per variant."""
    lists = {"main": MAIN, "tests": TESTS}
    if len(sys.argv) < 2 or sys.argv[1] not in lists:
        print(f"usage: warm_kernels.py {'|'.join(lists)} [JOBS]", file=sys.stderr)
        return 2
    variants = lists[sys.argv[1]]
    jobs = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        for line in pool.map(_warm, list(dict.fromkeys(variants))):
            print(f"kernels: {line}", flush=True)
    print(f"kernels: {len(variants)} variants ready in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
