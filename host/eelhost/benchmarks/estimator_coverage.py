"""Do the report's intervals and bands hold? ``eelbot estimate-bench --coverage N``, ``--bands``.

**Coefficient intervals** (:func:`measure_coverage`): over N seeds of a synthetic tank whose model
contains the truth (the paper's law and joints, table 3's straight row, the bundled dataset's
noise: clock offsets up to 0.1 s, control jitter, pixel rounding, causal median; or a named
plant whose law is a candidate, e.g. ``steady_current``, ``centred_median``), each seed records
the four training gaits of the straight fit, fits them with the default method, and computes the
report's intervals (:func:`eelhost.estimation.uncertainty.parametric_bootstrap`). Coverage is
the fraction of seeds whose interval holds the truth, per coefficient; the target is at least
90 % for 95 % intervals. :func:`needed_widening` is the smallest extra factor on the half-widths
that would have reached the target on these seeds: the value ``uncertainty.WIDEN`` is set to.

With ``motions=("straight", "turning")`` each seed records both motions' training gaits and is
treated as the report treats a dataset: each motion fitted, the tank's one current estimated from
both (:func:`eelhost.estimation.tank_current.share_tank_current`) and held by each motion's fit,
and the held fits bootstrapped. Those are the intervals ``eelbot report`` gives; the straight
tank alone fits its own current. Each fit is given the other motions' fits as starts for the search of
other valleys, as in the report. Beside each coverage the table gives the local intervals'
(the bootstrap around the estimate alone, before the search widened them: the same fits and
refits) and how many seeds' reports said the parameter is not identified.

**Prediction bands** (:func:`measure_bands`): for each named plant (typically one whose law is
no candidate), the virtual tank records the paper's 34 experiments, ``eelbot report`` runs on
them (straight and turning fits, bootstrap, validation), and the fraction of held-out positions
inside their 95 % bands is read from its ``coefficients.json``; the target is at least 90 % on
at least two mismatched plants.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eelhost.data.plants import PLANTS, Plant
from eelhost.data.virtual_tank import (
    TABLE3,
    TankSettings,
    generate_dataset,
    paper_experiment_plan,
    record_experiment,
    true_robot,
)
from eelhost.estimation.coefficients_file import (
    prediction_band_coverage,
    read_coefficients_file,
    reported_uncertainty,
)
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.identify import identifiability
from eelhost.estimation.methods import FitProblem, FitSettings, run_fit
from eelhost.estimation.space import ParameterSpace
from eelhost.estimation.uncertainty import WIDEN, BootstrapResult, parametric_bootstrap
from eelsim.robot import Robot, load_robot

log = logging.getLogger(__name__)

TARGET = 0.90
MOTION = "straight"


@dataclass(frozen=True)
class Intervals:
    """One seed's estimates and intervals (of one fit, or of several side by side).

    Attributes
    ----------
    estimate, lower, upper : ndarray, shape (K,)
    split : ndarray of bool, shape (K,), optional
        Where the report says the parameter is not identified: another valley fits within the
        noise (:meth:`BootstrapResult.not_identified`).
    local_lower, local_upper : ndarray, shape (K,), optional
        The intervals of the bootstrap around the estimate alone, before other valleys widened
        them.
    """

    estimate: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    split: np.ndarray | None = None
    local_lower: np.ndarray | None = None
    local_upper: np.ndarray | None = None

    @classmethod
    def of(cls, boots: Sequence[BootstrapResult]) -> Intervals:
        """The fits' intervals one after the other, in the order given."""
        def joined(f: str) -> np.ndarray:
            return np.concatenate([getattr(b, f) for b in boots])

        return cls(joined("estimate"), joined("lower"), joined("upper"),
                   np.concatenate([b.split.astype(bool) if len(b.split) == len(b.estimate)
                                   else np.zeros(len(b.estimate), bool) for b in boots]),
                   *(np.concatenate([getattr(b, f) if len(getattr(b, f)) == len(b.estimate)
                                     else getattr(b, f.split("_")[1]) for b in boots])
                     for f in ("local_lower", "local_upper")))

    def covers(self, truth: np.ndarray) -> np.ndarray:
        """Whether each interval holds the true value."""
        t = np.asarray(truth, dtype=float)
        return (self.lower <= t) & (t <= self.upper)


