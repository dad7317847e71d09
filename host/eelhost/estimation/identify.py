"""Which coefficients the data pins down, and how uncertain each fitted value is.

Two complementary answers:

- **Local identifiability** from the Jacobian of the stacked residuals (positions and weighted
  velocities at the sample times) with respect to each coefficient's logarithm: the sensitivity of
  the fit to a 1 % change of each coefficient, the singular values, the correlation matrix and the
  linearised standard errors (residual variance times (J^T J)^-1). A coefficient is *pinned down*
  when its relative standard error is below 10 %, *weakly* below 50 %, otherwise *not identified*.
- **Bootstrap over experiments**: refit (least-squares polish from the estimate) on training sets
  resampled with replacement; the spread of the refits is the coefficient's uncertainty.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.optimise import NAMES, polish_least_squares
from eelhost.experiment import Experiment
from eelsim.robot import HydroCoefficients, Robot

REL_STEP = 0.01  # 1 % change of a coefficient
PINNED, WEAK = 0.10, 0.50


@dataclass
class Identifiability:
    """Local identifiability of the coefficients at an estimate.

    Attributes
    ----------
    sensitivity : ndarray, shape (4,)
        RMS change of the residuals for a 1 % change of each coefficient (m, mixed units).
    singular_values : ndarray, shape (4,)
        Of the log-scaled Jacobian, largest first.
    correlation : ndarray, shape (4, 4)
        Linearised correlation of the estimates.
    rel_std_error : ndarray, shape (4,)
        Linearised standard error over the value.
    verdict : list of str
        "pinned down", "weakly identified" or "not identified" per coefficient.
    """

    sensitivity: np.ndarray
    singular_values: np.ndarray
    correlation: np.ndarray
    rel_std_error: np.ndarray
    verdict: list[str]

    def to_json(self) -> dict:
        """JSON-ready summary."""
        return {
            "sensitivity": dict(zip(NAMES, self.sensitivity.tolist(), strict=True)),
            "singular_values": self.singular_values.tolist(),
            "correlation": self.correlation.tolist(),
            "rel_std_error": dict(zip(NAMES, self.rel_std_error.tolist(), strict=True)),
            "verdict": dict(zip(NAMES, self.verdict, strict=True)),
        }


def identifiability(evaluator: Evaluator, estimate: HydroCoefficients) -> Identifiability:
    """Linearised identifiability of ``estimate`` on the evaluator's experiments.

    Parameters
    ----------
    evaluator : Evaluator
        The (training) experiments.
    estimate : HydroCoefficients

    Returns
    -------
    Identifiability
    """
    c0 = estimate.as_array()
    base = np.where(c0 > 0, c0, 1e-4)  # a zero coefficient is probed at a small positive value
    pts = np.vstack([c0] + [c0 + np.eye(4)[i] * base[i] * REL_STEP for i in range(4)])
    r = evaluator.residuals(pts)
    jac = ((r[1:] - r[0]) / REL_STEP).T  # d residual / d ln c, shape (M, 4)
    m = jac.shape[0]
    sensitivity = np.sqrt(np.mean((jac * REL_STEP) ** 2, axis=0))
    sing = np.linalg.svd(jac, compute_uv=False)
    sigma2 = float(r[0] @ r[0]) / max(1, m - 4)
    cov = sigma2 * np.linalg.pinv(jac.T @ jac)
    std = np.sqrt(np.clip(np.diag(cov), 0, None))  # standard error of ln c = relative error of c
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    verdict = [
        "pinned down" if s < PINNED else "weakly identified" if s < WEAK else "not identified"
        for s in std
    ]
    return Identifiability(sensitivity, sing, np.nan_to_num(corr), std, verdict)


@dataclass
class Bootstrap:
    """Coefficients refitted on resampled training sets.

    Attributes
    ----------
    samples : ndarray, shape (B, 4)
    mean, std : ndarray, shape (4,)
    """

    samples: np.ndarray
    mean: np.ndarray
    std: np.ndarray

    def to_json(self) -> dict:
        """JSON-ready summary."""
        return {
            "replicates": len(self.samples),
            "mean": dict(zip(NAMES, self.mean.tolist(), strict=True)),
            "std": dict(zip(NAMES, self.std.tolist(), strict=True)),
        }


def bootstrap(
    robot: Robot,
    experiments: Sequence[Experiment],
    estimate: HydroCoefficients,
    replicates: int = 12,
    seed: int = 0,
    backend: str = "auto",
    max_iterations: int = 8,
    progress: Callable[[int, int], None] | None = None,
) -> Bootstrap:
    """Bootstrap the estimate over the training experiments.

    Parameters
    ----------
    robot : Robot
    experiments : sequence of Experiment
        The training experiments.
    estimate : HydroCoefficients
        Where each refit starts.
    replicates : int
        Number of resampled training sets.
    seed : int
        Seeds the resampling.
    backend : str
    max_iterations : int
        Least-squares iterations per refit.
    progress : callable, optional
        ``progress(done, replicates)``.

    Returns
    -------
    Bootstrap
    """
    rng = np.random.default_rng(seed)
    out = []
    for b in range(replicates):
        pick = rng.integers(0, len(experiments), len(experiments))
        ev = Evaluator(robot, [experiments[i] for i in pick], backend=backend)
        # start_fitness inf: the refit is always taken (it is a different training set)
        res = polish_least_squares(ev.residuals, ev.fitness, estimate, np.inf, max_iterations)
        out.append(res.coefficients.as_array() if np.isfinite(res.fitness) else estimate.as_array())
        if progress:
            progress(b + 1, replicates)
    samples = np.array(out)
    return Bootstrap(
        samples,
        samples.mean(axis=0),
        samples.std(axis=0, ddof=1) if len(samples) > 1 else np.zeros(4),
    )
