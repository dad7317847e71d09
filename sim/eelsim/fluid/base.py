"""What a fluid law is: the interface every law of the water's forces on the links implements.

The dynamics (docs/model.md section 2) fix the structure: each link carries, besides its body's
mass and inertia, an added mass mu_n in its normal direction (the mass matrix's mu_n n n^T) and an
added yaw inertia lambda_1; everything else the water does to a link is a force on its centre and
a torque about it, computed from the link's motion relative to the water and the current. A fluid
law supplies exactly that, in three forms that must agree:

1. its coefficients: the names (``coefficient_names``), a pydantic record of them for the robot
   file's ``[hydrodynamics]`` table (``coefficients``) and the default search bounds of the
   estimator (``bounds``);
2. per-link coefficients from the links' geometry (:meth:`FluidLaw.link_coefficients`),
   broadcasting over runs so that the batched kernel and the readable model share one
   computation;
3. the forces: readable numpy (:meth:`FluidLaw.forces`) and the batched kernel's straight-line
   code for one link (:meth:`FluidLaw.emit_link_forces`), which ``sim/tests/test_fluid.py``
   checks against each other.

docs/model.md ("Fluid laws: how to add one") walks through adding a law.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, Self

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import BaseModel, ConfigDict

FloatArray = NDArray[np.float64]


class FluidCoefficients(BaseModel):
    """The coefficients of one fluid law: the ``[hydrodynamics]`` table of a robot file.

    Each law subclasses this with one float field per coefficient, in ``coefficient_names``
    order, and sets :attr:`law_name`. Unknown keys are refused; values are frozen.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)

    law_name: ClassVar[str] = ""

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The coefficient names, in the order of :meth:`as_array`."""
        return tuple(cls.model_fields)

    def as_array(self) -> FloatArray:
        """Return the coefficients as a float array, in :meth:`names` order."""
        return np.array([getattr(self, name) for name in self.names()], dtype=float)

    @classmethod
    def from_array(cls, values: Any) -> Self:
        """Build from a sequence of numbers in :meth:`names` order.

        Parameters
        ----------
        values : sequence of float

        Returns
        -------
        FluidCoefficients
            An instance of the class it is called on.

        Raises
        ------
        ValueError
            When the count is wrong (the message names the coefficients), or a value is out of
            range (pydantic's ValidationError, a ValueError).
        """
        v = [float(x) for x in values]
        names = cls.names()
        if len(v) != len(names):
            raise ValueError(
                f"expected {len(names)} coefficients ({', '.join(names)}), got {len(v)}"
            )
        return cls(**dict(zip(names, v, strict=True)))

    @classmethod
    def from_text(cls, text: str, base: FluidCoefficients | None = None) -> Self:
        """Build from ``"C_d=0.8,C_a=1.0"`` (by name) or ``"0.008,0.8,1.0,0.01"`` (in order).

        By name, the coefficients not named keep ``base``'s values (all must be named without a
        base); in order, every coefficient is given, in :meth:`names` order.

        Parameters
        ----------
        text : str
            Comma-separated: every item ``NAME=VALUE``, or every item a number.
        base : FluidCoefficients, optional
            Coefficients of the same law whose values the unnamed coefficients keep.

        Returns
        -------
        FluidCoefficients
            An instance of the class it is called on.

        Raises
        ------
        ValueError
            A name the law does not have, a name given twice, a mixture of both forms, the wrong
            count in order, a missing coefficient, a value that is not a finite number: the
            message names the law's coefficients. A value out of range: pydantic's
            ValidationError (a ValueError) naming the field.
        """
        names = cls.names()
        law = f"the {cls.law_name} law's coefficients are {', '.join(names)}"
        items = [item.strip() for item in str(text).split(",") if item.strip()]
        if not items:
            raise ValueError(f"no coefficients in {text!r} ({law})")
        named = ["=" in item for item in items]
        if any(named) and not all(named):
            raise ValueError(f"give all as NAME=VALUE or all as numbers in order, got {text!r} "
                             f"({law})")
        if not all(named):
            if len(items) != len(names):
                raise ValueError(f"expected {len(names)} numbers in order, got {len(items)} in "
                                 f"{text!r} ({law}; or give some as NAME=VALUE)")
            return cls.from_array([_finite(name, item, law) for name, item in zip(names, items,
                                                                                  strict=True)])
        values: dict[str, float] = {}
        for item in items:
            key, _, raw = (part.strip() for part in item.partition("="))
            if key not in names:
                raise ValueError(f"{key!r} is not a coefficient of the {cls.law_name} law ({law})")
            if key in values:
                raise ValueError(f"{key} given twice in {text!r}")
            values[key] = _finite(key, raw, law)
        missing = [name for name in names if name not in values]
        if missing and base is None:
            raise ValueError(f"missing {', '.join(missing)} in {text!r} ({law})")
        if missing and type(base) is not cls:
            raise ValueError(f"missing {', '.join(missing)} in {text!r}, and the values to keep "
                             f"are {type(base).__name__}'s, not {cls.__name__}'s")
        kept = {} if base is None else {name: float(getattr(base, name)) for name in missing}
        return cls(**{name: values.get(name, kept.get(name)) for name in names})


def _finite(name: str, raw: str, law: str) -> float:
    """``raw`` as a finite float, or a ValueError naming the coefficient."""
    try:
        value = float(raw)
    except ValueError:
        raise ValueError(f"{name}={raw!r} is not a number ({law})") from None
    if not math.isfinite(value):
        raise ValueError(f"{name}={raw} is not finite")
    return value


@dataclass(frozen=True)
class LinkFluid:
    """Per-link coefficients of a fluid law, arrays of shape (..., N) (leading axes: runs).

    Every law provides the two the mass matrix needs; a law's subclass adds its own.

    Attributes
    ----------
    mu_n : ndarray
        Added mass in the link's normal direction, kg.
    lambda_1 : ndarray
        Added yaw inertia, kg m^2.
    """

    mu_n: FloatArray
    lambda_1: FloatArray

    def kernel_values(self) -> dict[str, FloatArray]:
        """The law's own per-link rows for the batched kernel, by row name.

        Returns
        -------
        dict
            Row name (one of the law's ``kernel_rows``) -> array of shape (..., N).
        """
        return {}


@dataclass(frozen=True)
class LinkMotion:
    """How each link moves through the water (arrays of shape (N,)).

    Attributes
    ----------
    sin, cos : ndarray
        sin and cos of the link angles theta_i.
    omega : ndarray
        Link angular rates theta_dot_i, rad/s.
    rel_vx, rel_vy : ndarray
        Velocity of each link centre relative to the water (link velocity minus current), m/s.
    """

    sin: FloatArray
    cos: FloatArray
    omega: FloatArray
    rel_vx: FloatArray
    rel_vy: FloatArray


@dataclass(frozen=True)
class LinkForces:
    """What the water does to each link (arrays of shape (N,)), global frame.

    Attributes
    ----------
    fx, fy : ndarray
        Force on the link centre, N (all of it except the added-mass inertia of the mass matrix).
    torque : ndarray
        Torque about the link centre, N m (except the added yaw inertia's).
    parts : dict
        The law's named parts of the force, name -> (fx, fy), for reports and tests; they sum to
        (fx, fy).
    """

    fx: FloatArray
    fy: FloatArray
    torque: FloatArray
    parts: Mapping[str, tuple[FloatArray, FloatArray]]


class KernelCode(Protocol):
    """What a law's batched form writes its code with (``eelsim.batch.codegen``'s emitter)."""

    def line(self, text: str) -> None:
        """Append one statement of the per-lane loop body."""

    def w(self, name: str, index: int = 0) -> str:
        """The expression reading row ``name[index]`` of the current lane."""
        ...


# What the batched form may read and must write (emit_link_forces' contract): the sweep sets
# these locals before the law's code and reads these after it; the law's own temporaries start
# with ``fl_``.
KERNEL_INPUTS = ("s", "c", "om", "h", "lvx", "lvy")
KERNEL_OUTPUTS = ("fxn", "fyn", "fnn", "tqn")
KERNEL_TEMPORARY_PREFIX = "fl_"


def declared_candidate(law: FluidLaw) -> bool:
    """Whether ``law``'s own class sets ``candidate = True`` (a subclass does not inherit it).

    So a law derived from a candidate (a user's variant of Morison's) joins the model
    comparison only when it says so itself.
    """
    return bool(vars(type(law)).get("candidate", False))


class FluidLaw(abc.ABC):
    """A law of the water's forces on the links (see the module docstring).

    Class attributes each law sets
    ------------------------------
    name : str
        What the robot file's ``[hydrodynamics] law`` says.
    coefficients : type of FluidCoefficients
        The record of the law's coefficients (its field names are the coefficient names).
    default_bounds : sequence of (low, high)
        Default search bounds of each coefficient for the estimator, in ``coefficient_names``
        order.
    kernel_rows : tuple of str
        Names of the per-link rows the batched form reads (one row per link each), filled from
        :meth:`LinkFluid.kernel_values`.
    candidate : bool
        Declared by a law meant as a candidate model for fitting: it joins the model
        comparison's default grid (``eelbot report``; :func:`eelsim.fluid.candidate_laws`).
        False by default, and not inherited (only the class that sets it is a candidate), so that
        a new law, even one derived from a candidate, or a law for test plants only, is fitted
        only when asked for by name.
    """

    name: ClassVar[str]
    coefficients: ClassVar[type[FluidCoefficients]]
    default_bounds: ClassVar[Sequence[tuple[float, float]]]
    kernel_rows: ClassVar[tuple[str, ...]]
    candidate: ClassVar[bool] = False

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        """The coefficient names, in array order."""
        return self.coefficients.names()

    @property
    def bounds(self) -> FloatArray:
        """Default search bounds, shape (k, 2): low and high of each coefficient."""
        return np.array(self.default_bounds, dtype=float).reshape(-1, 2)

    @abc.abstractmethod
    def link_coefficients(
        self,
        half_length_m: ArrayLike,
        half_axis_vertical_m: ArrayLike,
        half_axis_horizontal_m: ArrayLike,
        coefficients: ArrayLike,
        water_density_kg_m3: ArrayLike,
    ) -> LinkFluid:
        """Per-link coefficients from the links' geometry and the law's coefficients.

        Parameters
        ----------
        half_length_m, half_axis_vertical_m, half_axis_horizontal_m : array_like
            l, a and b of each link, shape (..., N) (or scalars).
        coefficients : array_like, shape (..., k)
            The law's coefficients in ``coefficient_names`` order; the leading axes broadcast
            against the geometry's (for R runs of N links: geometry (R, N), coefficients
            (R, 1, k)).
        water_density_kg_m3 : array_like
            rho, broadcasting like one coefficient.

        Returns
        -------
        LinkFluid
        """

    @abc.abstractmethod
    def forces(self, fluid: LinkFluid, motion: LinkMotion, current_m_s: FloatArray) -> LinkForces:
        """The water's forces and torques on the links (the readable form).

        Parameters
        ----------
        fluid : LinkFluid
            This law's per-link coefficients (shape (N,)).
        motion : LinkMotion
            The links' angles, rates and velocities relative to the water.
        current_m_s : ndarray, shape (2,)
            The uniform current v_c.

        Returns
        -------
        LinkForces
        """

    @abc.abstractmethod
    def emit_link_forces(self, code: KernelCode, link: int, still_water: bool) -> None:
        """Write the batched form for link ``link``: statements of one lane's loop body.

        Before this code the sweep has set the locals ``s``, ``c`` (sin, cos of the link
        angle), ``om`` (its rate), ``h`` (half-length) and ``lvx``, ``lvy`` (velocity of the link
        centre relative to the water). The code reads rows through ``code.w(name, link)``: its
        own ``kernel_rows``, and of the kernel's rows ``mu`` (added mass), ``half_length``,
        ``vcx``, ``vcy`` (the current). It must assign ``fxn``, ``fyn`` (minus the force, global
        x and y), ``fnn`` (minus its normal component n . F) and ``tqn`` (minus the torque), and
        may use temporaries named ``fl_...``; nothing else. Everything must vectorise across
        lanes: arithmetic, ``abs``, ``min``, ``max``, ``_vsqrt`` (the kernel's square root),
        conditional expressions (the subset ``eelsim.batch.c_stage`` translates to C).

        Parameters
        ----------
        code : KernelCode
            The emitter.
        link : int
            The link's index (0 = tail).
        still_water : bool
            The block has no current (``vcx = vcy = 0``): terms in the current may be left out,
            as long as the numbers stay the same.
        """


def law_coefficient_columns(coefficients: ArrayLike, count: int) -> list[FloatArray]:
    """Split coefficients of shape (..., k) into k arrays of shape (...), checking k.

    Parameters
    ----------
    coefficients : array_like, shape (..., k)
    count : int
        k, the law's number of coefficients.

    Returns
    -------
    list of ndarray
    """
    c = np.asarray(coefficients, dtype=float)
    if c.shape[-1:] != (count,):
        raise ValueError(f"expected {count} coefficients on the last axis, got shape {c.shape}")
    return [c[..., i] for i in range(count)]