@dataclass
class Coverage:
    """Coverage of the intervals over seeds.

    Attributes
    ----------
    names : tuple of str
        The parameters ("<motion> <name>" when several motions are fitted).
    truth : ndarray, shape (K,)
    results : list of Intervals
        One per seed.
    motions : tuple of str
        The motions fitted.
    """

    names: tuple[str, ...]
    truth: np.ndarray
    results: list[Intervals]
    motions: tuple[str, ...] = (MOTION,)

    def covered(self) -> np.ndarray:
        """Whether each seed's interval holds the truth, shape (seeds, K)."""
        return np.array([r.covers(self.truth) for r in self.results])

    def rate(self) -> np.ndarray:
        """Fraction of seeds covered, per parameter."""
        return self.covered().mean(axis=0)

    def local_rate(self) -> np.ndarray:
        """Fraction of seeds the bootstrap around the estimate alone covered, per parameter."""
        return np.array([(r.local_lower <= self.truth) & (self.truth <= r.local_upper)
                         if r.local_lower is not None and r.local_upper is not None
                         else r.covers(self.truth) for r in self.results]).mean(axis=0)

    def flagged(self) -> np.ndarray:
        """Seeds whose report says the parameter is not identified (other valleys), per parameter."""
        return np.sum([r.split if r.split is not None else np.zeros(len(self.names), bool)
                       for r in self.results], axis=0)

    def needed_widening(self, target: float = TARGET) -> np.ndarray:
        """Per parameter, the factor on the half-widths that covers ``target`` of the seeds.

        The half-width each seed would have needed (|estimate - truth| over its half-width, the
        interval's centre being the estimate), at the ``target`` quantile; at least 1.
        """
        ratio = np.array([
            np.abs(r.estimate - self.truth) / np.maximum((r.upper - r.lower) / 2, 1e-300)
            for r in self.results
        ])
        return np.maximum(1.0, np.quantile(ratio, target, axis=0))


def measure_coverage(
    seeds: int,
    first_seed: int = 0,
    replicates: int = 8,
    settings: FitSettings | None = None,
    say: Callable[[str], None] | None = None,
    plant: Plant | None = None,
    robot_file: str | None = None,
    motions: Sequence[str] = (MOTION,),
) -> Coverage:
    """The intervals' coverage over ``seeds`` synthetic tanks (module docstring).

    Parameters
    ----------
    seeds : int
    first_seed : int
        Tanks use seeds first_seed, first_seed + 1, ...
    replicates : int
        Bootstrap refits per fit (the report's default).
    settings : FitSettings, optional
        The fit (default: the default method with seed = the tank's).
    say : callable, optional
        Gets a line per seed.
    plant : Plant, optional
        A named plant whose model the fitted one contains (default: the bundled tank's noise).
    robot_file : str, optional
        The robot file whose model is fitted (default: the paper's); the tank is recorded from
        the paper robot with the plant's differences either way (``stiff_servos`` with the
        servo file: its joints are that file's, so the servo model contains the truth, its
        fitted joint parameters included).
    motions : sequence of str
        The motions recorded and fitted ("straight", "turning"); with both, the tank's one
        current is shared and held by each fit, as in ``eelbot report``.

    Returns
    -------
    Coverage
    """
    from eelhost.estimation.tank_current import share_tank_current

    recorder = load_robot()
    robot = load_robot(robot_file) if robot_file else recorder
    tank = plant.settings if plant is not None else TankSettings()
    truths = plant.truths() if plant is not None else TABLE3
    # the fit's parameters (with the ambient current when the settings fit it: still water here)
    space = ParameterSpace.for_robot(robot, current=(settings or FitSettings()).fit_current)
    several = len(motions) > 1
    names = tuple(f"{m} {n}" if several else n for m in motions for n in space.names)
    truth = np.concatenate([coverage_truth(space, plant, recorder, m) for m in motions])
    gaits = {m: [s for motion, split, s in paper_experiment_plan()
                 if motion == m and split == "train"] for m in motions}
    results = []
    for k in range(seeds):
        seed = first_seed + k
        fit_settings = settings or FitSettings(seed=seed)
        fits, evs = {}, {}
        for j, m in enumerate(motions):
            # the straight gaits keep the seeds they had when only they were measured
            exps = [record_experiment(recorder, s, m, truths[m], tank,
                                      seed=1000 * seed + 100 * j + i)
                    for i, s in enumerate(gaits[m])]
            evs[m] = Evaluator(robot, exps, backend=fit_settings.backend,
                               align_s=fit_settings.align_s, space=space)
            fits[m] = run_fit(FitProblem(evs[m], fit_settings, space.start(robot)))
        if several:
            fits, evs, _ = share_tank_current(fits, evs)
        boots = []
        for m in motions:
            ident = identifiability(evs[m], fits[m].values)
            # the other motions' fits are starts for the search of other valleys, as in the
            # report
            others = [fits[o].values for o in motions
                      if o != m and len(fits[o].values) == len(fits[m].values)]
            boots.append(parametric_bootstrap(evs[m], fits[m].values, fits[m].fitness,
                                              replicates, seed=seed,
                                              unidentified=ident.unidentified(),
                                              linear_std=ident.std_error, starts=others))
        got = Intervals.of(boots)
        results.append(got)
        line = (f"seed {seed}: " + ", ".join(
            f"{n} {v:.4g} [{lo:.4g}, {hi:.4g}] (local [{llo:.4g}, {lhi:.4g}])"
            f"{' (valleys)' if sp else ''}{'' if c else ' MISSED'}"
            for n, v, lo, hi, llo, lhi, sp, c in zip(
                names, got.estimate, got.lower, got.upper,
                got.local_lower if got.local_lower is not None else got.lower,
                got.local_upper if got.local_upper is not None else got.upper,
                got.split if got.split is not None else np.zeros(len(names), bool),
                got.covers(truth), strict=True)))
        log.info("%s", line)
        if say:
            say(line)
    return Coverage(names, truth, results, tuple(motions))


