"""Fluid laws, chosen by name in the robot file (``[hydrodynamics] law = "morison"``).

A fluid law owns its coefficients (names, record, default bounds for estimation), its per-link
coefficients, its readable numpy forces and its batched form for the generated kernel
(:class:`FluidLaw`; docs/model.md section 2 and "Fluid laws: how to add one"). One module per law;
each registers itself here, at the bottom of this file.

>>> from eelsim.fluid import get_fluid_law
>>> law = get_fluid_law("morison")
>>> law.coefficient_names, law.bounds
"""

from __future__ import annotations

from eelsim.fluid.base import (
    FluidCoefficients,
    FluidLaw,
    KernelCode,
    LinkFluid,
    LinkForces,
    LinkMotion,
)

DEFAULT_FLUID_LAW = "morison"
"""The law of a robot file whose ``[hydrodynamics]`` table names none: the paper's."""

FLUID_LAWS: dict[str, FluidLaw] = {}
"""The registered laws, by name."""


def register_fluid_law(law: FluidLaw) -> FluidLaw:
    """Make ``law`` available by its name (robot files, batches, the estimator).

    Parameters
    ----------
    law : FluidLaw

    Returns
    -------
    FluidLaw
        The law itself.

    Raises
    ------
    ValueError
        When the name is not an identifier (it names the law's kernel modules) or is taken by
        another law, or the law's coefficient record or bounds do not fit it.
    """
    if not law.name.isidentifier():
        raise ValueError(f"a fluid law's name must be an identifier, got {law.name!r}")
    if law.name in FLUID_LAWS and FLUID_LAWS[law.name] is not law:
        raise ValueError(f"a fluid law named {law.name!r} is already registered")
    if law.coefficients.law_name != law.name:
        raise ValueError(
            f"fluid law {law.name!r}: its coefficient record {law.coefficients.__name__} says "
            f"law_name = {law.coefficients.law_name!r}"
        )
    if len(law.default_bounds) != len(law.coefficient_names):
        raise ValueError(
            f"fluid law {law.name!r}: {len(law.default_bounds)} bounds for "
            f"{len(law.coefficient_names)} coefficients"
        )
    FLUID_LAWS[law.name] = law
    return law


def get_fluid_law(name: str) -> FluidLaw:
    """The registered law called ``name``.

    Parameters
    ----------
    name : str

    Returns
    -------
    FluidLaw

    Raises
    ------
    ValueError
        For an unknown name; the message lists the known ones.
    """
    try:
        return FLUID_LAWS[name]
    except KeyError:
        known = ", ".join(sorted(FLUID_LAWS))
        raise ValueError(f"unknown fluid law {name!r}; known laws: {known}") from None


def law_of(coefficients: FluidCoefficients) -> FluidLaw:
    """The law whose coefficients ``coefficients`` are.

    Parameters
    ----------
    coefficients : FluidCoefficients

    Returns
    -------
    FluidLaw
    """
    return get_fluid_law(type(coefficients).law_name)


# ---- the laws (one module each)
from eelsim.fluid.morison import MORISON, HydroCoefficients  # noqa: E402

register_fluid_law(MORISON)

__all__ = [
    "DEFAULT_FLUID_LAW",
    "FLUID_LAWS",
    "FluidCoefficients",
    "FluidLaw",
    "HydroCoefficients",
    "KernelCode",
    "LinkFluid",
    "LinkForces",
    "LinkMotion",
    "MORISON",
    "get_fluid_law",
    "law_of",
    "register_fluid_law",
]
