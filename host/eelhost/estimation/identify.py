"""Which parameters the data pins down: local identifiability at an estimate.

From the Jacobian of the stacked residuals (positions and weighted velocities at the sample
times) in the unit cube of the search bounds: the sensitivity of the fit to a step of 1 % of each
parameter's range, the singular values, the correlation matrix and the linearised standard errors
(residual variance times (J^T J)^-1). A parameter is *pinned down* when its relative standard
error is below 10 %, *weakly* below 50 %, otherwise *not identified*. The error is relative to the
value, except for a parameter whose search range holds both signs (the ambient current's
components, rightly 0 in still water): relative to half its range.

These linearised errors treat the residuals as independent noise; they are not intervals that
hold (measured: docs/estimation_benchmarks.md): the report's intervals come from the parametric
bootstrap of :mod:`eelhost.estimation.uncertainty`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eelhost.estimation.evaluate import Evaluator

REL_STEP = 0.01  # a step of 1 % of a coefficient's search range
PINNED, WEAK = 0.10, 0.50


@dataclass
class Identifiability:
    """Local identifiability of the coefficients at an estimate.

    Attributes
    ----------
    names : tuple of str
        The parameters (of the evaluator's space).
    sensitivity : ndarray, shape (K,)
        RMS change of the residuals for a step of 1 % of each range (m, mixed units).
    singular_values : ndarray, shape (K,)
        Of the unit-cube Jacobian, largest first.
    correlation : ndarray, shape (K, K)
        Linearised correlation of the estimates.
    rel_std_error : ndarray, shape (K,)
        Linearised standard error over the value (over half the range for a signed parameter).
    std_error : ndarray, shape (K,)
        The same in the parameter's own unit (inf where the data does not see it).
    verdict : list of str
        "pinned down", "weakly identified" or "not identified" per parameter.
    """

    names: tuple[str, ...]
    sensitivity: np.ndarray
    singular_values: np.ndarray
    correlation: np.ndarray
    rel_std_error: np.ndarray
    verdict: list[str]
    std_error: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def unidentified(self) -> list[str]:
        """The parameters reported *not identified*."""
        return [n for n, v in zip(self.names, self.verdict, strict=True) if v == "not identified"]

    def to_json(self) -> dict:
        """JSON-ready summary."""
        return {
            "sensitivity": dict(zip(self.names, self.sensitivity.tolist(), strict=True)),
            "singular_values": self.singular_values.tolist(),
            "correlation": self.correlation.tolist(),
            "rel_std_error": dict(zip(self.names, self.rel_std_error.tolist(), strict=True)),
            "verdict": dict(zip(self.names, self.verdict, strict=True)),
        }


def identifiability(evaluator: Evaluator, estimate: np.ndarray) -> Identifiability:
    """Linearised identifiability of ``estimate`` on the evaluator's experiments.

    The Jacobian is taken in the unit cube of the search bounds (a step of 1 % of each range), so a
    parameter near zero is probed as well as any other; standard errors come from its singular
    value decomposition, and a direction the data does not see at all (a singular value below 1e-9
    of the largest) gets an infinite error instead of the zero a pseudo-inverse would give. The
    residual variance is never taken below the pixel rounding's (pixel^2 / 12).

    Parameters
    ----------
    evaluator : Evaluator
        The (training) experiments.
    estimate : ndarray, shape (K,)
        A vector of the evaluator's space.

    Returns
    -------
    Identifiability
    """
    space = evaluator.space
    k = space.size
    c0 = np.asarray(estimate, dtype=float)
    u0 = space.to_unit(c0)
    steps = np.where(u0 + REL_STEP <= 1.0, REL_STEP, -REL_STEP)
    pts = np.vstack([c0] + [space.from_unit(u0 + np.eye(k)[i] * steps[i]) for i in range(k)])
    r = evaluator.residuals(pts)
    jac = ((r[1:] - r[0]) / steps[:, None]).T  # d residual / d unit coordinate, shape (M, K)
    m = jac.shape[0]
    ranges = space.bounds[:, 1] - space.bounds[:, 0]
    sensitivity = np.sqrt(np.mean((jac * REL_STEP) ** 2, axis=0))
    _, sing, vt = np.linalg.svd(jac, full_matrices=False)
    # never below the pixel rounding's variance (a uniform half-pixel error): a fit that
    # reproduces its recordings exactly still only knows them to a pixel
    pixel = max(float(p.experiment.recording_camera().pixel_m) for p in evaluator.prepared)
    sigma2 = max(float(r[0] @ r[0]) / max(1, m - k), pixel**2 / 12.0)
    with np.errstate(divide="ignore"):
        inv_s2 = np.where(sing > 1e-9 * sing[0], 1.0 / sing**2, np.inf)
    # an unidentified direction has an infinite variance; 0 x inf (a parameter with no share in
    # it) is NaN here and read as infinite below, or as no correlation
    with np.errstate(invalid="ignore"):
        cov_u = sigma2 * (vt.T * inv_s2) @ vt
        var_u = np.einsum("ij,j,ij->i", vt.T, inv_s2, vt.T) * sigma2  # diagonal
    std = np.sqrt(np.where(np.isnan(var_u), np.inf, var_u)) * ranges
    signed = (space.bounds[:, 0] < 0) & (space.bounds[:, 1] > 0)
    scale = np.where(signed, ranges / 2, np.abs(c0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(scale > 0, std / scale, np.inf)
        corr = np.nan_to_num(cov_u / np.sqrt(np.outer(np.diag(cov_u), np.diag(cov_u))))
    verdict = [
        "pinned down" if e < PINNED else "weakly identified" if e < WEAK else "not identified"
        for e in rel
    ]
    return Identifiability(space.names, sensitivity, sing, corr, rel, verdict, std)