def coverage_truth(space: ParameterSpace, plant: Plant | None, recorder: Robot,
                   motion: str = MOTION) -> np.ndarray:
    """The true point of ``space`` for a ``motion`` tank of ``plant`` recorded from ``recorder``.

    The law's truth for that motion, the plant's own joint parameters where the space fits them
    (the servo model's lag and motor time constant on ``stiff_servos``), and the tank's steady
    current where the space has one (still water when the plant's current is drawn anew per
    experiment, which has no one true value).
    """
    tank = plant.settings if plant is not None else TankSettings()
    true = plant.truths()[motion] if plant is not None else TABLE3[motion]
    current = np.zeros(len(space.current_names))
    if space.current_names and tank.stray_current_direction_deg is not None:
        a = np.radians(tank.stray_current_direction_deg)
        current = tank.stray_current_m_s * np.array([np.cos(a), np.sin(a)])
    body = space.vector(true.as_array(), true_robot(recorder, tank))
    return np.concatenate([body[: space.size - len(current)], current])


def coverage_markdown(cov: Coverage, seeds_command: str, tank: str = "bundled noise") -> str:
    """The coverage as a markdown section."""
    rate = cov.rate()
    need = cov.needed_widening()
    what = (f"{' and '.join(cov.motions)} tank" if len(cov.motions) > 1
            else f"{cov.motions[0]} tank") + (
        " (the tank's one current, held by each fit)" if len(cov.motions) > 1 else "")
    lines = [
        f"## Coverage of the report's 95 % intervals: {tank}",
        "",
        f"`{seeds_command}`: {len(cov.results)} seeds of a {what} whose model contains the "
        f"truth ({tank}), intervals with the widening factor {WIDEN:g} in use. Target: "
        f"the truth inside in at least {TARGET * 100:.0f} % of the seeds.",
        "",
        "| parameter | coverage | factor needed for 90 % | coverage around the estimate alone "
        "(before other valleys) | seeds said not identified (other valleys fit alike) |",
        "|---|---|---|---|---|",
    ]
    lines += [f"| {n} | {r * 100:.0f} % | {f:.2f} | {lr * 100:.0f} % | {g} of "
              f"{len(cov.results)} |"
              for n, r, f, lr, g in zip(cov.names, rate, need, cov.local_rate(), cov.flagged(),
                                        strict=True)]
    lines.append("")
    return "\n".join(lines)


