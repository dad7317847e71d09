"""The estimation report: fit, validate, quantify uncertainty, and write everything to a folder.

Folder contents: ``coefficients.json`` (fits, uncertainty, identifiability), ``table4.md`` and
``table4.csv`` (validation errors, both definitions), ``fitness_history.png``, ``paths_*.png``,
``timeseries_*.png`` and ``report.md`` tying them together.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from eelhost.data.experiments import Dataset
from eelhost.estimation.adopt import fit_and_choose
from eelhost.estimation.clock import clock_check
from eelhost.estimation.coefficients_file import write_coefficients
from eelhost.estimation.diagnostics import fit_warnings
from eelhost.estimation.evaluate import Evaluator, simulations_counter
from eelhost.estimation.identify import Identifiability, identifiability
from eelhost.estimation.methods import FitSettings
from eelhost.estimation.neighbours import SANE_FACTOR
from eelhost.estimation.optimise import FitResult
from eelhost.estimation.pipeline import fit_motion
from eelhost.estimation.runs import ALIGN_S
from eelhost.estimation.selection import Workers, recommend
from eelhost.estimation.selection import table_markdown as comparison_markdown
from eelhost.estimation.shared_joints import share_joints
from eelhost.estimation.space import ParameterSpace
from eelhost.estimation.speeds import speed_errors, speeds_markdown
from eelhost.estimation.steering import steering_check
from eelhost.estimation.tank_current import share_tank_current
from eelhost.estimation.uncertainty import BootstrapResult, parametric_bootstrap
from eelhost.estimation.validate import (
    BAND_LEVEL,
    BAND_WIDEN,
    PredictionBand,
    ValidationRun,
    band_coverage,
    bands_markdown,
    ex_text,
    prediction_bands,
    table_csv,
    table_markdown,
    validate,
    worst_ex,
)
from eelhost.files import atomic_write
from eelhost.progress import phase

log = logging.getLogger(__name__)

Say = Callable[[str], None]


def run_report(
    dataset: Dataset,
    out: str | Path,
    motions: tuple[str, ...] = ("straight", "turning"),
    settings: FitSettings | None = None,
    bootstrap_replicates: int = 8,
    resume: bool = False,
    compare_models: bool = True,
    adopt_recommended: bool = True,
    laws: Sequence[str] | None = None,
    joint_models: Sequence[str] | None = None,
    say: Say | None = None,
    progress_factory: Callable[[str], Callable[[int, float, int], None]] | None = None,
) -> Path:
    """Run the whole chain on a dataset and write the report folder.

    Parameters
    ----------
    dataset : Dataset
    out : str or Path
        Report folder (created; checkpoints are kept there too).
    motions : tuple of str
        Fits to make: "straight", "turning" and/or "joint".
    settings : FitSettings, optional
    bootstrap_replicates : int
        Refits per motion for the uncertainty (0: skip).
    resume : bool
        Continue interrupted fits from their checkpoints.
    compare_models : bool
        Compare the candidate models (joint model x fluid law) by leave-one-gait-out
        cross-validation (:mod:`eelhost.estimation.selection`).
    adopt_recommended : bool
        When the comparison recommends another model than the robot file's, fit it and report
        and validate its fits (:mod:`eelhost.estimation.adopt`); the robot file's fits are kept
        in ``coefficients.json`` under ``robot_file_fits``.
    laws : sequence of str, optional
        Fluid laws the comparison tries (default:
        :func:`eelhost.estimation.selection.default_laws`, the twin's candidate laws and their lift
        variants).
    joint_models : sequence of str, optional
        Joint models the comparison tries (default: those offered by default and the robot
        file's, ``eelsim.joints.default_grid_models``).
    say : callable, optional
        Where progress messages go (default: this module's logger, at INFO).
    progress_factory : callable, optional
        Gives a per-generation progress callback for a fit, named by its motion (and by the
        model, for the fits of a model the comparison recommended).

    Returns
    -------
    Path
        ``report.md``.
    """
    say = say or log.info
    settings = settings or FitSettings()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    seconds: dict[str, float] = {}

    def said(motion: str, res: FitResult) -> None:
        say(
            f"{motion}, {res.space.model_name}: {res.method} fitness {res.fitness:.4f} after "
            f"{res.simulations} simulations: "
            + ", ".join(f"{n} {v:.4g}" for n, v in res.space.as_dict(res.values).items())
            + (f" (ambient current {res.model.current_text()})" if res.space.current else "")
        )

    def fit(motion: str, space: ParameterSpace | None,
            start: np.ndarray | None) -> tuple[FitResult, Evaluator]:
        t0 = time.perf_counter()
        label = motion if space is None else f"{motion}, {space.model_name}"
        prog = progress_factory(label) if progress_factory else None
        res, ev = fit_motion(dataset, motion, settings, checkpoint_dir=out, resume=resume,
                             progress=prog, space=space, start=start)
        seconds[motion] = seconds.get(motion, 0.0) + time.perf_counter() - t0
        said(motion, res)
        return res, ev

    def fit_many(asks: Sequence[tuple[str, ParameterSpace | None, np.ndarray | None]],
                 ) -> list[tuple[FitResult, Evaluator]]:
        # the motions' fits are independent: one per worker process (their generations'
        # progress is not shown then, only the stage's); each fit is the one made here
        # (docs/estimation_benchmarks.md, "Session 18: the main job's time")
        workers = Workers(settings.jobs, len(asks))
        if workers.jobs < 2:
            return [fit(*ask) for ask in asks]
        names = ", ".join(m for m, _, _ in asks)
        with phase(f"fits ({names})", simulations_counter()), workers:
            done = workers.map(_fit_task, [(dataset, m, settings, out, resume, space, start)
                                           for m, space, start in asks])
        for (motion, _, _), (res, _, took) in zip(asks, done, strict=True):
            seconds[motion] = seconds.get(motion, 0.0) + took
            said(motion, res)
        return [(res, ev) for res, ev, _ in done]

    chosen = fit_and_choose(dataset, motions, settings, compare_models, adopt_recommended,
                            fit=fit, say=say, laws=laws, joint_models=joint_models,
                            fit_many=fit_many)
    # one current for the tank, from both motions' experiments (estimation/tank_current.py)
    with phase("the tank's current from every training experiment", simulations_counter()):
        chosen.fits, chosen.evaluators, tank = share_tank_current(chosen.fits,
                                                                  chosen.evaluators, say)
    # one set of joint parameters for the robot (estimation/shared_joints.py)
    with phase("one set of joint parameters for both motions", simulations_counter()):
        chosen.fits, _ = share_joints(chosen.fits, chosen.evaluators, say)
    fits = chosen.fits
    extra: dict = {"model": chosen.model, "uncertainty": {}, "identifiability": {},
                   "simulations": {}, "seconds": seconds, "warnings": []}
    if tank is not None:
        extra["tank_current"] = tank.to_json()
    boots: dict[str, BootstrapResult] = {}
    # each fit's identifiability and bootstrap are independent of the others': one task per fit
    # in the comparison's worker processes, one per core, so that both cores work (a fit's
    # refits alone kept the second core idle for most of the bootstrap: much of it is
    # single-threaded Python, and its small batches fill one of numba's blocks;
    # docs/estimation_benchmarks.md, "Session 18: the main job's time"); the results are those
    # of the serial run (the kernel's runs do not depend on the thread count)
    tasks = [(chosen.evaluators[m], r.values, r.fitness, bootstrap_replicates, settings.seed,
              [o.values for n, o in fits.items() if n != m and o.space.names == r.space.names])
             for m, r in fits.items()]
    what = (f"bootstrap of the {', '.join(fits)} fits ({bootstrap_replicates} refits each)"
            if bootstrap_replicates > 0 else f"identifiability of the {', '.join(fits)} fits")
    with phase(what, simulations_counter()), Workers(settings.jobs, len(tasks)) as workers:
        done = workers.map(_uncertainty, tasks)
    for (motion, res), (ident, boot, took) in zip(fits.items(), done, strict=True):
        extra["simulations"][motion] = res.simulations
        extra["identifiability"][motion] = ident.to_json()
        if boot is not None:
            extra["uncertainty"][motion] = boot.to_json()
            boots[motion] = boot
            say(f"{motion}: noise floor {boot.noise_floor:.4f}, fitness / noise floor {boot.excess:.1f}")
        extra["warnings"] += fit_warnings(motion, res.space, res.values, boot)
        seconds[motion] = seconds.get(motion, 0.0) + took
    comparison = chosen.comparison
    choice = recommend(comparison) if comparison else None
    if comparison:
        extra["model_comparison"] = {
            "recommended": choice.model if choice else None,
            "adopted": chosen.adopted,
            "candidates": {c.model: {"parameters": c.parameters, "fitness": c.fitness,
                                     "held_out": {m: v.tolist() for m, v in c.held_out.items()},
                                     "failed": c.failed, "screened_out": c.screened_out,
                                     "middle_rung": c.middle_rung,
                                     "between_training_gaits": {
                                         m: v if np.isfinite(v) else None
                                         for m, v in c.between.items()}}
                           for c in comparison},
        }
    tests = dataset.held_out
    if chosen.robot_file_fits:
        with phase("validation of the robot file's model on the held-out experiments",
                   simulations_counter()):
            own_runs = validate(dataset.robot,
                                {m: r.model for m, r in chosen.robot_file_fits.items()},
                                tests, backend=settings.backend)
        extra["robot_file_fits"] = {
            "fits": {m: r.to_json() for m, r in chosen.robot_file_fits.items()},
            "worst_Ex_unaligned_BL": worst_ex(own_runs),
        }
    if dataset.truth:
        extra["truth"] = {m: c.model_dump() for m, c in dataset.truth.items()}
    with phase("validation on the held-out experiments", simulations_counter()):
        runs = validate(dataset.robot, {m: r.model for m, r in fits.items()}, tests,
                        backend=settings.backend)
    with phase("prediction bands of the held-out experiments", simulations_counter()):
        bands = prediction_bands(dataset.robot, {m: r.model for m, r in fits.items()},
                                 {m: b.ensemble(fits[m].space.bounds) for m, b in boots.items()},
                                 {m: b.growth for m, b in boots.items()}, tests,
                                 backend=settings.backend,
                                 dof={m: b.growth_dof for m, b in boots.items()})
    if bands:
        extra["prediction_band"] = {
            "level": BAND_LEVEL, "widen": BAND_WIDEN, "coverage": band_coverage(bands),
            "experiments": {b.name: {"coverage": b.coverage, "radius_m": b.radius_m.tolist()}
                            for b in bands},
        }
    clock = clock_check(runs)  # offsets at their bound absorb misfit (estimation/clock.py)
    extra["clock_offsets_at_bound"] = list(clock.at_bound)
    extra["warnings"] += [w for w in [clock.warning()] if w]
    # a held-out run that steers harder than any training run extrapolates (estimation/steering.py)
    steering = steering_check(dataset, tests)
    extra["steering_beyond_training"] = {"training_rad": steering.training_rad
                                         if np.isfinite(steering.training_rad) else None,
                                         "held_out_rad": steering.beyond_rad}
    extra["warnings"] += [w for w in [steering.warning()] if w]
    write_coefficients(out / "coefficients.json", fits, extra, robot=dataset.robot)
    atomic_write(out / "table4.md", table_markdown([r.row for r in runs]) + "\n")
    atomic_write(out / "table4.csv", table_csv([r.row for r in runs]))
    # matplotlib only now: importing it costs half a second of every command's start
    from eelhost.estimation.figures import plot_fitness_history, plot_validation

    plot_fitness_history(fits, out / "fitness_history.png")
    plot_validation(runs, out)
    report = out / "report.md"
    text = _report_text(dataset, fits, extra, runs, settings)
    if bands:
        text += _bands_text(bands, extra["prediction_band"]["coverage"],
                            dataset.robot.body_length_m())
    if comparison:
        verdict = (
            "Recommended: none: every candidate failed, so the robot file's model was fitted."
            if choice is None else
            f"Recommended: **{choice.model}** (lowest mean held-out error of the candidates "
            "that stay sane between their training gaits; within 2 % or one standard error of "
            "the folds the model with fewer parameters)"
            + ("; adopted: the fits above are its own." if chosen.adopted else
               "." if choice.model == chosen.model else
               f"; not adopted (`--keep-model`): the fits above are {chosen.model}'s."))
        text += "\n".join([
            "",
            "## Candidate models (leave-one-gait-out cross-validation)",
            "",
            "Each training gait held out in turn: the model refitted on the others, scored on it "
            "(the fitness's per-experiment error, m; docs/estimation.md, \"Model comparison\")."
            " Between training gaits: how far the candidate's mean speed at the gaits between its"
            " training gaits leaves the recorded speeds around them (x1.00: inside; more than"
            f" x{SANE_FACTOR:g}: not sane, not recommended while a sane candidate ran)."
            + (" Every candidate was first screened with a short search; those marked screened "
               "out were dropped there, and their figures are the screen's."
               if any(c.screened_out for c in comparison) else "")
            + (" Those marked stopped at the middle rung passed the screen only as their "
               "family's or joint model's best and were dropped after a medium search; their "
               "figures are that search's."
               if any(c.middle_rung for c in comparison) else ""),
            "",
            comparison_markdown(comparison),
            "",
            verdict,
            "",
        ])
    atomic_write(report, text)  # whole or not at all (eelhost.files)
    say(f"wrote {report}")
    return report


def _fit_task(
    dataset: Dataset, motion: str, settings: FitSettings, out: Path, resume: bool,
    space: ParameterSpace | None, start: np.ndarray | None,
) -> tuple[FitResult, Evaluator, float]:
    """One fit with the full method (its checkpoint in ``out``), and the seconds it took.

    A task of :class:`eelhost.estimation.selection.Workers`.
    """
    t0 = time.perf_counter()
    res, ev = fit_motion(dataset, motion, settings, checkpoint_dir=out, resume=resume,
                         space=space, start=start)
    return res, ev, time.perf_counter() - t0


def _uncertainty(
    ev: Evaluator, values: np.ndarray, fitness: float, replicates: int, seed: int,
    starts: list[np.ndarray],
) -> tuple[Identifiability, BootstrapResult | None, float]:
    """One fit's identifiability and bootstrap (``replicates`` 0: none), and the seconds taken.

    ``starts``: the other fits of the same space, where the bootstrap looks for other valleys.
    A task of :class:`eelhost.estimation.selection.Workers`.
    """
    t0 = time.perf_counter()
    ident = identifiability(ev, values)
    boot = None
    if replicates > 0:
        boot = parametric_bootstrap(ev, values, fitness, replicates, seed=seed,
                                    unidentified=ident.unidentified(),
                                    linear_std=ident.std_error, starts=starts)
    return ident, boot, time.perf_counter() - t0


def _bands_text(bands: list[PredictionBand], coverage: dict[str, float], bl_m: float) -> str:
    """The report's section on the held-out experiments' prediction bands."""
    return "\n".join([
        "## Prediction bands of the held-out experiments",
        "",
        f"{BAND_LEVEL * 100:.0f} % bands around each prediction: the spread of the bootstrap's "
        "refits swum on the held-out task plus the misfit's growth along a recording (each "
        "training experiment against the fit without it; docs/estimation.md, \"Prediction "
        "bands\"). Positions inside their band, on the "
        "recordings' own clocks: "
        + ", ".join(f"{m} {v * 100:.0f} %" for m, v in coverage.items()) + ".",
        "",
        bands_markdown(bands, bl_m),
        "",
    ])


def _report_text(
    dataset: Dataset,
    fits: dict[str, FitResult],
    extra: dict,
    runs: list[ValidationRun],
    settings: FitSettings,
) -> str:
    lines = [
        "# Estimation report",
        "",
        f"Dataset: `{dataset.folder}` ({dataset.manifest.get('description', '')})",
        "",
    ]
    names = next(iter(fits.values())).space.names
    lines += ["## Model", "", f"Fitted: **{extra['model']}** (joint model x fluid law)."]
    own = extra.get("robot_file_fits")
    if own:
        first = next(iter(own["fits"].values()))
        lines += [
            "",
            f"The robot file's model is {first['joint_model']} x {first['law']}; the "
            "leave-one-gait-out comparison of every candidate, each fitted from its own starts "
            "(end of this report), recommends another model, so that model was fitted and its "
            "fits are the ones below, validated and written to `coefficients.json` "
            "(docs/estimation.md, \"Model choice\"). The robot file's model's fits, kept under "
            "`robot_file_fits`, for comparison:",
            "",
            "| fit | fitness (robot file's model) | fitness (fitted model) |",
            "|---|---|---|",
        ]
        lines += [f"| {m} | {f['fitness']:.4f} | "
                  + (f"{fits[m].fitness:.4f} |" if m in fits else "- |")
                  for m, f in own["fits"].items()]
        lines += [f"| {m} | - | {r.fitness:.4f} |" for m, r in fits.items()
                  if m not in own["fits"]]
        lines += [""] + [f"- worst held-out E_x ({m}), recorded clock, with the robot file's "
                         f"model: {v:.4f} BL" for m, v in own["worst_Ex_unaligned_BL"].items()]
    lines += [
        "",
        "## Fitted coefficients",
        "",
        "| fit | method | fitness | simulations | " + " | ".join(names) + " |",
        "|---|---|---|---|" + "---|" * len(names),
    ]
    currents = [f"{m}: {r.model.current_text()}" for m, r in fits.items() if r.space.current]
    for m, r in fits.items():
        unc = extra["uncertainty"].get(m, {})
        lo, hi = unc.get("lower", {}), unc.get("upper", {})
        vals = [
            f"{v:.4g}" + (f" [{lo[n]:.3g}, {hi[n]:.3g}]" if n in lo else "")
            for n, v in zip(names, r.values, strict=True)
        ]
        lines.append(
            f"| {m} | {r.method} | {r.fitness:.4f} | {extra['simulations'][m]} | "
            + " | ".join(vals)
            + " |"
        )
    if currents:
        lines += [
            "",
            "Ambient current of the tank, fitted as a nuisance shared by a fit's experiments and "
            "added to the current each declares (docs/estimation.md, \"Nuisance parameters\"); "
            "validation simulates in it: " + "; ".join(currents) + ".",
        ]
    tank = extra.get("tank_current")
    if tank:
        alone = "; ".join(
            f"{m} {1e3 * np.hypot(*c):.1f} mm/s towards {np.degrees(np.arctan2(c[1], c[0])):.0f} deg"
            for m, c in tank["per_motion_alone"].items())
        lines += [
            "",
            f"One current for the tank, estimated from all {tank['experiments']} training "
            f"experiments together: "
            + ("" if tank.get("resolved", True) else
               "no current resolved (still water lies inside its 95 % confidence ellipse): ")
            + f"{tank['speed_m_s']:.4f} m/s towards "
            f"{tank['direction_deg']:.0f} deg (the 95 % ellipse's interval +-"
            f"{1e3 * tank['half_width_m_s'][0]:.1f} mm/s in v_x, "
            f"+-{1e3 * tank['half_width_m_s'][1]:.1f} mm/s in v_y"
            + (f", widened {tank['misfit_scale']:.1f} times because the motions' own currents "
               "disagree beyond their intervals: the model's misfit"
               if tank.get("misfit_scale", 1.0) > 1.0 else "")
            + "); each fit holds it within "
            f"that interval. Each motion's fit alone had found: {alone}.",
        ]
    if "truth" in extra:
        lines += [
            "",
            "Truth (virtual tank): "
            + "; ".join(
                f"{m}: " + ", ".join(f"{k} {v:g}" for k, v in c.items())
                for m, c in extra["truth"].items()
            ),
        ]
        for m, r in fits.items():
            t = dataset.truth.get(m)
            if t is not None and type(t).law_name != r.space.law.name:
                # the tank's water follows another law: its coefficients are not these
                lines.append(f"- {m}: the truth is in the {type(t).law_name} law, the fit in "
                             f"{r.space.law.name}: no coefficient-by-coefficient comparison")
            elif t is not None:
                rel = (r.coefficients.as_array() - t.as_array()) / np.where(
                    t.as_array() > 0, t.as_array(), 1
                )
                lines.append(
                    f"- {m}: relative error "
                    + ", ".join(f"{n} {e * 100:+.1f} %"
                                for n, e in zip(r.space.coefficient_names, rel, strict=True))
                )
    if extra["uncertainty"]:
        u = next(iter(extra["uncertainty"].values()))
        lines += [
            "",
            f"[low, high]: {u['level'] * 100:.0f} % intervals from two bootstraps: "
            f"{u['replicates']} data sets regenerated from the fit with the dataset's declared "
            "noise (their spread widened by the fit's excess over its noise floor), and "
            f"{u.get('misfit_replicates', 0)} made of the fit's noise-free view plus each "
            "training experiment's residual curve against the fit without it, reweighted per "
            "experiment (a wild cluster bootstrap: what the model misses, whatever its cause); "
            "the wider sets the interval, never narrower than the linearised standard error, "
            f"times the measured factor {u['widen']:g}; then grown to hold every other valley "
            "and point that fits the recordings within what the noise lets a refit gain (the "
            "recordings refitted from the other motions' fits and from starts spread over the "
            "bounds; docs/estimation.md, \"Uncertainty\").",
            "",
            "| fit | noise floor | fitness / noise floor | intervals set by the misfit | "
            "not identified (another valley fits within the noise; intervals span both) |",
            "|---|---|---|---|---|",
        ]
        lines += [f"| {m} | {u['noise_floor']:.4f} | {u['excess']:.1f} | "
                  + (", ".join(u.get("misfit_dominated", [])) or "none") + " | "
                  + (", ".join(u.get("valleys", {}).get("not_identified", [])) or "none") + " |"
                  for m, u in extra["uncertainty"].items()]
    lines += ["", "## Warnings", ""]
    lines += [f"- {w}" for w in extra["warnings"]] or ["None."]
    lines += [
        "",
        "## What the data pins down",
        "",
        "Linearised at the estimate (local sensitivities; not intervals: see above).",
        "",
    ]
    for m, ident in extra["identifiability"].items():
        lines.append(
            f"- **{m}**: "
            + "; ".join(
                f"{n} {ident['verdict'][n]} (rel. std. error {ident['rel_std_error'][n]:.2g})"
                for n in names
            )
        )
    lines += [
        "",
        "## Validation on held-out experiments",
        "",
        "E_x and E_v as the paper defines them (mean of norms over n = 35 samples, which the paper "
        "calls RMS) and as true RMS, in body lengths (BL) and BL/s.",
        "",
    ]
    lines += [f"- worst E_x ({m}): {ex_text(v)} BL" for m, v in worst_ex(runs, aligned=True).items()]
    clock = clock_check(runs)
    if runs:  # validation reports the best clock offset besides the recorded clock
        lines.append(
            f"\nEach experiment is compared at the clock offset of its recording that fits best "
            f"(searched within {clock.bound_text()}, the time-stamp uncertainty the recordings "
            f"declare; {ALIGN_S:g} s where they declare none). "
            "On the recordings' own clocks:" if clock.total else
            "\nThe recordings declare exact time stamps (camera.timestamp_jitter_s 0): each "
            "experiment is compared on its own clock only:"
        )
        lines += [f"- worst E_x ({m}), recorded clock: {ex_text(v)} BL"
                  for m, v in worst_ex(runs).items()]
    lines += [
        "",
        table_markdown([r.row for r in runs]),
        "",
        "Mean speed per gait (the metric of Kelasidi et al., IEEE RAM 2016: the distance along "
        "the sampled path over the recorded span, recording and prediction on the recording's "
        "clock; docs/estimation.md, \"Validation\"):",
        "",
        speeds_markdown(speed_errors(runs)),
        "",
        "Figures: `fitness_history.png`, `paths_straight.png`, `paths_turning.png`, `paths_path.png`, "
        "`timeseries_path1.png`, `timeseries_path2.png`.",
        "",
    ]
    return "\n".join(lines)
