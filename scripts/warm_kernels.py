"""Compile batched-kernel variants into the kernel disk cache, two at a time.

A variant is links x fluid law x joint model x stage. The first of the C stage's variants with N
links takes about 30 s to compile on first use (numba compiles the driver, which every C variant
with N links shares: ``eelsim.batch.loading.driver_module``), each further one 2-3 s (its C
library), a numba-stage variant about 50 s (a whole module of its own). The main job needs thirty (its fits, and the model comparison's candidates: five laws and
their lift variants, with either joint model, and with the PD loop on the servo line, which joins
the comparison after its screen with the laws the screen ranks best), the test suite
twenty-three (thirteen of them also the main job's), both read from the registries
(:func:`variant_lists`); compiled one after another inside the command that needs them they were
most of its time from a fresh clone. Compiled here in parallel into the cache
(``eelsim.batch.kernel_cache_dir``), the command loads each in under a second. A variant missing
from a list is still compiled by the code that needs it: the lists only save time (and the test
suite fails when a test compiled one its list lacks: conftest.py, :func:`unlisted`).

    python scripts/warm_kernels.py main [JOBS]     # scripts/setup.sh main (scripts/main.sh)
    python scripts/warm_kernels.py tests [JOBS]    # scripts/setup.sh tests (scripts/test.sh)
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor
from typing import Any

Variant = tuple[int, str | None, str, str]
"""(links, stage or None for the machine's default, fluid law, bundled robot file or joint model).

A joint model's name in place of a robot file (``pd_limited``): the paper robot with that
model's joints (:func:`eelhost.estimation.joint_fit.joint_fit`), as the comparison swims it.
"""

PAPER, SERVO = "paper_robot.toml", "servo_robot.toml"
ROBOTS = (PAPER, SERVO)
"""The bundled robot files: the PD joints and the servo joints, the comparison's two joint models."""


def variant_lists() -> dict[str, list[Variant]]:
    """The lists, with the laws read from the registries.

    Nothing is named here by hand but the few variants particular tests swim.

    - ``main``: ``eelbot report`` on the bundled dataset: the comparison's default grid
      (:func:`eelhost.estimation.selection.default_laws`, the laws that declare themselves
      candidates), each with both joint models, and with every joint model that joins after the
      screen (``eelsim.joints.after_screen_models``: which laws it takes depends on the data).
    - ``tests``: sim/tests and host/tests: the default law at 3, 6 and 8 links, every candidate
      law, every plant-only law and the numba stage the C stage is checked against.
    """
    import eelhost.data  # noqa: F401  (registers the plant-only fluid laws, e.g. "foil")
    from eelhost.estimation.selection import default_laws
    from eelsim.fluid import DEFAULT_FLUID_LAW, FLUID_LAWS, LiftLaw, candidate_laws
    from eelsim.joints import after_screen_models

    main: list[Variant] = [(6, None, law, robot) for robot in ROBOTS for law in default_laws()]
    main += [(6, None, law, model) for model in after_screen_models(("pd", "servo"))
             for law in default_laws()]
    bases = [law for law in candidate_laws(lift_variants=False) if law != DEFAULT_FLUID_LAW]
    plant_laws = [name for name, law in FLUID_LAWS.items()
                  if name not in candidate_laws() and not isinstance(law, LiftLaw)]
    tests: list[Variant] = [(n, "c", DEFAULT_FLUID_LAW, robot) for n in (3, 6, 8)
                            for robot in ROBOTS]
    tests += [(6, "c", law, PAPER) for law in bases]
    # the servo-joint tests of the Galilean-consistent laws, the middle rung's comparison
    # (host/tests/test_estimation_middle_rung.py: three laws with either joint model, in worker
    # processes), the lift law's literature test, and a lift variant's screening restart from its
    # base's fit (host/tests/test_estimation_choice.py)
    tests += [(6, "c", law, SERVO) for law in ("galilean", "linear_quadratic", "resistive")]
    tests += [(6, "c", law, PAPER) for law in ("lighthill_lift", "morison_lift")]
    # the choice from either robot file (host/tests/test_estimation_choice.py): two laws, so the
    # PD loop on the servo line joins with both
    tests += [(6, "c", law, "pd_limited") for law in ("linear_quadratic", "morison")]
    # the plant-only laws: reynolds on the paper robot (sim/tests/test_fluid_laws.py), the foil
    # family (foil, stall, quarter_chord) on the servos that their plants swim on
    # (host/tests/test_plants.py)
    tests += [(6, "c", law, PAPER if law == "reynolds" else SERVO) for law in plant_laws]
    tests += [(6, "numba", DEFAULT_FLUID_LAW, robot) for robot in ROBOTS]
    return {"main": main, "tests": tests}


def _stage(variant: Variant) -> str:
    """The stage a variant compiles here: its own, else the machine's; numba without a C compiler."""
    from eelsim.batch import stage_backend

    stage = variant[1] or stage_backend()
    return "numba" if stage == "c" and stage_backend() != "c" else stage


def _joint_model(variant: Variant) -> str:
    """A variant's joint model: a bundled robot file's, or the one it names."""
    from eelsim.joints import joint_model_of
    from eelsim.robot import load_robot

    robot = variant[3]
    return joint_model_of(load_robot(robot).joints).name if robot in ROBOTS else robot


def kernel_keys(name: str) -> set[tuple[int, int, str, str, str]]:
    """List ``name``'s variants as the kernel loader keys them on this machine.

    The key is ``eelsim.batch.loading``'s: (N, lanes, stage, fluid law, joint model), the stage
    resolved as :func:`_warm` resolves it (numba when there is no C compiler) and the lanes the
    default, which is what every variant here is compiled with.
    """
    from eelsim.batch.loading import DEFAULT_LANES

    return {(v[0], DEFAULT_LANES, _stage(v), v[2], _joint_model(v)) for v in variant_lists()[name]}


def module_keys(names: Iterable[str]) -> set[tuple[int, int, str, str, str]]:
    """The loader keys of kernel modules named by ``eelsim.batch.loading.kernel_module_name``.

    ``n{N}_l{lanes}_{stage}_{law}`` with ``_{joint model}`` after it unless the model is the
    default; a name of another form is skipped.
    """
    import re

    from eelsim.joints import DEFAULT_JOINT_MODEL, JOINT_MODELS

    suffixes = sorted((m for m in JOINT_MODELS.names() if m != DEFAULT_JOINT_MODEL), key=len,
                      reverse=True)
    keys = set()
    for name in names:
        match = re.fullmatch(r"n(\d+)_l(\d+)_(c|numba)_(\w+)", name)
        if match is None:
            continue
        n, lanes, stage, rest = match.groups()
        model = next((m for m in suffixes if rest.endswith(f"_{m}")), DEFAULT_JOINT_MODEL)
        law = rest if model == DEFAULT_JOINT_MODEL else rest[: -len(model) - 1]
        keys.add((int(n), int(lanes), stage, law, model))
    return keys


def unlisted(loaded: Iterable[tuple[int, int, str, str, str]],
             name: str = "tests") -> list[tuple[int, int, str, str, str]]:
    """The kernels in ``loaded`` (loader keys) that list ``name`` does not compile beforehand.

    A kernel of a fluid law or joint model that the twin and the host do not register themselves
    (one a test defines, or a plug-in a test installs) is left out: no list can name it.
    """
    from eelsim.fluid import FLUID_LAWS
    from eelsim.joints import JOINT_MODELS

    def ours(registry: Any, entry: str) -> bool:
        try:
            module = getattr(registry[entry], "__module__", None) or ""
        except KeyError:  # gone again: a test's own, unregistered after it
            return False
        return module.startswith(("eelsim.", "eelhost."))

    listed = kernel_keys(name)
    return sorted(key for key in set(loaded) if key not in listed
                  and ours(FLUID_LAWS, key[3]) and ours(JOINT_MODELS, key[4]))


def _warm(variant: Variant) -> str:
    import eelhost.data  # noqa: F401  (registers the plant-only fluid laws, e.g. "foil")
    from eelsim.batch import warm_up

    n, _, law, robot = variant
    stage = _stage(variant)  # without a C compiler the numba stage is what runs
    if robot in ROBOTS:
        seconds = warm_up(n_links=n, stage=stage, law=law, robot_file=robot)
    else:
        seconds = _warm_joint_model(n, stage, law, robot)
    return f"N = {n}, {stage} stage, {law}, {robot}: {seconds:.0f} s"


def _warm_joint_model(n: int, stage: str, law: str, model: str) -> float:
    """Compile a kernel of joint model ``model`` on the paper robot (``eelsim.batch.warm_up``'s way)."""
    from eelhost.estimation.joint_fit import joint_fit
    from eelsim.batch import run_batch
    from eelsim.fluid import get_fluid_law
    from eelsim.robot import load_robot
    from eelsim.scenario import load_scenario

    start = time.perf_counter()
    robot = joint_fit(load_robot(PAPER), model).impose(load_robot(PAPER))
    fluid = get_fluid_law(law)
    robot = robot.with_coefficients(fluid.coefficients.from_array(fluid.bounds.mean(axis=1)))
    if robot.n_links != n:
        robot = robot.model_copy(update={"n_links": n})
    scenario = load_scenario("straight").model_copy(update={"duration_s": 0.05})
    run_batch(robot, scenario, sample_steps=[0], stage=stage)
    return time.perf_counter() - start


def _rounds(variants: list[Variant]) -> list[list[Variant]]:
    """The variants in two rounds: first the long compiles, then the rest.

    The C stage's variants of one N share one driver, which numba compiles once (about 30 s;
    ``eelsim.batch.loading.driver_module``); each of them alone is then its C library (2-3 s).
    So the first round compiles one C variant per N (its driver) and the numba stage's (about
    50 s each, a whole module each), the longest first, so that the last to end is a short one;
    the second round the other C variants, whose drivers are then cached (two processes would
    otherwise compile the same driver side by side).
    """
    first: list[Variant] = []
    drivers: set[int] = set()
    for v in variants:
        if _stage(v) == "numba" or v[0] not in drivers:
            first.append(v)
            if _stage(v) == "c":
                drivers.add(v[0])
    first.sort(key=lambda v: (_stage(v) == "numba", v[0]), reverse=True)
    return [first, [v for v in variants if v not in first]]


def _c_library(variant: Variant) -> None:
    """Compile a variant's C library (gcc), or nothing without C: the loader's own text does it.

    ``eelsim.batch.loading.kernel_source`` builds the library its module binds (keyed on the
    generated text, so the variant's own turn finds it); any failure is left to that turn to report.
    """
    import eelhost.data  # noqa: F401  (registers the plant-only fluid laws, e.g. "foil")
    from eelsim.batch import c_stage, loading
    from eelsim.fluid import get_fluid_law
    from eelsim.joints import get_joint_model

    if _stage(variant) != "c":
        return
    try:
        loading.kernel_source(variant[0], loading.DEFAULT_LANES, "c", get_fluid_law(variant[2]),
                              get_joint_model(_joint_model(variant)))
    except c_stage.CStageError:
        pass


def main() -> int:
    """Compile the named list's variants, JOBS processes at a time; a line per variant."""
    if len(sys.argv) < 2 or sys.argv[1] not in ("main", "tests"):
        print("usage: warm_kernels.py main|tests [JOBS]", file=sys.stderr)
        return 2
    variants = list(dict.fromkeys(variant_lists()[sys.argv[1]]))
    jobs = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    start = time.perf_counter()
    first, rest = _rounds(variants)
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        long_ones = [pool.submit(_warm, v) for v in first]
        # queued behind the long compiles: a process that is free while a driver still compiles
        # compiles the C libraries of the second round (gcc only), which then only load
        libraries = [pool.submit(_c_library, v) for v in rest]
        for future in long_ones:
            print(f"kernels: {future.result()}", flush=True)
        for library in libraries:
            library.result()
        for line in pool.map(_warm, rest):
            print(f"kernels: {line}", flush=True)
    print(f"kernels: {len(variants)} variants ready in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
