"""What a fit searches: the model's parameters by name, with bounds (docs/estimation.md).

A fit's parameter vector is the fluid law's coefficients (names and default bounds from the law,
``eelsim.fluid.get_fluid_law(name)``; docs/model.md section 6), followed by the joint model's
fitted parameters, if any (:mod:`eelhost.estimation.joint_fit`: the paper's PD gains stay
fixed), followed, when the space fits one, by the tank's unknown ambient current
(``current_x_m_s``, ``current_y_m_s``: a nuisance shared by the fit's experiments and added to the
current each declares; docs/estimation.md, "Nuisance parameters"). A :class:`ParameterSpace` names
them, maps them to and from the unit cube the optimisers search (linearly onto the bounds), and
turns a vector into what the twin runs: the coefficient record, the robot with the joint
parameters set and the ambient current. :func:`spaces_of` lists the candidate models of the model
comparison. One point of a space, as ``coefficients.json`` stores it, is a
:class:`~eelhost.estimation.coefficients_file.FittedModel`.

Clock offsets, the other nuisance of the recordings, are not in the vector: they are profiled
per experiment (:mod:`eelhost.estimation.evaluate`), which costs no simulation.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from eelhost.estimation.joint_fit import (
    JointFit,
    ParameterError,
    joint_fit,
    joint_model_name,
)
from eelsim.fluid import FluidCoefficients, FluidLaw, get_fluid_law
from eelsim.joints import default_grid_models
from eelsim.robot import Robot

__all__ = ["CURRENT_BOUND_M_S", "CURRENT_NAMES", "ParameterSpace", "box_from_unit", "box_to_unit",
           "spaces_of"]

# The ambient current's components in the tank frame, m/s (docs/model.md: v_c, the direction it
# flows towards). Cartesian rather than speed and direction: the fitness is smooth in them, with
# no wrap-around and no undefined direction at the still water a clean tank should give.
CURRENT_NAMES = ("current_x_m_s", "current_y_m_s")
# Search bound of each component: residual tank currents (pumps, convection) are mm/s to cm/s;
# the paper's declared current is 0.03 m/s.
CURRENT_BOUND_M_S = 0.03


def box_from_unit(bounds: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Map unit-cube points (..., K) into the box ``bounds`` (K, 2), clipped to the cube first.

    The optimisers search the unit cube; this is the one linear map back to parameters.
    """
    b = bounds
    return b[:, 0] + np.clip(np.asarray(u, dtype=float), 0.0, 1.0) * (b[:, 1] - b[:, 0])


