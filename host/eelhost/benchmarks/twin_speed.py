"""How fast the twin runs (single run, a GA generation, MuJoCo for comparison): ``eelbot bench``.

:func:`twin_speed_report` measures, in one process and one sitting:

1. compile time of the batched kernel: cold (empty cache, in a subprocess) and cached;
2. a single closed-loop run: simulated seconds per wall second (batched kernel and reference path);
3. one generation of the paper's GA (150 candidates x 4 training experiments = 600 runs of 3,000
   RK4 steps): RK4 steps per second on one thread and on all cores, and the implied time of the
   whole GA (78,000 runs, 2.34e8 steps) for one motion type; then the paper's GA itself, end to
   end (``eelbot estimate --method ga`` on the bundled dataset's straight runs);
4. where the time of a step goes (one thread): the generated RK4 stage, the collision screen and
   the condition-number bound timed alone, the camera by switching it off, the rest by difference;
5. each candidate fluid law's kernel on the same generation, the laws in alternation;
6. the same robot in MuJoCo: ``mujoco.rollout`` with the built-in ellipsoid fluid model on all
   cores against the batched kernel with each joint model (the PD loop of section 2, and the
   servo model's prescribed-shape kernel), every engine timed alone in a fresh process, in
   rounds whose order rotates (:mod:`eelhost.benchmarks.engine_rounds`): the ratios are taken
   within each round and reported as median and range; and our Morison drag through
   ``xfrc_applied`` from Python.

It returns a markdown report, handing each line to ``emit`` as soon as it is known (the command
prints them and writes ``docs/benchmarks.md``).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from eelhost.machine import cpu_model, load_average, simd_flags
from eelsim.closed_loop import LoopOptions, simulate_closed_loop
from eelsim.fluid import FluidCoefficients
from eelsim.joints import pd_gains
from eelsim.robot import SERVO_ROBOT, Robot, load_robot
from eelsim.scenario import TRAINING_CORNERS, grid_scenario, load_scenario

GA_RUNS = 150 * 130 * 4
REPEATS = 10  # timed runs of the GA generation per thread count (best and median reported)
LAW_REPEATS = 5  # timed generations of each candidate law's kernel
GA_STEPS = GA_RUNS * 3000



@dataclass(frozen=True)
class TwinBenchSettings:
    """What :func:`twin_speed_report` measures.

    Attributes
    ----------
    runs : int
        Runs in the batch (600: one GA generation).
    steps : int
        RK4 steps per run.
    threads : int or None
        Threads for "all cores" (None: the CPU count).
    mujoco : bool
        Compare with MuJoCo.
    cold_compile : bool
        Measure the cold compile (about a minute).
    ga : bool
        Run the paper's GA end to end (about 40 s).
    rounds : int
        Rounds of the MuJoCo comparison per thread count: one window of each engine, each in
        its own process, back to back.
    note : str
        A remark for the report.
    command : str
        The command line that produced the report, as shown in it.
    """

    runs: int = 600
    steps: int = 3000
    threads: int | None = None
    mujoco: bool = True
    cold_compile: bool = True
    ga: bool = True
    rounds: int = 15
    note: str = ""
    command: str = "eelbot bench"


def _stage_name(stage: str) -> str:
    """How a stage backend is called in the report (the C compiler's own name and version)."""
    if stage != "c":
        return "numba (LLVM)"
    from eelsim.batch import c_stage

    compiler = c_stage.find_compiler() or "C"
    try:
        out = subprocess.run([compiler, "--version"], capture_output=True, text=True, check=False)
        version = out.stdout.splitlines()[0].strip()
    except (OSError, IndexError):
        version = compiler
    return f"C ({version})"


def _warm_up_in_subprocess(cache_dir: str | None, stage: str, law: str | None = None) -> float:
    """Seconds to compile (or load) the kernel (of fluid law ``law``) in a fresh Python process."""
    env = dict(os.environ)
    if cache_dir is not None:
        env["EELSIM_KERNEL_CACHE"] = cache_dir
    code = f"from eelsim.batch import warm_up; print(warm_up(stage={stage!r}, law={law!r}))"
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return float(out.stdout.strip().splitlines()[-1])


def _other_law(robot: Robot) -> str | None:
    """A candidate fluid law other than the robot's (for the compile of a second C variant)."""
    from eelsim.fluid import candidate_laws

    return next((law for law in candidate_laws(lift_variants=False)
                 if law != robot.fluid_law.name), None)


def twin_speed_report(
    robot: Robot,
    coeffs: FluidCoefficients,
    settings: TwinBenchSettings,
    emit: Callable[[str], None] | None = None,
) -> list[str]:
    """Measure the twin's speed and write the markdown report of docs/benchmarks.md.

    Parameters
    ----------
    robot : Robot
        The robot simulated.
    coeffs : FluidCoefficients
        Its hydrodynamic coefficients.
    settings : TwinBenchSettings
        What to measure.
    emit : callable, optional
        Gets each line of the report as soon as it is known (the command prints them).

    Returns
    -------
    list of str
        The report's lines.
    """
    import numba

    from eelsim import batch

    threads = settings.threads or os.cpu_count() or 1
    lines: list[str] = []

    def say(text: str = "") -> None:
        if emit is not None:
            emit(text)
        lines.append(text)

    load_before = load_average()
    say("# Benchmarks of the twin")
    say()
    say(f"Produced by `{settings.command}` on {time.strftime('%Y-%m-%d %H:%M')}.")
    say()
    say("## Machine")
    say()
    say(f"- CPU: {cpu_model()}; {os.cpu_count()} logical cores (nproc); SIMD: {simd_flags()}")
    say(
        f"- Python {platform.python_version()}, numpy {np.__version__}, numba {numba.__version__}"
        f" (threading layer: {getattr(numba.config, 'THREADING_LAYER', '?')}, reported again after the runs)"
    )
    say(f"- load average before the benchmark: {load_before}")
    if settings.note:
        say(f"- note: {settings.note}")
    say()

    # 1. compile time
    say(f"## Compile time of the batched kernel (N = {robot.n_links})")
    say()
    default_stage = batch.stage_backend()
    stages = [default_stage] + (["numba"] if default_stage == "c" else [])
    name = {stage: _stage_name(stage) for stage in stages}  # asks the compiler once
    say(f"The generated RK4 stage is compiled by {name[default_stage]} (the default here"
        f"; `{batch.STAGE_ENV}` chooses); the rest of the kernel by numba.")
    say()
    for stage in stages:
        if settings.cold_compile:
            with tempfile.TemporaryDirectory() as tmp:
                cold = _warm_up_in_subprocess(tmp, stage)
                # every C variant with N links shares one driver (eelsim.batch.loading.
                # driver_module): another law then compiles its C library only
                second_law = _other_law(robot) if stage == "c" else None
                more = _warm_up_in_subprocess(tmp, stage, second_law) if second_law else None
            say(f"- stage by {name[stage]}: cold (empty cache, fresh process): {cold:.1f} s")
            if more is not None:
                say(f"- stage by {name[stage]}: another fluid law ({second_law}) cold, the driver "
                    f"cached (fresh process): {more:.1f} s")
        batch.warm_up(robot.n_links, stage=stage)  # make sure the default cache is filled
        cached = _warm_up_in_subprocess(None, stage)
        say(f"- stage by {name[stage]}: cached (fresh process, on-disk cache): "
            f"{cached:.2f} s")
    say()

    # 2. a single run
    say("## 1. A single closed-loop run")
    say()
    single = load_scenario("turning").model_copy(update={"duration_s": 60.0})
    opts = LoopOptions(stop_at_goal=False)
    batch.run_batch(robot, single, coeffs, opts, threads=1)  # warm
    start = time.perf_counter()
    one = batch.run_batch(robot, single, coeffs, opts, threads=1)
    wall = time.perf_counter() - start
    sim_s = float(one.final_step[0]) * opts.timing.dt_s
    short = single.model_copy(update={"duration_s": 5.0})
    start = time.perf_counter()
    simulate_closed_loop(robot, short, opts, coefficients=coeffs)
    ref_wall = time.perf_counter() - start
    say("| path | simulated s per wall s |")
    say("|---|---|")
    say(f"| batched kernel, one run (60 s of 'turning', one thread) | {sim_s / wall:,.0f} |")
    say(f"| reference `simulate_closed_loop` (5 s) | {5.0 / ref_wall:,.1f} |")
    say()
    lanes = batch.DEFAULT_LANES
    say(
        f"A single run occupies one block of {lanes} lanes, so it runs at 1/{lanes} of the "
        "batch rate."
    )
    say()

    # 3. a GA generation
    say(f"## 2. One GA generation: {settings.runs} runs x {settings.steps} steps")
    say()
    corners = [
        grid_scenario("straight", a, w).model_copy(
            update={"duration_s": settings.steps * opts.timing.dt_s}
        )
        for a, w in TRAINING_CORNERS
    ]
    rng = np.random.default_rng(0)
    base = coeffs.as_array()
    candidates = base * rng.uniform(0.5, 1.5, size=(settings.runs, 4))
    start = time.perf_counter()
    spec = batch.BatchSpec.build(
        robot, [corners[i % 4] for i in range(settings.runs)], candidates, opts, 0
    )
    prep = time.perf_counter() - start
    # best of REPEATS, the thread counts in alternation, so that both see the same moments of
    # a machine whose speed drifts (a shared VM: 5-10 % from minute to minute)
    counts = sorted({1, threads})
    cases = [(stage, n_threads) for stage in stages for n_threads in counts]
    walls: dict[tuple[str, int], list[float]] = {case: [] for case in cases}
    # the same generation with the other joint model (the robot's links; the bundled servo's
    # joints or PD's), timed in the same alternation: kernel against kernel in one process
    other_robot = robot.with_joints(load_robot(
        SERVO_ROBOT if pd_gains(robot.joints) is not None else None).joints)
    other_spec = batch.BatchSpec.build(
        other_robot, [corners[i % 4] for i in range(settings.runs)], candidates, opts, 0
    )
    other_walls: dict[int, list[float]] = {n: [] for n in counts}
    for stage, n_threads in cases:
        batch.run_spec(spec, threads=n_threads, stage=stage)  # warm the threads
    for n_threads in counts:
        batch.run_spec(other_spec, threads=n_threads)
    for _ in range(REPEATS):
        for stage, n_threads in cases:
            start = time.perf_counter()
            res = batch.run_spec(spec, threads=n_threads, stage=stage)
            walls[stage, n_threads].append(time.perf_counter() - start)
        for n_threads in counts:
            start = time.perf_counter()
            other = batch.run_spec(other_spec, threads=n_threads)
            other_walls[n_threads].append(time.perf_counter() - start)
    steps = float(res.final_step.sum())
    best_rate = {case: steps / min(walls[case]) for case in cases}
    median_rate = {case: steps / float(np.median(walls[case])) for case in cases}
    rates = {n: best_rate[default_stage, n] for n in counts}
    typical = {n: median_rate[default_stage, n] for n in counts}
    flagged = int(np.count_nonzero(res.failure >= 2))
    say(f"Best and median of {REPEATS} generations per case, the cases in alternation.")
    say()
    say("| stage compiled by | threads | RK4 steps per second (best) | per step and core "
        "| median of the runs |")
    say("|---|---|---|---|---|")
    for stage, n_threads in cases:
        rate = best_rate[stage, n_threads]
        say(f"| {name[stage]} | {n_threads} | {rate / 1e6:.2f} million "
            f"| {n_threads / rate * 1e9:.0f} ns | {median_rate[stage, n_threads] / 1e6:.2f} million |")
    say()
    if len(stages) > 1:
        ratios = [
            f"{np.median(np.array(walls['c', n]) / np.array(walls['numba', n])):.3f} ({n} thr.)"
            for n in counts
        ]
        say("- time of the C-compiled stage's generation over numba's, median of the paired "
            f"repeats: {', '.join(ratios)}")
    # servo over PD, whichever of the two the robot file has: rate ratio of the paired repeats
    other_steps = float(other.final_step.sum())
    robot_is_pd = pd_gains(robot.joints) is not None
    servo_pd = []
    for n in counts:
        other_rate = other_steps / np.array(other_walls[n])
        own_rate = steps / np.array(walls[default_stage, n])
        paired = other_rate / own_rate if robot_is_pd else own_rate / other_rate
        servo_pd.append(f"{np.median(paired):.2f} ({paired.min():.2f}-{paired.max():.2f}; "
                        f"{max(other_rate if robot_is_pd else own_rate) / 1e6:.2f} million steps/s "
                        f"best, {n} thr.)")
    say("- the servo joint model's kernel over the PD kernel's rate (the same generation, "
        f"{name[default_stage]}, timed in the same alternation), median (range) of the paired "
        f"repeats: {', '.join(servo_pd)}")
    ga = GA_STEPS / rates[threads]
    say(
        f"- implied time of the paper's whole GA for one motion type (150 x 130 x 4 = {GA_RUNS:,}"
        f" runs, {GA_STEPS:.3g} steps) on {threads} threads, stage by "
        f"{name[default_stage]}: **{ga:.0f} s** at the best generation's rate, "
        f"{GA_STEPS / typical[threads]:.0f} s at the median's"
    )
    say(
        f"- preparing the batch in Python (BatchSpec.build): {prep * 1e3:.0f} ms; "
        f"runs flagged ill-conditioned or self-colliding: {flagged} of {settings.runs}"
    )
    say("- target of issue 4: 10 million steps/s on 2 cores (GA under 30 s)")
    say()
    if not settings.ga:
        say("The paper's GA end to end: skipped (--no-ga).")
    else:
        for text in _whole_ga(threads):
            say(text)
    say()

    # the same links with each joint model, for the engines' rounds below
    servo_robot = robot if robot.joint_model.kinematic else robot.with_joints(
        load_robot(SERVO_ROBOT).joints)

    say("### Each candidate fluid law's kernel (PD joints)")
    say()
    for text in _law_rates(batch, robot, settings):
        say(text)
    say()

    # 4. profile
    say("## 3. Where the time of a step goes (one thread)")
    say()
    for text in _profile(batch, spec, opts):
        say(text)
    say()

    # 5. MuJoCo
    say("## 4. The same robot in MuJoCo")
    say()
    if not settings.mujoco:
        say("Skipped (--no-mujoco).")
    else:
        from eelhost.benchmarks import mujoco_compare

        try:
            mujoco_compare.require_mujoco()
        except mujoco_compare.MujocoMissing as err:
            say(f"Skipped: {err}")
        else:
            for text in _mujoco_section(robot, servo_robot, coeffs, settings, threads,
                                        rates[1], opts.timing.dt_s):
                say(text)
    say(
        f"- load average after the benchmark: {load_average()}; numba threading layer used: "
        f"{numba.threading_layer()}"
    )
    say()
    say(
        f"Figures are wall-clock, best of {REPEATS} for the GA generation and of two elsewhere; "
        "other processes running at the same time slow them down (see the load averages above "
        "and the note)."
    )
    say()
    say(
        "How the kernel got here, what each change gained and what was tried and dropped: "
        "[kernel_history.md](kernel_history.md)."
    )
    return lines


def _law_rates(batch: ModuleType, robot: Robot, settings: TwinBenchSettings) -> list[str]:
    """Each candidate law's GA-generation rate beside the default law's, as markdown lines.

    The same generation (the robot's PD joints, each law's coefficients at the middle of its
    bounds times U(0.5, 1.5)), one thread (a thread's rate is what a law costs; several threads
    on a loaded machine measure the scheduler), the laws in alternation, :data:`LAW_REPEATS`
    times; a law's kernel is compiled on first use if the cache lacks it.
    """
    from eelhost.benchmarks.engine_rounds import generation_spec
    from eelsim.fluid import candidate_laws, get_fluid_law

    laws = list(candidate_laws(lift_variants=False))
    pd_robot = robot if pd_gains(robot.joints) is not None else robot.with_joints(
        load_robot().joints)
    specs = {}
    for law in laws:
        fluid = get_fluid_law(law)
        middle = fluid.coefficients.from_array(fluid.bounds.mean(axis=1))
        specs[law] = generation_spec(pd_robot.with_coefficients(middle), settings.runs,
                                     settings.steps)
        batch.run_spec(specs[law], threads=1)  # compile or load, warm
    rates: dict[str, list[float]] = {law: [] for law in laws}
    flagged: dict[str, int] = {}
    for _ in range(LAW_REPEATS):
        for law in laws:
            start = time.perf_counter()
            res = batch.run_spec(specs[law], threads=1)
            rates[law].append(float(res.final_step.sum()) / (time.perf_counter() - start))
            flagged[law] = int(np.count_nonzero(res.failure >= 2))
    first = laws[0]
    lines = [f"One thread, the laws in alternation, best of {LAW_REPEATS} generations each; the "
             f"rate ratio is the median of the paired repeats.", "",
             f"| law | RK4 steps per second (best) | rate over {first}'s | runs flagged |",
             "|---|---|---|---|"]
    for law in laws:
        ratio = np.median(np.array(rates[law]) / np.array(rates[first]))
        lines.append(f"| {law} | {max(rates[law]) / 1e6:.2f} million | {ratio:.2f} "
                     f"| {flagged[law]} of {settings.runs} |")
    return lines


def _mujoco_section(robot: Robot, servo_robot: Robot, coeffs: FluidCoefficients,
                    settings: TwinBenchSettings, threads: int, one_thread_rate: float,
                    dt_s: float) -> list[str]:
    """MuJoCo against the kernel, each engine in its own process, in rounds; markdown lines."""
    import mujoco

    from eelhost.benchmarks import mujoco_compare
    from eelhost.benchmarks.engine_rounds import (
        MUJOCO_WINDOW_FRACTION,
        engine_rounds,
        mujoco_window_runs,
        quartiles,
        spread,
    )

    # MuJoCo's position actuator is a PD law: a servo robot is compared with its links on the
    # bundled PD joints
    pd_robot = robot if pd_gains(robot.joints) is not None else robot.with_joints(
        load_robot().joints)
    counts = sorted({1, threads})
    rounds = engine_rounds(pd_robot, servo_robot, settings.runs, settings.steps, counts,
                           settings.rounds)
    lines = [
        f"mujoco {mujoco.__version__}; ellipsoid fluid model, implicitfast, dt = {dt_s} s, PD as "
        "position actuator + joint damping; open-loop gait.",
        "",
        "Each engine runs in a worker process of its own, started and warmed up once (the "
        "kernel loads its compiled code and starts its threads, MuJoCo builds its model); a "
        "round then times one window of each engine, back to back, while the other workers "
        "wait idle (no thread of theirs runs), the order rotated from round to round. A "
        f"kernel's window is the whole generation ({settings.runs} runs x {settings.steps} "
        f"steps), MuJoCo's `mujoco.rollout` of {mujoco_window_runs(settings.runs, 1)} runs "
        f"(1/{MUJOCO_WINDOW_FRACTION} of them; at least 2 per thread) x {settings.steps} steps, "
        "about as long. The ratios are taken within each round, so that the machine's load, "
        f"which changes from second to second, divides out as far as it can: {settings.rounds} "
        f"rounds on {' and on '.join(str(n) for n in counts)} threads; the figures are the "
        "median of the rounds with the quartiles (and the range).",
        "",
        "| round | threads | load before / after | MuJoCo (million steps/s) | PD kernel "
        "| servo kernel | PD kernel / MuJoCo | servo kernel / MuJoCo | servo / PD |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for i, r in enumerate(rounds):
        lines.append(
            f"| {i % settings.rounds + 1} | {r.threads} | {r.load_before.split()[0]} / "
            f"{r.load_after.split()[0]} | {r.rates['mujoco'] / 1e6:.3f} "
            f"| {r.rates['pd kernel'] / 1e6:.2f} | {r.rates['servo kernel'] / 1e6:.2f} "
            f"| {r.ratio('pd kernel'):.1f} | {r.ratio('servo kernel'):.1f} "
            f"| {r.ratio('servo kernel', 'pd kernel'):.2f} |")
    lines.append("")
    for n in counts:
        mine = [r for r in rounds if r.threads == n]
        pd_mj = [r.ratio("pd kernel") for r in mine]
        servo_mj = [r.ratio("servo kernel") for r in mine]
        servo_pd = [r.ratio("servo kernel", "pd kernel") for r in mine]
        lines.append(
            f"- {n} thread{'s' if n > 1 else ''}: **PD kernel / MuJoCo {quartiles(pd_mj)}; "
            f"servo kernel / MuJoCo {quartiles(servo_mj)}** (median of the rounds and "
            f"quartiles; range {spread(pd_mj).split(' ', 1)[1]} and "
            f"{spread(servo_mj).split(' ', 1)[1]}); servo kernel / PD kernel "
            f"{quartiles(servo_pd, 2)}; rates, medians: MuJoCo "
            f"{np.median([r.rates['mujoco'] for r in mine]) / 1e6:.3f}, PD kernel "
            f"{np.median([r.rates['pd kernel'] for r in mine]) / 1e6:.2f}, servo kernel "
            f"{np.median([r.rates['servo kernel'] for r in mine]) / 1e6:.2f} million steps/s")
    xf = mujoco_compare.morison_xfrc_speed(pd_robot, coeffs, 2, settings.steps) if isinstance(
        coeffs, mujoco_compare.HydroCoefficients) else None
    if xf is not None:
        lines.append(
            f"- Morison drag via `xfrc_applied` from Python, 2 x {settings.steps}, 1 thread: "
            f"{xf.steps_per_s / 1e6:.4f} million steps/s; our kernel on 1 thread (section 2) is "
            f"{one_thread_rate / xf.steps_per_s:.0f} x faster (in this process, after the kernel "
            "ran)")
    lines += ["- target of issue 4: at least 15 x MuJoCo's fastest batched path; of issue 19: "
              "at least 25 x with the servo joint model; of issue 32: at least 100 x, and the "
              "servo kernel at least as fast as the PD kernel"]
    return lines


def _whole_ga(threads: int) -> list[str]:
    """Run the paper's GA for the bundled dataset's straight runs; report it as markdown lines."""
    from eelhost.data.experiments import BUNDLED_DATASET, load_dataset
    from eelhost.estimation.methods import FitSettings
    from eelhost.estimation.pipeline import fit_motion

    dataset = load_dataset(BUNDLED_DATASET)
    start = time.perf_counter()
    res, ev = fit_motion(dataset, "straight", FitSettings("ga", seed=0))
    wall = time.perf_counter() - start
    return [
        "### The paper's GA, end to end",
        "",
        f"`eelbot estimate datasets/{BUNDLED_DATASET.name} --motion straight --method ga` (150 candidates x"
        f" 130 generations x 4 training experiments, {threads} threads): **{wall:.1f} s** for"
        f" {ev.simulations:,} closed-loop runs and {ev.steps / 1e6:.0f} million RK4 steps"
        f" ({ev.steps / wall / 1e6:.1f} million per second, everything included: the GA, the"
        f" camera's view of each run, the fitness); best fitness {res.fitness:.4f}.",
        "",
        "Fewer steps than 78,000 x 3,000: a run ends at its goal once the last recorded sample is"
        " passed (nothing after can count), else at T_max = 1.5 x the recording; the kernel packs"
        " runs of about the same length into a block (guessed from the nearest earlier candidate)"
        " so that few lanes idle. See [kernel_history.md](kernel_history.md), session 6.",
    ]


def _profile(batch: ModuleType, spec: Any, opts: LoopOptions) -> list[str]:
    """Per-step cost of the kernel's parts on one thread, as markdown lines.

    The batch runs with and without the camera (one frame only), each with the real kernel and
    with the generated physics stubbed out (:func:`_driver_only_kernel`): the stub run gives the
    driver (control updates, checks, commit, block set-up) and the camera, the real run adds
    the stages, the screen and the condition bound; the screen and the bound are also timed
    alone on one block whose lanes hold the batch's first runs at random states.

    Parameters
    ----------
    batch : module
        ``eelsim.batch``.
    spec : BatchSpec
        The GA generation of section 2.
    opts : LoopOptions
        Its loop options.

    Returns
    -------
    list of str
    """
    import dataclasses

    import numba

    from eelsim.camera import CameraModel

    n = spec.n_links
    lanes = batch.DEFAULT_LANES
    k = batch.kernel_module(n, lanes, None, spec.fluid_law, spec.joint_model)
    work = np.zeros((k.WORK_ROWS + k.OUT_ROWS) * lanes)  # out's rows follow work's
    rng = np.random.default_rng(1)
    for r in range(lanes):
        run = r % spec.n_runs
        for p in range(spec.params.shape[1]):
            work[(k.W_GEOMETRY + p) * lanes + r] = spec.params[run, p]
        x = np.concatenate([rng.normal(0, 0.3, n), [0.5, 0.1], rng.normal(0, 1.0, n), [0.1, 0.0]])
        for row in range(2 * n + 4):
            work[(k.W_X + row) * lanes + r] = x[row]
            work[(k.W_Y + row) * lanes + r] = x[row]
    stage, screen, cond_bound = k._stage, k._screen, k._cond_bound

    # the sweep the driver picks for this block (the GA's runs: no current, no servo line)
    plain = bool(batch.plain_runs(spec)[np.arange(lanes) % spec.n_runs].all())

    @numba.njit
    def _steps(work, count, rotate_first):  # pragma: no cover - compiled
        # the four stages of a step with the driver's flags (the state does not move: a = 0);
        # stage 1 rotates stage 4's angles or computes them in full
        for i in range(count):
            for st in range(4):
                stage(work, i * 1e-3, 0.0, 1.0, st == 0, st == 3, 1e-3,
                      st != 0 or rotate_first, st == 1 or st == 3, plain)

    @numba.njit
    def _screens(work, count):  # pragma: no cover - compiled
        for _ in range(count):
            screen(work)

    @numba.njit
    def _bounds(work, count):  # pragma: no cover - compiled
        for _ in range(count):
            cond_bound(work)

    def per_lane(fn, count: int, *extra) -> float:
        fn(work, 10, *extra)  # compile
        best = np.inf
        for _ in range(3):
            start = time.process_time()
            fn(work, count, *extra)
            best = min(best, time.process_time() - start)
        return best / count / lanes * 1e9

    t_rotated = per_lane(_steps, 5000, True)
    t_full = per_lane(_steps, 5000, False)
    resync = k.RESYNC_STEPS
    t_screen = per_lane(_screens, 20000)
    t_bound = per_lane(_bounds, 5000)
    period = max(1, opts.timing.period_steps)
    no_cam = dataclasses.replace(spec, options=dataclasses.replace(
        opts, camera=CameraModel(fps=1e-6)))
    no_cam = dataclasses.replace(no_cam, frame_step=spec.frame_step[:1],
                                 frame_fraction=spec.frame_fraction[:1],
                                 frame_time_s=spec.frame_time_s[:1])
    # the whole step, and the step without the generated physics (_driver_only_kernel), each
    # with and without the camera, interleaved (best of three each) so that all see the same
    # moments of the machine
    stub = _driver_only_kernel(batch, n, lanes, spec)
    best: dict[tuple[bool, bool], float] = {}
    for _ in range(3):
        for physics in (True, False):
            for camera in (True, False):
                start = time.process_time()
                res = batch.run_spec(spec if camera else no_cam, threads=1,
                                     kernel=k if physics else stub)
                wall = time.process_time() - start
                per_step = wall / float(res.final_step.sum()) * 1e9
                best[physics, camera] = min(best.get((physics, camera), np.inf), per_step)
    step = best[True, True]
    driver = best[False, False]
    camera_ns = best[False, True] - best[False, False]
    bound = t_bound / period
    stages = step - best[False, True] - t_screen - bound
    rows = [
        ("4 RK4 stages (generated; sin/cos, gait and PD, forces, O(N) recursion, RK4 sums)",
         stages),
        ("self-collision screen of x (generated)", t_screen),
        (f"condition-number bound, once per control period ({period} steps; generated)", bound),
        ("camera frames (Hermite pose, pixels, median filter, waypoints; per lane)", camera_ns),
        ("driver: control updates, checks, commit, block set-up (per lane)", driver),
    ]
    lines = ["| part | ns per run and step | share |", "|---|---|---|"]
    for name, value in rows:
        lines.append(f"| {name} | {value:.0f} | {value / step:.0%} |")
    lines.append(f"| whole step (measured here, one thread) | {step:.0f} | 100% |")
    lines.append("")
    lines.append(
        "The driver and the camera are timed in the run itself with the generated stage, screen "
        "and condition bound replaced by stubs (the state then stays put, so no lane stops "
        "early and no check fires); the stages are what the real run adds to that beyond the "
        "screen and the bound, which are timed alone. Timed alone, the four stages cost "
        f"{t_rotated:.0f} ns per run when every stage rotates the previous stage's sin and cos "
        f"and {t_full:.0f} ns when stage 1 computes them in full (one step in {resync}); the "
        f"condition-number bound {t_bound:.0f} ns per run when it is computed. CPU time of this "
        "one-thread process, best of three (on a machine loaded beyond its cores the wall clock "
        "would mostly measure the wait for a core)."
    )
    return lines


def _driver_only_kernel(batch: ModuleType, n_links: int, lanes: int, spec: Any) -> ModuleType:
    """The kernel module with the generated stage, screen and condition bound replaced by stubs.

    What is left of a step is the driver (control updates, checks, commit) and the camera; the
    state stays put (the stub stage only clears the rotation offset), so the runs go their full
    length without a failure. Written beside the real kernel, under its own module name.
    """
    source = batch.kernel_source(n_links, lanes, "numba", spec.fluid_law, spec.joint_model)
    generated = source.index("# ---- generated for N")
    stubs = {
        "_stage": (
            "def _stage(work, t_s, a, wk, first, last, sixth, rotate, advance, plain):\n"
            "    for r in range(LANES):\n"
            "        work[(WORK_ROWS + O_OFFSET) * LANES + r] = 0.0\n"
        ),
        "_screen": (
            "def _screen(work):\n"
            "    for r in range(LANES):\n"
            "        work[(WORK_ROWS + O_NEAR) * LANES + r] = 0.0\n"
        ),
        "_cond_bound": (
            "def _cond_bound(work):\n"
            "    for r in range(LANES):\n"
            "        work[(WORK_ROWS + O_COND_BOUND) * LANES + r] = 1.0\n"
        ),
    }
    for name, stub in stubs.items():
        start = source.index(f"def {name}(", generated)
        end = source.find("@numba.njit", start)
        end = len(source) if end < 0 else end
        source = source[:start] + stub + "\n\n" + source[end:]
    return batch.load_kernel_source(
        f"eelsim_batch_driver_only_n{n_links}_l{lanes}_{spec.joint_model.name}", source)
