"""What a joint model is: the interface every model of the robot's joints implements.

The robot's joints are hobby servos; the twin can model them in two ways (docs/model.md section
4, "Joint models"), and a joint model says which and supplies, in forms that must agree:

1. its parameters: a pydantic record for the robot file's ``[joints]`` table
   (:class:`JointParameters`, with the fields every model shares: the mechanical limit, the
   reference clamp and the servo's stall torque and no-load speed), and the parameters an
   estimator may fit, by name with bounds (``fit_names``, ``fit_bounds``, :meth:`fit_values`,
   :meth:`with_fit_values`);
2. its law, readable numpy (:meth:`JointModel.drive`): either the joint torques u (``kinematic``
   False: the joints are free pins driven by torques, the full N + 2 dynamics of docs/model.md
   section 2) or the joint accelerations phi_ddot (``kinematic`` True: the joint angles follow the
   law whatever the water does, and x, y and the heading follow from the 3 x 3 reduced system of
   the prescribed-shape dynamics, ``eelsim.dynamics.prescribed_shape_derivative``);
3. its batched form, straight-line code for one joint in the generated kernel
   (:meth:`JointModel.emit_joint`), which ``sim/tests/test_joints.py`` checks against (2);
4. what explicit RK4 needs of the physics step (:meth:`JointModel.largest_stable_step_s`,
   :meth:`JointModel.check_step`).
"""

from __future__ import annotations

import abc
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Protocol, Self

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import BaseModel, ConfigDict, Field, model_validator

if TYPE_CHECKING:
    from eelsim.model import SwimmerModel

FloatArray = NDArray[np.float64]
PositiveFloat = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]
NonNegativeFloat = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]

# What the batched form may read and must write (emit_joint's contract): codegen sets these locals
# for joint jt before the model's code and stores ``jout`` after it; the model's own temporaries
# start with ``jm_``.
KERNEL_INPUTS = ("al", "ald", "ph", "phd")
KERNEL_OUTPUT = "jout"
KERNEL_TEMPORARY_PREFIX = "jm_"


class JointParameters(BaseModel):
    """The ``[joints]`` table of a robot file: what every joint model has, and its own fields.

    Each model subclasses this with its own fields and sets :attr:`model_name`. Unknown keys are
    refused; values are frozen.

    Attributes
    ----------
    limit_rad : float
        Mechanical limit of |phi_j|; exceeding it is a failure (self-collision).
    reference_limit_rad : float, optional
        The joint references are clamped to +-this (default: ``limit_rad``); keep it below the
        mechanical limit so that overshoot stays clear of the stop.
    servo_max_torque_nm, servo_max_speed_rad_s : float
        The hobby servo's stall torque and no-load speed (paper section 4: 1.26 N m, 8 rad/s):
        the torque-speed line against which saturation is counted, the PD loop's optional
        torque limit, and the servo model's rate limit.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, strict=False)

    model_name: ClassVar[str] = ""

    limit_rad: PositiveFloat
    reference_limit_rad: PositiveFloat | None = None
    servo_max_torque_nm: PositiveFloat = 1.26
    servo_max_speed_rad_s: PositiveFloat = 8.0

    @model_validator(mode="after")
    def _reference_inside_mechanical_limit(self) -> Self:
        if self.reference_limit_rad is not None and self.reference_limit_rad > self.limit_rad:
            raise ValueError("reference_limit_rad must not exceed limit_rad")
        return self

    @property
    def command_limit_rad(self) -> float:
        """The clamp applied to joint references."""
        return self.reference_limit_rad if self.reference_limit_rad is not None else self.limit_rad

    @classmethod
    def table_order(cls) -> tuple[str, ...]:
        """Field names as a robot file lists them: the model's own first, then the shared ones."""
        shared = tuple(JointParameters.model_fields)
        return tuple(f for f in cls.model_fields if f not in shared) + shared


class KernelCode(Protocol):
    """What a model's batched form writes its code with (``eelsim.batch.codegen``'s emitter)."""

    def line(self, text: str) -> None:
        """Append one statement of the per-lane loop body."""

    def w(self, name: str, index: int = 0) -> str:
        """The expression reading row ``name[index]`` of the current lane."""
        ...