def box_to_unit(bounds: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Map points (..., K) of the box ``bounds`` (K, 2) to the unit cube.

    The inverse of :func:`box_from_unit` inside the box.
    """
    b = bounds
    return (np.asarray(x, dtype=float) - b[:, 0]) / (b[:, 1] - b[:, 0])


@dataclass(frozen=True, eq=False)
class ParameterSpace:
    """The parameters of a candidate model, by name, with search bounds.

    Attributes
    ----------
    law : FluidLaw
        The fluid law whose coefficients come first.
    joints : JointFit
        The joint model and its fitted parameters (after the coefficients).
    law_bounds : ndarray, shape (k, 2)
        Search bounds of the coefficients (the law's default bounds unless given).
    current : bool
        Whether the tank's ambient current is fitted too (:data:`CURRENT_NAMES`, last, each
        within +-:data:`CURRENT_BOUND_M_S`).
    current_bounds : ndarray, shape (2, 2), optional
        The current's bounds when a fit holds it within the interval of the tank's current
        (:mod:`eelhost.estimation.tank_current`); default +-:data:`CURRENT_BOUND_M_S` each.
    """

    law: FluidLaw
    joints: JointFit = field(default_factory=JointFit)
    law_bounds: np.ndarray | None = None
    current: bool = False
    current_bounds: np.ndarray | None = None

    @classmethod
    def for_robot(
        cls, robot: Robot, law: str | None = None, current: bool = False
    ) -> ParameterSpace:
        """The space of a robot's model.

        Its fluid law (or ``law``), its joint model, and the ambient current when ``current``.
        """
        fluid = robot.fluid_law if law is None else get_fluid_law(law)
        return cls(fluid, joint_fit(robot), current=current)

    @property
    def model_name(self) -> str:
        """"<joint model> x <fluid law>", how reports name the candidate."""
        return f"{self.joints.model} x {self.law.name}"

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        """The fluid law's coefficients, in array order."""
        return self.law.coefficient_names

    @property
    def current_names(self) -> tuple[str, ...]:
        """The ambient current's components when fitted (else none)."""
        return CURRENT_NAMES if self.current else ()

    @property
    def names(self) -> tuple[str, ...]:
        """Every parameter: the law's coefficients, the joint model's, then the current's."""
        return self.coefficient_names + self.joints.names + self.current_names

    @property
    def size(self) -> int:
        """Number of parameters K."""
        return len(self.names)

    @property
    def bounds(self) -> np.ndarray:
        """Search bounds, shape (K, 2)."""
        law = self.law.bounds if self.law_bounds is None else np.asarray(self.law_bounds, float)
        current = np.tile([-CURRENT_BOUND_M_S, CURRENT_BOUND_M_S], (len(self.current_names), 1))
        if self.current and self.current_bounds is not None:
            current = np.asarray(self.current_bounds, dtype=float)
        return np.vstack([law, self.joints.bounds, current.reshape(-1, 2)])

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        """Map unit-cube points (..., K) to parameters (clipped to the cube first)."""
        return box_from_unit(self.bounds, u)

    def to_unit(self, x: np.ndarray) -> np.ndarray:
        """Map parameters (..., K) to the unit cube."""
        return box_to_unit(self.bounds, x)

    def coefficient_array(self, x: np.ndarray) -> np.ndarray:
        """The fluid-law part of parameter vectors, shape (..., k)."""
        return np.asarray(x, dtype=float)[..., : len(self.coefficient_names)]

    def joint_array(self, x: np.ndarray) -> np.ndarray:
        """The joint part of parameter vectors, shape (..., number of joint parameters)."""
        k = len(self.coefficient_names)
        return np.asarray(x, dtype=float)[..., k : k + len(self.joints.names)]

    def current_array(self, x: np.ndarray) -> np.ndarray:
        """The ambient current (v_x, v_y) of parameter vectors, m/s, shape (..., 2).

        Zero when the space does not fit a current.
        """
        x = np.asarray(x, dtype=float)
        if not self.current:
            return np.zeros(x.shape[:-1] + (2,))
        return x[..., self.size - len(CURRENT_NAMES) :]

    def coefficients(self, x: np.ndarray) -> FluidCoefficients:
        """The law's coefficient record of one parameter vector."""
        return self.law.coefficients.from_array(self.coefficient_array(x))

    def model_robot(self, robot: Robot) -> Robot:
        """``robot`` as this space's model: its joint table, if it imposes one, and its fluid law.

        The coefficients are the robot's if it has the law, else the middle of the bounds.
        """
        robot = self.joints.impose(robot)
        if robot.fluid_law is self.law:
            return robot
        middle = self.law.bounds.mean(axis=1)
        return robot.with_coefficients(self.law.coefficients.from_array(middle))

    def robots(self, robot: Robot, x: np.ndarray) -> list[Robot]:
        """One robot per parameter vector with its joint parameters set (the coefficients apart).

        Without fitted joint parameters every entry is the same object (the batched kernel lays
        out a robot once per distinct object).
        """
        base = self.model_robot(robot)
        x = np.atleast_2d(x)
        if not self.joints.names:
            return [base] * len(x)
        return [self.joints.apply(base, j) for j in self.joint_array(x)]

    def start(self, robot: Robot) -> np.ndarray:
        """The robot file's values where it has this model's parameters, else the middle.

        The joint parameters start from the joint table the space imposes, if it does.
        """
        middle = self.bounds.mean(axis=1)  # still water for the current
        k = len(self.coefficient_names)
        if robot.fluid_law is self.law:
            middle[:k] = robot.hydrodynamics.as_array()
        joints_robot = self.joints.impose(robot)
        if self.joints.names and joint_model_name(joints_robot) == self.joints.model:
            middle[k : k + len(self.joints.names)] = self.joints.values_of(joints_robot)
        return middle

    def vector(self, coefficients: np.ndarray, robot: Robot) -> np.ndarray:
        """A vector of this space with the law's ``coefficients``, the rest as :meth:`start`.

        The robot file's joint parameters, and still water (besides the declared currents).
        """
        x = self.start(robot)
        x[: len(self.coefficient_names)] = np.asarray(coefficients, dtype=float)
        return x

    def as_dict(self, x: np.ndarray) -> dict[str, float]:
        """Parameter values by name."""
        return {n: float(v) for n, v in zip(self.names, np.asarray(x, float), strict=True)}

    def from_dict(self, values: Mapping[str, Any], where: str = "parameters") -> np.ndarray:
        """A vector from values by name; every name must be there and nothing else.

        Raises
        ------
        ParameterError
            Naming the missing or unknown parameter and ``where`` it was read.
        """
        missing = [n for n in self.names if n not in values]
        unknown = [n for n in values if n not in self.names]
        if missing or unknown:
            what = (f"missing {', '.join(missing)}" if missing else "") + (
                ("; " if missing and unknown else "") + f"unknown {', '.join(unknown)}"
                if unknown
                else ""
            )
            raise ParameterError(
                f"{where}: {what} (model {self.model_name} has {', '.join(self.names)})"
            )
        try:
            out = np.array([float(values[n]) for n in self.names])
        except (TypeError, ValueError):
            raise ParameterError(f"{where}: every value must be a number") from None
        bad = [n for n, v in zip(self.names, out, strict=True) if not np.isfinite(v)]
        if bad:
            raise ParameterError(f"{where}: {', '.join(bad)} must be finite")
        return out

    def at_bound(self, x: np.ndarray, fraction: float = 0.01) -> list[str]:
        """Parameters within ``fraction`` of their search range from a bound (by name).

        A coefficient whose lower bound is 0 and which sits there is reported too: the data may
        simply not need it, and the report says so rather than calling it an estimate.
        """
        u = self.to_unit(np.asarray(x, float))
        return [n for n, v in zip(self.names, u, strict=True) if v <= fraction or v >= 1 - fraction]




def spaces_of(
    robot: Robot,
    laws: Sequence[str],
    current: bool = False,
    joint_models: Sequence[str] | None = None,
) -> list[ParameterSpace]:
    """The candidate models of a robot (docs/estimation.md, "Model comparison").

    Its joint model with each of ``laws``, then each other joint model (of ``joint_models``,
    default every one the twin has) with the robot's fluid law, on the joint table of the
    bundled robot file that uses it (:func:`joint_fit`). Each fits the ambient current too when
    ``current``.
    """
    own = joint_model_name(robot)
    others = default_grid_models(own) if joint_models is None else list(joint_models)
    spaces = [ParameterSpace.for_robot(robot, law, current) for law in laws]
    spaces += [ParameterSpace(robot.fluid_law, joint_fit(robot, model), current=current)
               for model in others if model != own]
    return spaces
