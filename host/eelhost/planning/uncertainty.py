"""The coefficients the planner swims with, and how uncertain they are.

docs/planning.md, "Coefficients and their uncertainty", is the long form.

The paper fits one coefficient set to straight swimming and one to turning (docs/model.md section
6); the planner swims straight legs with the first and turning legs with the second. Each has a
standard deviation per coefficient:

- from a ``coefficients.json`` written by ``eelbot report`` (or ``eelbot estimate``): the fits
  under ``fits.<motion>.coefficients`` and the bootstrap standard deviations under
  ``uncertainty.<motion>.std`` (by coefficient name). A file with one ``joint`` fit uses it for
  both motions; a motion without a standard deviation, or a coefficient without one, gets the
  default below;
- without a file: the robot file's coefficients (or ``--coefficients``) for straight motion; for
  turning, the paper's table 3 turning set when the straight set is table 3's (the bundled robot),
  else the same set;
- the default standard deviation, when none is reported, is ``DEFAULT_RELATIVE_STD`` (10 %) of
  each coefficient's value.

Draws of the water (docs/planning.md, "Coefficients and their uncertainty"): the planner checks a
plan over joint draws of every coefficient of a fit, not one coefficient at a time. Each fit's
coefficients are normal around the fit with covariance ``cov`` (the bootstrap replicates'
correlation when the file stores them, else independent), restricted to the fit's 95 % region
(the ellipsoid that holds 95 % of that normal: squared Mahalanobis distance at most the chi-square
quantile with as many degrees of freedom as coefficients). A draw also has a current: the tank's
fitted current moved within its own 95 % region, plus an unknown current the planner is not told
of, of a speed the user bounds (``DEFAULT_UNKNOWN_CURRENT_M_S`` for a lab tank), its direction
stratified round the circle: with ``count`` draws, each in its own of ``count`` equal sectors,
uniform within it, the sectors in a random order (``STRATIFIED``). The draws stay independent, and
a plan fails no fewer of them than of independent uniform directions in expectation, nor passes
all of them more often (the product of the sectors' pass probabilities is at most the mean's
power, by the inequality of the arithmetic and geometric means), so the check's Clopper-Pearson
bound holds. The earlier lattice (``LATTICE``: ``CURRENT_DIRECTIONS`` directions 45 degrees apart
from one random first, draw after draw) swam 60 draws in 8 directions only, so a plan that fails
in a band of directions between them passed far more often than its failure probability allows
(docs/planning.md, "Coefficients and their uncertainty"); the benchmark's fresh draws keep it, so
its judging is unchanged. :meth:`CoefficientModel.water_draws` gives the draws, seeded;
:meth:`CoefficientModel.draw` one coefficient set the same way.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2, norm

from eelhost.errors import UserError
from eelhost.estimation.coefficients_file import (
    CoefficientsError,
    ReportedUncertainty,
    fitted_models,
    read_coefficients_file,
    reported_uncertainty,
)
from eelhost.planning.world import Current, World
from eelsim.fluid import FluidCoefficients
from eelsim.model import SwimmerModel
from eelsim.robot import Robot

FloatArray = NDArray[np.float64]

DEFAULT_RELATIVE_STD = 0.10
"""Standard deviation assumed for a coefficient whose uncertainty is not reported, relative."""

MOTIONS = ("straight", "turning")

REGION_LEVEL = 0.95
"""Probability mass of the region the draws are restricted to (the fit's 95 % region)."""

DEFAULT_UNKNOWN_CURRENT_M_S = 0.02
"""Bound of the current the planner is not told of: a lab tank's residual flow, m/s."""

CURRENT_DIRECTIONS = 8
"""The lattice's directions (``LATTICE``): evenly spread, from a seeded random first one."""

STRATIFIED = "stratified"
"""The unknown current's direction: one draw per equal sector, uniform within it, random order."""

LATTICE = "lattice"
"""The unknown current's direction: ``CURRENT_DIRECTIONS`` directions from a random first one."""

CURRENT_NAMES = ("current_x_m_s", "current_y_m_s")

_TABLE3_STRAIGHT = (0.008, 0.776, 0.618, 0.007)
_TABLE3_TURNING = (0.009, 0.978, 1.169, 0.001)


class CoefficientsFileError(UserError, ValueError):
    """A coefficients file the planner cannot use (the message names the file and the key)."""


@dataclass(frozen=True)
class CoefficientModel:
    """Straight and turning coefficient sets with a standard deviation per coefficient.

    Attributes
    ----------
    fits : dict
        ``"straight"`` and ``"turning"`` -> FluidCoefficients.
    std : dict
        The same keys -> ndarray of standard deviations, in the law's coefficient order.
    source : str
        Where they came from (for reports).
    """

    fits: dict[str, FluidCoefficients]
    std: dict[str, FloatArray]
    source: str
    robot: Robot | None = None
    ambient_current_m_s: tuple[float, float] = (0.0, 0.0)
    cov: dict[str, FloatArray] | None = None
    current_cov: FloatArray | None = None

    def covariance(self, motion: str) -> FloatArray:
        """Covariance of a fit's coefficients (independent with ``std`` when none is given)."""
        if self.cov is not None and motion in self.cov:
            return np.asarray(self.cov[motion], dtype=float)
        return np.diag(np.asarray(self.std[motion], dtype=float) ** 2)

    def robot_for(self, robot: Robot) -> Robot:
        """The robot the planner swims: the fitted model's (its law and joints), else ``robot``."""
        return self.robot if self.robot is not None else robot

    def swimmer_for(self, robot: Robot) -> SwimmerModel:
        """The model of the robot the planner swims (:meth:`robot_for`) with the straight fit.

        A command builds it once and hands it on to the planner, its twin, search and check,
        and every replan (docs/architecture.md, "The planning room"): only the body's
        dimensions are read from it, and the batch's step check when the fit is the robot's own
        coefficients (the fitted model's robot has the straight fit's).

        Parameters
        ----------
        robot : Robot
            The robot file's robot.

        Returns
        -------
        SwimmerModel
        """
        return SwimmerModel.from_robot(self.robot_for(robot), self.fits["straight"])

    def in_tank(self, world: World) -> World:
        """``world`` with the fitted ambient current of the tank added to its own current.

        The estimation fits the tank's unknown current as a nuisance added to each experiment's
        declared current (docs/estimation.md, "Nuisance parameters"); a world's current is
        the declared one, so the planner swims in their sum.
        """
        if self.ambient_current_m_s == (0.0, 0.0):
            return world
        vx, vy = np.add(world.current_m_s, self.ambient_current_m_s)
        current = Current(speed_m_s=float(math.hypot(vx, vy)),
                          direction_deg=float(math.degrees(math.atan2(vy, vx))))
        return world.model_copy(update={"current": current})

    @property
    def sets(self) -> list[FluidCoefficients]:
        """[straight, turning]: the twin's coefficient sets 0 and 1."""
        return [self.fits[m] for m in MOTIONS]

    def _bounded(self, motion: str, values: FloatArray) -> FluidCoefficients:
        cls = type(self.fits[motion])
        # keep every coefficient positive: a law's coefficients are magnitudes
        nominal = self.fits[motion].as_array()
        return cls.from_array(np.maximum(values, 0.05 * nominal))

    def draw(self, rng: np.random.Generator, motion: str,
             sigmas: float | None = None) -> FluidCoefficients:
        """One coefficient set drawn jointly within the fit's 95 % region (module docstring).

        Parameters
        ----------
        rng : numpy.random.Generator
        motion : {"straight", "turning"}
        sigmas : float, optional
            Ignored (the region is the fit's 95 % one); kept for callers of the earlier form.

        Returns
        -------
        FluidCoefficients
        """
        nominal = self.fits[motion].as_array()
        return self._bounded(motion, nominal + region_draw(rng, self.covariance(motion)))

    def water_draws(self, rng: np.random.Generator, count: int,
                    unknown_current_m_s: float = DEFAULT_UNKNOWN_CURRENT_M_S,
                    directions: str = STRATIFIED) -> list[WaterDraw]:
        """``count`` draws of the water a plan is checked in (module docstring).

        Each draw has a straight and a turning set and an unknown current's direction.

        Parameters
        ----------
        rng : numpy.random.Generator
        count : int
        unknown_current_m_s : float
            Speed of the current the planner is not told of (at the bound: the worst speed).
        directions : str
            :data:`STRATIFIED` (the check's: draw k in sector ``order[k]`` of ``count`` equal
            sectors, uniform within it, ``order`` a random permutation) or :data:`LATTICE`
            (:data:`CURRENT_DIRECTIONS` directions from a random first one, draw after draw).

        Returns
        -------
        list of WaterDraw
        """
        if directions not in (STRATIFIED, LATTICE):
            raise ValueError(f"directions: expected {STRATIFIED!r} or {LATTICE!r}, "
                             f"got {directions!r}")
        first = rng.uniform(0.0, 2.0 * math.pi)
        cov = self.current_cov if self.current_cov is not None else np.zeros((2, 2))
        # the coefficients and the fitted current consume the generator as they always have, so
        # a seed's coefficients are the lattice's (and the bench's lattice draws are unchanged);
        # the stratified directions come from it afterwards
        drawn = []
        for _ in range(count):
            straight, turning = self.draw(rng, "straight"), self.draw(rng, "turning")
            fitted = region_draw(rng, cov) if np.any(cov) else np.zeros(2)
            drawn.append((straight, turning, fitted))
        k = np.arange(count)
        if directions == STRATIFIED:
            angles = 2.0 * np.pi * (rng.permutation(count) + rng.uniform(size=count)) / count
        else:
            angles = first + 2.0 * np.pi * (k % CURRENT_DIRECTIONS) / CURRENT_DIRECTIONS
        out = []
        for i, ((straight, turning, fitted), angle) in enumerate(zip(drawn, angles, strict=True)):
            offset = (float(fitted[0] + unknown_current_m_s * math.cos(angle)),
                      float(fitted[1] + unknown_current_m_s * math.sin(angle)))
            out.append(WaterDraw(
                f"draw {i + 1} (unknown current {unknown_current_m_s:g} m/s towards "
                f"{math.degrees(angle) % 360:.0f} deg)", straight, turning, offset))
        return out

    def describe(self) -> str:
        """One line per fit: values with their standard deviations, and the source."""
        lines = []
        for m in MOTIONS:
            names = type(self.fits[m]).names()
            vals = self.fits[m].as_array()
            lines.append(f"{m}: " + ", ".join(
                f"{n} {v:.4g} +- {s:.2g}" for n, v, s in zip(names, vals, self.std[m], strict=True)
            ))
        if self.ambient_current_m_s != (0.0, 0.0):
            vx, vy = self.ambient_current_m_s
            lines.append(f"tank's fitted current {math.hypot(vx, vy):.4f} m/s towards "
                         f"{math.degrees(math.atan2(vy, vx)):.0f} deg")
        return "; ".join(lines) + f" ({self.source})"


@dataclass(frozen=True)
class WaterDraw:
    """One draw of the water a plan is checked in.

    Attributes
    ----------
    label : str
    straight, turning : FluidCoefficients
        The straight and turning sets, each drawn within its fit's region: the robot swims
        straight legs with the first and turns with the second, as the search does.
    current_offset_m_s : (float, float)
        Added to the planner's current: the fitted current's deviation and the unknown current.
    """

    label: str
    straight: FluidCoefficients
    turning: FluidCoefficients
    current_offset_m_s: tuple[float, float]


def region_draw(rng: np.random.Generator, cov: FloatArray,
                level: float = REGION_LEVEL) -> FloatArray:
    """A deviation normal with covariance ``cov``, restricted to its ``level`` region.

    The region is {x : x^T cov^-1 x <= chi2_k(level)}, k the dimension (the directions of zero
    variance are left at 0); drawn by rejection (``level`` of the draws are kept).

    Parameters
    ----------
    rng : numpy.random.Generator
    cov : ndarray, shape (k, k)
    level : float

    Returns
    -------
    ndarray, shape (k,)
    """
    cov = np.asarray(cov, dtype=float)
    vectors, scale, limit = _region_basis(cov.tobytes(), cov.shape, float(level))
    if limit is None:
        return np.zeros(len(scale))
    while True:
        z = rng.standard_normal(len(scale)) * (scale > 0)
        if z @ z <= limit:
            return np.asarray(vectors @ (scale * z), dtype=float)


@functools.lru_cache(maxsize=64)
def _region_basis(cov_bytes: bytes, shape: tuple[int, ...], level: float
                  ) -> tuple[FloatArray, FloatArray, float | None]:
    """The eigenvectors, standard deviations and chi-squared limit of :func:`region_draw`.

    Kept per covariance: a check's draws ask for the same two or three covariances hundreds of
    times, and the decomposition and ``chi2.ppf`` cost far more than the draw itself (on
    development seeds 28600-28609 they were most of the water draws' processor time,
    docs/planning.md "The check's processor time"). The same values as computed afresh: the
    decomposition of the same bytes is deterministic.

    Returns
    -------
    vectors : ndarray, shape (k, k)
    scale : ndarray, shape (k,)
    limit : float or None
        None when every variance is 0.
    """
    cov = np.frombuffer(cov_bytes, dtype=float).reshape(shape)
    values, vectors = np.linalg.eigh(cov)
    scale = np.sqrt(np.clip(values, 0.0, None))
    dims = int(np.count_nonzero(scale > 0))
    limit = None if dims == 0 else float(chi2.ppf(level, dims))
    vectors.setflags(write=False)
    scale.setflags(write=False)
    return vectors, scale, limit


def clopper_pearson(failures: int, draws: int, level: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper-Pearson) interval of a probability from ``failures`` in ``draws``.

    Parameters
    ----------
    failures, draws : int
    level : float
        Two-sided confidence level.

    Returns
    -------
    (float, float)
        Lower and upper bound (with 0 failures the upper bound is 1 - ((1 - level) / 2)^(1/n),
        about 3.7 / n at 95 %; the one-sided rule of three gives 3 / n).
    """
    from scipy.stats import beta

    alpha = 1.0 - level
    lower = 0.0 if failures == 0 else float(beta.ppf(alpha / 2, failures, draws - failures + 1))
    upper = (1.0 if failures == draws
             else float(beta.ppf(1 - alpha / 2, failures + 1, draws - failures)))
    return lower, upper


def _default_std(c: FluidCoefficients) -> FloatArray:
    return DEFAULT_RELATIVE_STD * np.abs(c.as_array())


def default_model(robot: Robot, coefficients: FluidCoefficients | None = None) -> CoefficientModel:
    """The coefficient model without a coefficients file (module docstring).

    Parameters
    ----------
    robot : Robot
    coefficients : FluidCoefficients, optional
        The straight-motion set (default: the robot file's).

    Returns
    -------
    CoefficientModel
    """
    straight = coefficients if coefficients is not None else robot.hydrodynamics
    values = straight.as_array()
    turning = straight
    source = "robot coefficients for both motions"
    if values.size == len(_TABLE3_STRAIGHT) and np.allclose(values, _TABLE3_STRAIGHT):
        turning = type(straight).from_array(_TABLE3_TURNING)
        source = "paper table 3 (straight and turning)"
    std = {"straight": _default_std(straight), "turning": _default_std(turning)}
    return CoefficientModel({"straight": straight, "turning": turning}, std,
                            f"{source}; std {DEFAULT_RELATIVE_STD:.0%} of each value (default)")


def read_coefficient_model(
    path: str | Path, robot: Robot, allow_other_robot: bool = False
) -> CoefficientModel:
    """Read fits and bootstrap standard deviations from a ``coefficients.json``.

    Parameters
    ----------
    path : str or Path
    robot : Robot
        The robot file the fits are of (records that name no law are the Morison law's, as
        in the first format). A file recording another robot is refused unless
        ``allow_other_robot`` (:func:`eelhost.estimation.coefficients_file.check_robot`).

    Returns
    -------
    CoefficientModel
        With the file's model: its law's coefficients, the robot with its joint model and fitted
        joint parameters (:attr:`CoefficientModel.robot`), and the tank's fitted current.

    Raises
    ------
    CoefficientsFileError
        An unreadable file, no usable fit, or a malformed value (naming file and key).
    """
    path = Path(path)
    try:
        data = read_coefficients_file(path)
        models = fitted_models(data, robot, path, allow_other_robot)
    except CoefficientsError as err:
        raise CoefficientsFileError(str(err)) from None
    fits = {m: f.coefficients for m, f in models.items()}
    chosen: dict[str, FluidCoefficients] = {}
    from_key: dict[str, str] = {}
    for m in MOTIONS:
        key = m if m in fits else "joint" if "joint" in fits else None
        if key is None:
            raise CoefficientsFileError(
                f"{path}: fits: no {m!r} (or 'joint') set; found {', '.join(sorted(fits))}"
            )
        chosen[m], from_key[m] = fits[key], key
    uncertainty = reported_uncertainty(data)
    std: dict[str, FloatArray] = {}
    cov: dict[str, FloatArray] = {}
    notes: list[str] = []
    correlated: list[str] = []
    for m in MOTIONS:
        names = type(chosen[m]).names()
        entry = uncertainty.get(from_key[m])
        values = _marginal_sigmas(entry, names, chosen[m].as_array(), f"{m}", notes)
        std[m] = values
        corr = _sample_correlation(entry, names, f"{path}: uncertainty.{from_key[m]}.samples")
        if corr is not None:
            correlated.append(m)
        cov[m] = (corr if corr is not None else np.eye(len(names))) * np.outer(values, values)
    source = f"{path}" + (
        f"; no reported uncertainty for {', '.join(notes)}: {DEFAULT_RELATIVE_STD:.0%} of the value"
        if notes else "; bootstrap intervals"
    ) + (f"; correlation from the bootstrap replicates ({', '.join(correlated)})" if correlated
         else "; no bootstrap replicates stored: coefficients drawn independently")
    # the fitted model's robot: its law, joint model and fitted joint parameters (those of the
    # straight fit: one robot swims every leg); and the tank's current, the fits' mean
    straight = models[from_key["straight"]]
    used = {models[from_key[m]] for m in MOTIONS}
    current = tuple(float(v) for v in np.mean([f.current_m_s for f in used], axis=0))
    source += f"; model {straight.space.model_name}"
    found = uncertainty.get(from_key["straight"])
    current_sigma = (_marginal_sigmas(found, CURRENT_NAMES, np.asarray(straight.current_m_s), "",
                                      [], default=0.0)
                     if found is not None and straight.space.current else np.zeros(2))
    return CoefficientModel(chosen, std, source, straight.robot(robot), (current[0], current[1]),
                            cov, np.diag(current_sigma**2))


def _marginal_sigmas(entry: ReportedUncertainty | None, names: tuple[str, ...],
                     estimate: FloatArray, label: str, notes: list[str],
                     default: float | None = None) -> FloatArray:
    """Standard deviation of each named parameter, from a bootstrap entry of coefficients.json.

    From the reported interval when there is one (``lower``, ``upper`` at ``level``): its wider
    side over the normal quantile, so the excess and widening the report applied are kept;
    else the replicates' ``std``; else ``default`` (None: :data:`DEFAULT_RELATIVE_STD` of the
    value), and ``label name`` is added to ``notes``.
    """
    entry = entry if entry is not None else ReportedUncertainty.from_json(None)
    level = entry.level if entry.level is not None else REGION_LEVEL
    z = float(norm.ppf(0.5 + level / 2))
    out = np.empty(len(names))
    for i, name in enumerate(names):
        lo, hi, sd = entry.lower.get(name), entry.upper.get(name), entry.std.get(name)
        if lo is not None and hi is not None and lo <= hi:
            out[i] = max(hi - estimate[i], estimate[i] - lo, 0.0) / z
        elif sd is not None and sd >= 0:
            out[i] = sd
        else:
            out[i] = DEFAULT_RELATIVE_STD * abs(estimate[i]) if default is None else default
            notes.append(f"{label} {name}".strip())
    return out


def _sample_correlation(entry: ReportedUncertainty | None, names: tuple[str, ...],
                        where: str) -> FloatArray | None:
    """Correlation of the named parameters over the stored bootstrap replicates, if any.

    ``samples`` is a list of replicates, each the parameters by name (or one list of values per
    name). None without replicates, or with fewer than the parameters plus two.
    """
    raw = entry.samples if entry is not None else None
    if raw is None:
        return None
    try:
        if isinstance(raw, dict):
            rows = np.column_stack([np.asarray(raw[n], dtype=float) for n in names])
        else:
            rows = np.asarray([[float(r[n]) for n in names] for r in raw], dtype=float)
    except (KeyError, TypeError, ValueError) as err:
        raise CoefficientsFileError(f"{where}: expected replicates by name ({err})") from None
    if rows.ndim != 2 or len(rows) < len(names) + 2 or not np.all(np.isfinite(rows)):
        return None
    sd = rows.std(axis=0, ddof=1)
    corr = np.eye(len(names))
    live = sd > 0
    if live.sum() > 1:
        sub = np.corrcoef(rows[:, live], rowvar=False)
        corr[np.ix_(live, live)] = np.atleast_2d(sub)
    return np.asarray(corr, dtype=float)
