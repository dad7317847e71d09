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

From these, :meth:`CoefficientModel.ensemble` gives the sets the planner checks a plan with (each
fit, and each fit with one coefficient moved by +-``sigmas`` standard deviations), and
:meth:`CoefficientModel.draw` the random sets the benchmark swims with (each coefficient normal
around its fit with its standard deviation, truncated at +-``sigmas``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from eelhost.errors import UserError
from eelhost.estimation.pipeline import CoefficientsError, fitted_models, read_coefficients_file
from eelhost.planning.world import Current, World
from eelsim.fluid import FluidCoefficients
from eelsim.robot import Robot

FloatArray = NDArray[np.float64]

DEFAULT_RELATIVE_STD = 0.10
"""Standard deviation assumed for a coefficient whose uncertainty is not reported, relative."""

MOTIONS = ("straight", "turning")

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

    def robot_for(self, robot: Robot) -> Robot:
        """The robot the planner swims: the fitted model's (its law and joints), else ``robot``."""
        return self.robot if self.robot is not None else robot

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

    def ensemble(self, sigmas: float = 2.0) -> list[tuple[str, FluidCoefficients]]:
        """Each fit, and each fit with one coefficient at +-``sigmas`` standard deviations.

        Parameters
        ----------
        sigmas : float

        Returns
        -------
        list of (label, FluidCoefficients)
            ``2 (1 + 2 k)`` sets for k coefficients, nominal ones first.
        """
        out = [(m, self.fits[m]) for m in MOTIONS]
        for m in MOTIONS:
            nominal = self.fits[m].as_array()
            names = type(self.fits[m]).names()
            for i, name in enumerate(names):
                for sign in (-1.0, 1.0):
                    v = nominal.copy()
                    v[i] += sign * sigmas * self.std[m][i]
                    out.append((f"{m} {name}{'+' if sign > 0 else '-'}{sigmas:g}sd",
                                self._bounded(m, v)))
        return out

    def draw(self, rng: np.random.Generator, motion: str, sigmas: float = 2.0) -> FluidCoefficients:
        """One random set around a fit.

        Each coefficient normal with its standard deviation, truncated at +-``sigmas`` of them.

        Parameters
        ----------
        rng : numpy.random.Generator
        motion : {"straight", "turning"}
        sigmas : float

        Returns
        -------
        FluidCoefficients
        """
        nominal = self.fits[motion].as_array()
        z = np.clip(rng.standard_normal(nominal.size), -sigmas, sigmas)
        return self._bounded(motion, nominal + z * self.std[motion])

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
        ``allow_other_robot`` (:func:`eelhost.estimation.pipeline.check_robot`).

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
    uncertainty = data.get("uncertainty") if isinstance(data.get("uncertainty"), dict) else {}
    std: dict[str, FloatArray] = {}
    notes = []
    for m in MOTIONS:
        names = type(chosen[m]).names()
        reported = (uncertainty.get(from_key[m]) or {}).get("std") if uncertainty else None
        default = _default_std(chosen[m])
        values = default.copy()
        if isinstance(reported, dict):
            for i, name in enumerate(names):
                v = reported.get(name)
                if isinstance(v, int | float) and math.isfinite(v) and v >= 0:
                    values[i] = float(v)
                else:
                    notes.append(f"{m} {name}")
        else:
            notes.append(m)
        std[m] = values
    source = f"{path}" + (
        f"; no reported std for {', '.join(notes)}: {DEFAULT_RELATIVE_STD:.0%} of the value"
        if notes else "; bootstrap std"
    )
    # the fitted model's robot: its law, joint model and fitted joint parameters (those of the
    # straight fit: one robot swims every leg); and the tank's current, the fits' mean
    straight = models[from_key["straight"]]
    used = {models[from_key[m]] for m in MOTIONS}
    current = tuple(float(v) for v in np.mean([f.current_m_s for f in used], axis=0))
    source += f"; model {straight.space.model_name}"
    return CoefficientModel(chosen, std, source, straight.robot(robot), (current[0], current[1]))