class JointModel(abc.ABC):
    """A model of the robot's joints (see the module docstring).

    Class attributes each model sets
    --------------------------------
    name : str
        What the robot file's ``[joints] model`` says.
    parameters : type of JointParameters
        The record of the ``[joints]`` table.
    kinematic : bool
        False: the law gives joint torques (free joints); True: joint accelerations
        (prescribed-shape dynamics).
    fit_parameters : sequence of (name, low, high)
        What an estimator may fit, with default bounds (the names :meth:`fit_values` uses).
    kernel_rows : tuple of str
        Names of the per-run rows the batched form reads (one number each), filled from
        :meth:`kernel_values`.
    offered_by_default : bool
        Whether the estimator's model comparison tries it when neither the robot file nor the
        user names it (default True; a model whose candidates would cost the comparison too much
        for what most plants need says False).
    offered_after_screen : bool
        Whether a model not offered by default joins the comparison after its screen, with the
        few laws the screen ranks best for the default grid's models (default False; the PD loop
        on the servo line says True: docs/estimation.md, "Model comparison").
    fitted_by_estimator : bool
        Whether the estimator fits its ``fit_parameters`` (default True); False keeps them as the
        robot file has them (the paper's PD gains are its own: docs/estimation.md, "The protocol").
    """

    name: ClassVar[str]
    parameters: ClassVar[type[JointParameters]]
    kinematic: ClassVar[bool]
    fit_parameters: ClassVar[Sequence[tuple[str, float, float]]]
    kernel_rows: ClassVar[tuple[str, ...]]
    offered_by_default: ClassVar[bool] = True
    offered_after_screen: ClassVar[bool] = False
    fitted_by_estimator: ClassVar[bool] = True

    @property
    def fit_names(self) -> tuple[str, ...]:
        """Names of the parameters an estimator may fit."""
        return tuple(name for name, _, _ in self.fit_parameters)

    @property
    def fit_bounds(self) -> FloatArray:
        """Their default bounds, shape (k, 2)."""
        return np.array([(lo, hi) for _, lo, hi in self.fit_parameters], dtype=float).reshape(
            -1, 2)

    @abc.abstractmethod
    def fit_values(self, spec: JointParameters) -> FloatArray:
        """The fittable parameters' values in ``spec``, in ``fit_names`` order."""

    @abc.abstractmethod
    def with_fit_values(self, spec: JointParameters, values: ArrayLike) -> JointParameters:
        """A copy of ``spec`` with the fittable parameters set to ``values`` (``fit_names`` order)."""

    def table_from(self, spec: JointParameters) -> JointParameters | None:
        """The ``[joints]`` table of this model made from another model's, or None if it cannot be.

        For a model that extends another (the PD loop on the servo line extends the PD loop): a
        comparison candidate of this model on a robot file of the other starts from that file's
        table. None by default: the candidate brings the bundled robot file's table.
        """
        return None

    @abc.abstractmethod
    def drive(
        self,
        spec: JointParameters,
        alpha_rad: FloatArray,
        alpha_dot_rad_s: FloatArray,
        phi_rad: FloatArray,
        phi_dot_rad_s: FloatArray,
    ) -> FloatArray:
        """The law: joint torques (N m) or joint accelerations (rad/s^2), by ``kinematic``.

        Parameters
        ----------
        spec : JointParameters
            This model's parameters.
        alpha_rad, alpha_dot_rad_s : ndarray, shape (N-1,)
            The references (already clamped) and their rates.
        phi_rad, phi_dot_rad_s : ndarray, shape (N-1,)
            Joint angles and rates.

        Returns
        -------
        ndarray, shape (N-1,)
        """

    @abc.abstractmethod
    def kernel_values(self, spec: JointParameters, servo_limits: bool) -> dict[str, float]:
        """The model's per-run rows of the batched kernel, by row name (``kernel_rows``).

        Parameters
        ----------
        spec : JointParameters
        servo_limits : bool
            The loop's option to clip torques to the torque-speed line (``LoopOptions``).
        """

    @abc.abstractmethod
    def emit_joint(self, code: KernelCode, plain: bool) -> None:
        """Write the batched form for one joint: statements of one lane's loop body.

        Before it the sweep has set ``al`` (the clamped reference), ``ald`` (its rate), ``ph``
        and ``phd`` (joint angle and rate). The code reads this model's rows through
        ``code.w(name)``, must assign ``jout`` (the torque, or the joint acceleration for a
        kinematic model) and may use temporaries named ``jm_...``; nothing else, and only
        arithmetic, ``abs``, ``min``, ``max`` and conditional expressions.

        Parameters
        ----------
        code : KernelCode
        plain : bool
            The block's runs have no current and no torque-speed clip (``batch.plain_runs``):
            terms for the clip may be left out as long as the numbers stay the same.
        """

    @abc.abstractmethod
    def largest_stable_step_s(self, spec: JointParameters, model: SwimmerModel) -> float:
        """The largest step at which explicit RK4 is stable on the joints' fast modes, s.

        Parameters
        ----------
        spec : JointParameters
        model : SwimmerModel
            The robot (its inertia sets a free joint's modes).

        Returns
        -------
        float
        """

    @abc.abstractmethod
    def check_step(self, spec: JointParameters, model: SwimmerModel, dt_s: float) -> None:
        """Refuse a step at which RK4 would be unstable (raise ValueError), or accept it.

        A model whose instability the loop's flags catch (the PD law: ill-conditioned, with a
        hint) accepts every step.
        """


def rk4_stable(z: complex) -> bool:
    """True when z = dt lambda lies in explicit RK4's region of absolute stability.

    |1 + z + z^2/2 + z^3/6 + z^4/24| <= 1 (the real axis from -2.785 to 0, the imaginary one up to
    +-2.83 i).
    """
    return abs(1 + z + z * z / 2 + z**3 / 6 + z**4 / 24) <= 1.0


def largest_stable_step(rates: Sequence[complex] | ArrayLike) -> float:
    """Largest dt such that dt lambda is in RK4's stability region for every rate lambda.

    Parameters
    ----------
    rates : sequence of complex
        The linear modes' eigenvalues lambda (Re lambda <= 0), 1/s.

    Returns
    -------
    float
        In s; ``inf`` when every rate is zero.
    """
    best = np.inf
    for lam in np.atleast_1d(np.asarray(rates, dtype=complex)):
        size = abs(lam)
        if size == 0.0:
            continue
        # along the ray dt lambda the region is an interval from 0: bisect its end in |dt lambda|
        lo, hi = 0.0, 3.0
        if rk4_stable(hi * lam / size):
            lo = hi
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if rk4_stable(mid * lam / size):
                lo = mid
            else:
                hi = mid
        best = min(best, lo / size)
    return float(best)


def parameters_of(table: Any, models: Mapping[str, JointModel], default: str) -> Any:
    """Validate a ``[joints]`` table given as a dict against its ``model``'s record."""
    if not isinstance(table, dict):
        return table
    fields = dict(table)
    name = fields.pop("model", default)
    if not isinstance(name, str) or name not in models:
        known = ", ".join(sorted(models))
        raise ValueError(f"model must name a joint model ({known}), got {name!r}")
    return models[name].parameters.model_validate(fields)
