"""What a fit searches: the model's parameters by name, with bounds (docs/estimation.md).

A fit's parameter vector is the fluid law's coefficients (names and default bounds from the law,
``eelsim.fluid.get_fluid_law(name)``; docs/model.md section 6), followed by the joint model's
fitted parameters, if any (names and bounds from the joint model's ``fit_parameters``; the
paper's PD gains stay fixed), followed, when the space
fits one, by the tank's unknown ambient current (``current_x_m_s``, ``current_y_m_s``: a nuisance
shared by the fit's experiments and added to the current each declares; docs/estimation.md,
"Nuisance parameters"). A :class:`ParameterSpace` names them, maps them to and from the unit cube
the optimisers search (linearly onto the bounds), and turns a vector into what the twin runs: the
coefficient record, the robot with the joint parameters set and the ambient current. A space
may impose another joint model than the robot file's (a candidate of the model comparison): it
carries that model's ``[joints]`` table, from the bundled robot file that uses it. A
:class:`FittedModel` is one point of a space: what ``coefficients.json`` stores and
``eelbot validate`` predicts with.

Clock offsets, the other nuisance of the recordings, are not in the vector: they are profiled
per experiment (:mod:`eelhost.estimation.evaluate`), which costs no simulation.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import numpy as np

from eelsim.fluid import FluidCoefficients, FluidLaw, get_fluid_law, law_of
from eelsim.joints import JOINT_MODELS, JointParameters, get_joint_model
from eelsim.robot import BUNDLED_ROBOTS, Robot, load_robot


class ParameterError(ValueError):
    """Parameters that do not fit a model (unknown or missing names, wrong count)."""


# The ambient current's components in the tank frame, m/s (docs/model.md: v_c, the direction it
# flows towards). Cartesian rather than speed and direction: the fitness is smooth in them, with
# no wrap-around and no undefined direction at the still water a clean tank should give.
CURRENT_NAMES = ("current_x_m_s", "current_y_m_s")
# Search bound of each component: residual tank currents (pumps, convection) are mm/s to cm/s;
# the paper's declared current is 0.03 m/s.
CURRENT_BOUND_M_S = 0.03
# Joint models whose parameters a fit keeps as the robot file has them: the paper's PD gains are
# its own (docs/estimation.md, "Fitness"); the twin's other joint models fit their
# ``fit_parameters`` (the servo's lag and motor time constant).
FIXED_JOINT_MODELS = frozenset({"pd"})



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
class JointFit:
    """The joint model of a space and the parameters a fit varies (none for the paper's PD).

    Attributes
    ----------
    model : str
        The joint model's name (as the robot file's ``[joints] model`` says; "pd" for the paper's).
    names : tuple of str
        The fitted parameters.
    bounds : ndarray, shape (k, 2)
    table : JointParameters or None
        The ``[joints]`` table the space puts on the robot (another joint model than the robot
        file's: its fixed parameters and the start of its fitted ones); None keeps the robot's.
    """

    model: str = "pd"
    names: tuple[str, ...] = ()
    bounds: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    table: JointParameters | None = None

    def impose(self, robot: Robot) -> Robot:
        """``robot`` with this space's joint table (the same object when it has it already)."""
        if self.table is None or robot.joints is self.table or robot.joints == self.table:
            return robot
        return robot.with_joints(self.table)

    def values_of(self, robot: Robot) -> np.ndarray:
        """The fitted parameters' values in a robot's joint table (of this model), shape (k,)."""
        if not self.names:
            return np.zeros(0)
        return np.asarray(get_joint_model(self.model).fit_values(robot.joints), dtype=float)

    def apply(self, robot: Robot, values: np.ndarray) -> Robot:
        """The robot (with this model's joint table) with the fitted parameters set to ``values``."""
        if not self.names:
            return robot
        model = get_joint_model(self.model)
        return robot.with_joints(model.with_fit_values(robot.joints, values))


def joint_model_name(robot: Robot) -> str:
    """The name of a robot's joint model ("pd": the paper's joint PD loop)."""
    return joint_model_name_of(robot.joints)


@cache
def bundled_joints(model: str) -> JointParameters:
    """The ``[joints]`` table of the bundled robot file that uses joint model ``model``.

    Raises
    ------
    ParameterError
        When no bundled robot file uses it.
    """
    for name in BUNDLED_ROBOTS:
        joints = load_robot(name).joints
        if joint_model_name_of(joints) == model:
            return joints
    raise ParameterError(
        f"joint model {model!r}: no bundled robot file uses it ({', '.join(BUNDLED_ROBOTS)})"
    )


def joint_model_name_of(joints: JointParameters) -> str:
    """The name of the joint model of a ``[joints]`` table."""
    return str(getattr(joints, "model_name", "") or "pd")


def joint_fit(robot: Robot, model: str | None = None) -> JointFit:
    """The joint model ``model`` (default: the robot's) on ``robot``, and what a fit varies.

    The robot's own model keeps its joint table; another one brings the table of the bundled
    robot file that uses it (:func:`bundled_joints`). The fitted parameters are the model's
    ``fit_parameters``, none for :data:`FIXED_JOINT_MODELS`.
    """
    own = joint_model_name(robot)
    name = own if model is None else model
    table = None if name == own else bundled_joints(name)
    if name in FIXED_JOINT_MODELS:
        return JointFit(name, table=table)
    joints = get_joint_model(name)
    return JointFit(name, joints.fit_names, joints.fit_bounds, table)


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


@dataclass(frozen=True, eq=False)
class FittedModel:
    """One fitted point of a parameter space: what ``coefficients.json`` stores per fit.

    Attributes
    ----------
    space : ParameterSpace
    values : ndarray, shape (K,)
    """

    space: ParameterSpace
    values: np.ndarray

    @property
    def coefficients(self) -> FluidCoefficients:
        """The fluid law's coefficients."""
        return self.space.coefficients(self.values)

    @property
    def current_m_s(self) -> tuple[float, float]:
        """The fitted ambient current (v_x, v_y), m/s ((0, 0) when none is fitted)."""
        vx, vy = self.space.current_array(self.values)
        return float(vx), float(vy)

    def current_text(self) -> str | None:
        """The fitted ambient current in words ("0.0049 m/s towards 123 deg"), None if not fitted."""
        if not self.space.current:
            return None
        vx, vy = self.current_m_s
        return f"{np.hypot(vx, vy):.4f} m/s towards {np.degrees(np.arctan2(vy, vx)):.0f} deg"

    def parameters(self) -> dict[str, float]:
        """Every parameter by name."""
        return self.space.as_dict(self.values)

    def robot(self, robot: Robot) -> Robot:
        """``robot`` as this model: the law, its coefficients and the joint parameters."""
        return self.space.robots(robot, self.values[None])[0].with_coefficients(self.coefficients)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready: the model's names and its parameters by name.

        The coefficients, the joint parameters and, when fitted, the ambient current (with its
        speed and direction for the reader; docs/data.md, "coefficients.json").
        """
        values = self.parameters()
        out: dict[str, Any] = {
            "law": self.space.law.name,
            "joint_model": self.space.joints.model,
            "coefficients": {n: values[n] for n in self.space.coefficient_names},
            "joint_parameters": {n: values[n] for n in self.space.joints.names},
        }
        if self.space.current:
            vx, vy = self.current_m_s
            out["ambient_current"] = {
                **{n: values[n] for n in CURRENT_NAMES},
                # for the reader: the same current as speed and the direction it flows towards
                "speed_m_s": float(np.hypot(vx, vy)),
                "direction_deg": float(np.degrees(np.arctan2(vy, vx))),
            }
        return out

    @classmethod
    def from_json(cls, entry: Any, robot: Robot, where: str) -> FittedModel:
        """A fit as :meth:`to_json` writes it, or as files made before models were named.

        Those have ``coefficients`` alone: the Morison law's, on the robot's joints.

        Raises
        ------
        ParameterError
            Naming ``where`` and what is wrong.
        """
        if not isinstance(entry, dict) or not isinstance(entry.get("coefficients"), dict):
            raise ParameterError(f"{where}: expected a fit with its coefficients by name")
        try:
            law = get_fluid_law(str(entry.get("law", "morison")))
        except ValueError as err:
            raise ParameterError(f"{where}: law: {err}") from None
        joints = entry.get("joint_parameters", {}) or {}
        model = str(entry.get("joint_model", joint_model_name(robot)))
        if model not in JOINT_MODELS:
            raise ParameterError(
                f"{where}: joint_model: unknown joint model {model!r} "
                f"(known: {', '.join(sorted(JOINT_MODELS))})"
            )
        fit = joint_fit(robot, model)
        if tuple(joints) != fit.names:
            raise ParameterError(
                f"{where}: joint_parameters: {', '.join(joints) or 'none'} do not match the "
                f"joint model {model!r} of the robot (fits {', '.join(fit.names) or 'none'})"
            )
        current = entry.get("ambient_current")
        if current is None:
            current = {}
        elif not isinstance(current, dict):
            raise ParameterError(f"{where}: ambient_current: expected {', '.join(CURRENT_NAMES)}")
        else:  # the speed and direction are a reading aid, derived from the components
            current = {k: v for k, v in current.items() if k not in ("speed_m_s", "direction_deg")}
            missing = [n for n in CURRENT_NAMES if n not in current]
            unknown = [n for n in current if n not in CURRENT_NAMES]
            if missing or unknown:
                raise ParameterError(
                    f"{where}: ambient_current: expected {', '.join(CURRENT_NAMES)}"
                    + (f"; missing {', '.join(missing)}" if missing else "")
                    + (f"; unknown {', '.join(unknown)}" if unknown else "")
                )
        space = ParameterSpace(law, fit, current=bool(current))
        return cls(space, space.from_dict({**entry["coefficients"], **joints, **current}, where))

    @classmethod
    def of_coefficients(cls, coefficients: FluidCoefficients, robot: Robot) -> FittedModel:
        """The model of a coefficient record on a robot (its joint model, nothing fitted)."""
        space = ParameterSpace(law_of(coefficients), JointFit(joint_model_name(robot)))
        return cls(space, coefficients.as_array())


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
    others = sorted(JOINT_MODELS) if joint_models is None else list(joint_models)
    spaces = [ParameterSpace.for_robot(robot, law, current) for law in laws]
    spaces += [ParameterSpace(robot.fluid_law, joint_fit(robot, model), current=current)
               for model in others if model != own]
    return spaces
