"""Fluid laws, chosen by name in the robot file (``[hydrodynamics] law = "morison"``).

A fluid law owns its coefficients (names, record, default bounds for estimation), its per-link
coefficients, its readable numpy forces and its batched form for the generated kernel
(:class:`FluidLaw`; docs/model.md section 2 and "Fluid laws: how to add one"). One module per law;
each registers itself here, at the bottom of this file.

>>> from eelsim.fluid import get_fluid_law
>>> law = get_fluid_law("morison")
>>> law.coefficient_names, law.bounds

The laws: ``"morison"`` (the paper's, the default), ``"galilean"`` (the paper's coefficients,
Galilean-consistent), ``"linear_quadratic"`` (separate linear and quadratic drag,
Galilean-consistent), ``"lighthill"`` (Lighthill's elongated-body reactive law with the paper's
drag) and ``"resistive"`` (resistive-force drag integrated along each link) are candidate models
for fitting; ``"reynolds"`` (drag with Reynolds-number-dependent coefficients) is for test plants
only (:func:`candidate_laws`). Each has a ``"<law>_lift"`` variant carrying a lift force
(:mod:`eelsim.fluid.lift`), fitted only when named.
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


def candidate_laws() -> tuple[str, ...]:
    """Names of the laws meant as candidate models for fitting (``FluidLaw.candidate``).

    The others (e.g. ``"reynolds"``) are for test plants: virtual tanks whose water the fitted
    model does not contain. The estimator fits any law asked for by name; this is its default
    list of candidates.

    Returns
    -------
    tuple of str
        In registration order (the default law first).
    """
    return tuple(name for name, law in FLUID_LAWS.items() if law.candidate)


# ---- the laws (one module each)
from eelsim.fluid.galilean import GALILEAN, GalileanCoefficients  # noqa: E402
from eelsim.fluid.lift import LiftLaw, with_lift  # noqa: E402
from eelsim.fluid.lighthill import LIGHTHILL, LighthillCoefficients  # noqa: E402
from eelsim.fluid.linear_quadratic import (  # noqa: E402
    LINEAR_QUADRATIC,
    LinearQuadraticCoefficients,
)
from eelsim.fluid.morison import MORISON, HydroCoefficients  # noqa: E402
from eelsim.fluid.resistive import RESISTIVE, ResistiveCoefficients  # noqa: E402
from eelsim.fluid.reynolds import REYNOLDS, ReynoldsCoefficients  # noqa: E402

for _law in (MORISON, GALILEAN, LINEAR_QUADRATIC, LIGHTHILL, RESISTIVE, REYNOLDS):
    register_fluid_law(_law)
# every law above can carry a lift (docs/model.md section 2, "Lift"): the <law>_lift variants
for _base in tuple(FLUID_LAWS.values()):
    register_fluid_law(with_lift(_base))

__all__ = [
    "DEFAULT_FLUID_LAW",
    "FLUID_LAWS",
    "GALILEAN",
    "LIGHTHILL",
    "LINEAR_QUADRATIC",
    "MORISON",
    "RESISTIVE",
    "REYNOLDS",
    "FluidCoefficients",
    "FluidLaw",
    "GalileanCoefficients",
    "HydroCoefficients",
    "KernelCode",
    "LiftLaw",
    "LighthillCoefficients",
    "LinearQuadraticCoefficients",
    "LinkFluid",
    "LinkForces",
    "LinkMotion",
    "ResistiveCoefficients",
    "ReynoldsCoefficients",
    "candidate_laws",
    "get_fluid_law",
    "law_of",
    "register_fluid_law",
    "with_lift",
]