@dataclass
class BandCoverage:
    """One plant's prediction bands, as its report measured them.

    Attributes
    ----------
    plant : str
    coverage : dict of str to float
        Fraction of held-out positions inside their bands, per motion type and "all".
    excess : dict of str to float
        Each fit's fitness over its noise floor.
    seconds : float
        The report's wall time.
    model : str
        The fitted model (the robot file's, or the one the report's comparison chose).
    clock_at_bound : int
        Held-out experiments whose best clock offset sits at the validation's bound.
    held_out : int
        Held-out experiments and paths.
    """

    plant: str
    coverage: dict[str, float]
    excess: dict[str, float]
    seconds: float
    model: str = ""
    clock_at_bound: int = 0
    held_out: int = 0


def measure_bands(
    plants: Sequence[str],
    work: Path,
    robot_file: str | None = None,
    seed: int = 0,
    replicates: int = 8,
    say: Callable[[str], None] | None = None,
    compare: bool = False,
) -> list[BandCoverage]:
    """Band coverage of held-out positions on named plants (module docstring).

    Parameters
    ----------
    plants : sequence of str
        Names of test plants (:data:`eelhost.data.plants.PLANTS`).
    work : Path
        Folder of the generated datasets and reports (a dataset already there is reused).
    robot_file : str, optional
        The datasets' robot file (default: the paper's); without ``compare`` the report fits its
        model.
    seed : int
        Seed of the recordings and the fits.
    replicates : int
        Bootstrap refits per fit.
    say : callable, optional
        Gets a line per plant.
    compare : bool
        Run the report's model comparison (its default) and measure the bands of the model it
        chooses, which misfits the plant less than the robot file's: narrower bands, the
        harder test.

    Returns
    -------
    list of BandCoverage
    """
    import time

    from eelhost.data.experiments import load_dataset
    from eelhost.estimation.report import run_report

    robot = load_robot(robot_file) if robot_file else load_robot()
    out = []
    for name in plants:
        plant = PLANTS[name]
        folder = work / f"{name}-seed{seed}"
        if not (folder / "manifest.toml").exists():
            generate_dataset(folder, robot, plant.truths(), plant.settings, seed)
        t0 = time.perf_counter()
        report_dir = work / (f"{name}-seed{seed}-report" + ("-chosen" if compare else ""))
        run_report(load_dataset(folder), report_dir, settings=FitSettings(seed=seed),
                   bootstrap_replicates=replicates, compare_models=compare)
        seconds = time.perf_counter() - t0
        path = report_dir / "coefficients.json"
        data = read_coefficients_file(path)
        excess = {m: u.excess if u.excess is not None else float("nan")
                  for m, u in reported_uncertainty(data).items()}
        band = BandCoverage(name, prediction_band_coverage(data, path), excess, seconds,
                            str(data.get("model", "")), len(data.get("clock_offsets_at_bound", [])),
                            len(data.get("prediction_band", {}).get("experiments", {})))
        out.append(band)
        line = (f"{name}: held-out positions inside their 95 % bands: "
                + ", ".join(f"{m} {v * 100:.0f} %" for m, v in band.coverage.items())
                + "; fitness / noise floor " + ", ".join(f"{m} {v:.1f}"
                                                         for m, v in band.excess.items())
                + f"; model {band.model}; best clock offsets at the bound: "
                f"{band.clock_at_bound} of {band.held_out}; report {seconds:.0f} s")
        log.info("%s", line)
        if say:
            say(line)
    return out


def bands_markdown(bands: Sequence[BandCoverage], command: str) -> str:
    """The band coverage as a markdown section."""
    motions = sorted({m for b in bands for m in b.coverage if m != "all"}) + ["all"]
    lines = [
        "## Coverage of the report's 95 % prediction bands",
        "",
        f"`{command}`: held-out positions (on the recordings' own clocks) inside their bands. "
        f"Target: at least {TARGET * 100:.0f} % on at least two mismatched plants.",
        "",
        "| plant | model | " + " | ".join(motions) + " | fitness / noise floor | best clock "
        "offsets at the bound |",
        "|---|---|" + "---|" * len(motions) + "---|---|",
    ]
    lines += [f"| {b.plant} | {b.model} | " + " | ".join(
        f"{b.coverage[m] * 100:.0f} %" if m in b.coverage else "" for m in motions)
        + " | " + ", ".join(f"{m} {v:.1f}" for m, v in b.excess.items())
        + f" | {b.clock_at_bound} of {b.held_out} |" for b in bands]
    lines.append("")
    return "\n".join(lines)
