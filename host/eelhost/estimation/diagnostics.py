"""Warnings about a fit that the report must not hide (docs/estimation.md, "Warnings").

- **At a bound**: a parameter within ``BOUND_FRACTION`` of its search range from a bound. The
  optimum may lie beyond it, so the value is the bound's, not the data's, and the fit elsewhere
  compensates for it.
- **Far above the noise floor**: the fit's fitness more than ``NOISE_RATIO`` times the fitness its
  own model gets on data regenerated with the dataset's declared noise (the parametric
  bootstrap's noise floor). The model then lacks something the plant does; the coefficients
  absorb it and predict the training gaits better than others, and the intervals are dominated by
  misfit, not by the declared noise (:mod:`eelhost.estimation.uncertainty`).
"""

from __future__ import annotations

import logging

import numpy as np

from eelhost.estimation.space import ParameterSpace
from eelhost.estimation.uncertainty import BootstrapResult

log = logging.getLogger(__name__)

BOUND_FRACTION = 0.01  # of the search range
NOISE_RATIO = 3.0


def at_bounds(space: ParameterSpace, values: np.ndarray) -> list[tuple[str, float, float]]:
    """Parameters at a search bound (:meth:`ParameterSpace.at_bound`): (name, value, bound).

    Parameters
    ----------
    space : ParameterSpace
    values : ndarray, shape (K,)

    Returns
    -------
    list of (str, float, float)
    """
    x = space.as_dict(values)
    bounds = dict(zip(space.names, space.bounds, strict=True))
    out = []
    for name in space.at_bound(values, BOUND_FRACTION):
        lo, hi = bounds[name]
        near = lo if abs(x[name] - lo) <= abs(x[name] - hi) else hi
        out.append((name, x[name], float(near)))
    return out


def fit_warnings(
    motion: str,
    space: ParameterSpace,
    values: np.ndarray,
    boot: BootstrapResult | None,
) -> list[str]:
    """The report's warnings about one fit (module docstring), as sentences.

    Parameters
    ----------
    motion : str
        The fit's name.
    space : ParameterSpace
    values : ndarray, shape (K,)
        The fitted parameters.
    boot : BootstrapResult, optional
        Its parametric bootstrap (without one, no noise-floor check).

    Returns
    -------
    list of str
    """
    # a current held within the tank's interval (docs/estimation.md, "One current for the
    # tank") sits at that interval's edge, not at a search bound of the water
    held = set(space.current_names) if space.current_bounds is not None else set()
    out = [
        f"{motion}: {name} = {v:.4g} is held at the edge {b:g} of the tank's current interval "
        "(one current for the tank, shared by the motions): this motion alone would put it "
        "further out; the other parameters take up the difference"
        if name in held else
        f"{motion}: {name} = {v:.4g} is at its search bound {b:g}: the optimum may lie beyond "
        "it, and the other parameters compensate"
        for name, v, b in at_bounds(space, values)
    ]
    if boot is not None and boot.noise_floor > 0 and boot.excess > NOISE_RATIO:
        out.append(
            f"{motion}: fitness {boot.fitness:.4g} is {boot.excess:.1f} times the noise floor "
            f"{boot.noise_floor:.4g} (what the declared noise alone gives): the model misses "
            "something the robot does, the coefficients absorb it, and the intervals are "
            "dominated by misfit (the declared noise's spread widened "
            f"{boot.excess:.1f}x, or the residual bootstrap's, whichever is wider), as are "
            "predictions of other gaits"
        )
    if boot is not None and boot.not_identified() and boot.valleys is not None:
        # per parameter, the other valley farthest from the estimate
        others = []
        for name in boot.not_identified():
            j = list(space.names).index(name)
            far = boot.valleys.minima[np.argmax(np.abs(boot.valleys.minima[:, j] - values[j])), j]
            others.append(f"{name} {values[j]:.4g} or {far:.4g}")
        out.append(
            f"{motion}: {', '.join(boot.not_identified())} not identified by the data: another "
            f"valley fits within the noise ({'; '.join(others)}; fitness threshold "
            f"{boot.valleys.threshold:.4g}), so their intervals span both (docs/estimation.md, "
            "\"Uncertainty\")"
        )
    for line in out:
        log.warning("%s", line)
    return out
