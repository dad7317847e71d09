"""Do the report's intervals hold? ``eelbot estimate-bench --coverage N``.

Over N seeds of a synthetic tank whose model contains the truth (the paper's law and joints,
table 3's straight row, the bundled dataset's noise: clock offsets up to 0.1 s, control jitter,
pixel rounding, causal median), each seed records the four training gaits of the straight fit,
fits them with the default method, and computes the report's intervals
(:func:`eelhost.estimation.uncertainty.parametric_bootstrap`). Coverage is the fraction of seeds
whose interval holds the truth, per coefficient; the target is at least 90 % for 95 % intervals.
:func:`needed_widening` is the smallest extra factor on the half-widths that would have reached
the target on these seeds: the value ``uncertainty.WIDEN`` is set to.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from eelhost.data.virtual_tank import (
    TABLE3,
    TankSettings,
    paper_experiment_plan,
    record_experiment,
)
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.identify import identifiability
from eelhost.estimation.methods import FitProblem, run_fit
from eelhost.estimation.parameters import ParameterSpace
from eelhost.estimation.pipeline import FitSettings
from eelhost.estimation.uncertainty import WIDEN, BootstrapResult, parametric_bootstrap
from eelsim.robot import load_robot

log = logging.getLogger(__name__)

TARGET = 0.90
MOTION = "straight"


@dataclass
class Coverage:
    """Coverage of the intervals over seeds.

    Attributes
    ----------
    names : tuple of str
    truth : ndarray, shape (K,)
    results : list of BootstrapResult
        One per seed.
    """

    names: tuple[str, ...]
    truth: np.ndarray
    results: list[BootstrapResult]

    def covered(self) -> np.ndarray:
        """Whether each seed's interval holds the truth, shape (seeds, K)."""
        return np.array([r.covers(self.truth) for r in self.results])

    def rate(self) -> np.ndarray:
        """Fraction of seeds covered, per parameter."""
        return self.covered().mean(axis=0)

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

    Returns
    -------
    Coverage
    """
    robot = load_robot()
    # the fit's parameters (with the ambient current when the settings fit it: still water here)
    space = ParameterSpace.for_robot(robot, current=(settings or FitSettings()).fit_current)
    truth = np.concatenate([TABLE3[MOTION].as_array(), np.zeros(len(space.current_names))])
    gaits = [s for motion, split, s in paper_experiment_plan()
             if motion == MOTION and split == "train"]
    results = []
    for k in range(seeds):
        seed = first_seed + k
        exps = [record_experiment(robot, s, MOTION, TABLE3[MOTION], TankSettings(),
                                  seed=1000 * seed + i)
                for i, s in enumerate(gaits)]
        fit_settings = settings or FitSettings(seed=seed)
        ev = Evaluator(robot, exps, backend=fit_settings.backend, align_s=fit_settings.align_s,
                       space=space)
        res = run_fit(FitProblem(ev, fit_settings, space.start(robot)))
        boot = parametric_bootstrap(ev, res.values, res.fitness, replicates, seed=seed,
                                    unidentified=identifiability(ev, res.values).unidentified())
        results.append(boot)
        line = (f"seed {seed}: " + ", ".join(
            f"{n} {v:.4g} [{lo:.4g}, {hi:.4g}]{'' if c else ' MISSED'}"
            for n, v, lo, hi, c in zip(space.names, boot.estimate, boot.lower, boot.upper,
                                       boot.covers(truth), strict=True)))
        log.info("%s", line)
        if say:
            say(line)
    return Coverage(space.names, truth, results)


def coverage_markdown(cov: Coverage, seeds_command: str) -> str:
    """The coverage as a markdown section."""
    rate = cov.rate()
    need = cov.needed_widening()
    lines = [
        "## Coverage of the report's 95 % intervals",
        "",
        f"`{seeds_command}`: {len(cov.results)} seeds of a straight tank whose model contains the "
        f"truth (bundled noise), intervals with the widening factor {WIDEN:g} in use. Target: "
        f"the truth inside in at least {TARGET * 100:.0f} % of the seeds.",
        "",
        "| parameter | coverage | factor needed for 90 % |",
        "|---|---|---|",
    ]
    lines += [f"| {n} | {r * 100:.0f} % | {f:.2f} |"
              for n, r, f in zip(cov.names, rate, need, strict=True)]
    lines.append("")
    return "\n".join(lines)
