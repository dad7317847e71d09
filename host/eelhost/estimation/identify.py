"""Which coefficients the data pins down, and how uncertain each fitted value is.

Two complementary answers:

- **Local identifiability** from the Jacobian of the stacked residuals (positions and weighted
  velocities at the sample times) in the unit cube of the search bounds: the sensitivity of the
  fit to a step of 1 % of each coefficient's range, the singular values, the correlation matrix and the
  linearised standard errors (residual variance times (J^T J)^-1). A coefficient is *pinned down*
  when its relative standard error is below 10 %, *weakly* below 50 %, otherwise *not identified*.
- **Bootstrap over experiments**: refit (least-squares polish from the estimate) on training sets
  resampled with replacement; the spread of the refits is the coefficient's uncertainty.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from eelhost.data.experiments import Experiment
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.optimise import BOUNDS, NAMES, from_unit, polish_least_squares, to_unit
from eelsim.fluid import FluidCoefficients
from eelsim.robot import Robot

REL_STEP = 0.01  # a step of 1 % of a coefficient's search range
PINNED, WEAK = 0.10, 0.50


@dataclass
class Identifiability:
    """Local identifiability of the coefficients at an estimate.

    Attributes
    ----------
    sensitivity : ndarray, shape (4,)
        RMS change of the residuals for a step of 1 % of each range (m, mixed units).
    singular_values : ndarray, shape (4,)
        Of the unit-cube Jacobian, largest first.
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


def identifiability(evaluator: Evaluator, estimate: FluidCoefficients) -> Identifiability:
    """Linearised identifiability of ``estimate`` on the evaluator's experiments.

    The Jacobian is taken in the unit cube of the search bounds (a step of 1 % of each range), so a
    coefficient near zero is probed as well as any other; standard errors come from its singular
    value decomposition, and a direction the data does not see at all (a singular value below 1e-9
    of the largest) gets an infinite error instead of the zero a pseudo-inverse would give.

    Parameters
    ----------
    evaluator : Evaluator
        The (training) experiments.
    estimate : FluidCoefficients

    Returns
    -------
    Identifiability
    """
    c0 = estimate.as_array()
    u0 = to_unit(c0)
    steps = np.where(u0 + REL_STEP <= 1.0, REL_STEP, -REL_STEP)
    pts = np.vstack([c0] + [from_unit(u0 + np.eye(4)[i] * steps[i]) for i in range(4)])
    r = evaluator.residuals(pts)
    jac = ((r[1:] - r[0]) / steps[:, None]).T  # d residual / d unit coordinate, shape (M, 4)
    m = jac.shape[0]
    ranges = BOUNDS[:, 1] - BOUNDS[:, 0]
    sensitivity = np.sqrt(np.mean((jac * REL_STEP) ** 2, axis=0))
    _, sing, vt = np.linalg.svd(jac, full_matrices=False)
    sigma2 = float(r[0] @ r[0]) / max(1, m - 4)
    with np.errstate(divide="ignore"):
        inv_s2 = np.where(sing > 1e-9 * sing[0], 1.0 / sing**2, np.inf)
    cov_u = sigma2 * (vt.T * inv_s2) @ vt
    var_u = np.einsum("ij,j,ij->i", vt.T, inv_s2, vt.T) * sigma2  # diagonal, inf-safe
    std = np.sqrt(np.where(np.isnan(var_u), np.inf, var_u)) * ranges
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(np.abs(c0) > 0, std / np.abs(c0), np.inf)
        corr = np.nan_to_num(cov_u / np.sqrt(np.outer(np.diag(cov_u), np.diag(cov_u))))
    verdict = [
        "pinned down" if e < PINNED else "weakly identified" if e < WEAK else "not identified"
        for e in rel
    ]
    return Identifiability(sensitivity, sing, corr, rel, verdict)


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
    estimate: FluidCoefficients,
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
    estimate : FluidCoefficients
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
