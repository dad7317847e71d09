"""Fluid laws, chosen by name in the robot file (``[hydrodynamics] law = "morison"``).

A fluid law owns its coefficients (names, record, default bounds for estimation), its per-link
coefficients, its readable numpy forces and its batched form for the generated kernel
(:class:`FluidLaw`; docs/model.md section 2 and "Fluid laws: how to add one"). One module per law,
which registers the law beside its definition with :func:`register_fluid_law` in
:data:`FLUID_LAWS` (an :class:`eelsim.registry.Registry`); another package adds its own through
the ``eelbot.fluid_laws`` entry-point group (docs/architecture.md, "Extension points").

>>> from eelsim.fluid import get_fluid_law
>>> law = get_fluid_law("morison")
>>> law.coefficient_names, law.bounds

The laws: ``"morison"`` (the paper's, the default), ``"galilean"`` (the paper's coefficients,
Galilean-consistent), ``"linear_quadratic"`` (separate linear and quadratic drag,
Galilean-consistent), ``"lighthill"`` (Lighthill's elongated-body reactive law with the paper's
drag) and ``"resistive"`` (resistive-force drag integrated along each link) are candidate models
for fitting; ``"reynolds"`` (drag with Reynolds-number-dependent coefficients) is for test plants
only (:func:`candidate_laws`). Each has a ``"<law>_lift"`` variant carrying a lift force
(:mod:`eelsim.fluid.lift`). The five candidate laws and their lift variants declare themselves
candidates (``FluidLaw.candidate``): they are the model comparison's default grid.
"""

from __future__ import annotations

from typing import TypeVar

from eelsim.fluid.base import (
    FluidCoefficients,
    FluidLaw,
    KernelCode,
    LinkFluid,
    LinkForces,
    LinkMotion,
    declared_candidate,
)
from eelsim.registry import Registry, check_kernel_named, import_package_modules

DEFAULT_FLUID_LAW = "morison"
"""The law of a robot file whose ``[hydrodynamics]`` table names none: the paper's."""


def _check_law(name: str, law: FluidLaw) -> None:
    """Refuse a law that cannot be registered under ``name`` (:func:`register_fluid_law`)."""
    check_kernel_named(name, law, FluidLaw, "fluid law")
    if law.coefficients.law_name != law.name:
        raise ValueError(
            f"its coefficient record {law.coefficients.__name__} says "
            f"law_name = {law.coefficients.law_name!r}"
        )
    if len(law.default_bounds) != len(law.coefficient_names):
        raise ValueError(
            f"{len(law.default_bounds)} bounds for {len(law.coefficient_names)} coefficients"
        )


_Law = TypeVar("_Law", bound=FluidLaw)

FLUID_LAWS: Registry[FluidLaw] = Registry(
    "fluid law", "eelbot.fluid_laws", check=_check_law, plural="laws"
)
"""The registered laws, by name (:mod:`eelsim.registry`; plug-ins: group ``eelbot.fluid_laws``)."""


def register_fluid_law(law: _Law, description: str | None = None) -> _Law:
    """Make ``law`` available by its name (robot files, batches, the estimator).

    Called beside the law's definition: ``MORISON = register_fluid_law(MorisonLaw(), "...")``.

    Parameters
    ----------
    law : FluidLaw
    description : str, optional
        One line for help texts (default: the law's ``description`` or its class docstring's
        first line).

    Returns
    -------
    FluidLaw
        The law itself.

    Raises
    ------
    eelsim.registry.RegistryError
        (a ValueError) When the name is not an identifier (it names the law's kernel modules) or
        is taken by another law, or the law's coefficient record or bounds do not fit it.
    """
    FLUID_LAWS.add(law.name, law, description)
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
    eelsim.registry.UnknownNameError
        (a ValueError) For an unknown name; the message lists the known ones.
    """
    return FLUID_LAWS[name]


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


def candidate_laws(lift_variants: bool = True) -> tuple[str, ...]:
    """Names of the laws that declare themselves candidates (``FluidLaw.candidate``).

    They make the model comparison's default grid (``eelbot report``,
    :func:`eelhost.estimation.selection.default_laws`). A law is not a candidate unless its own
    class says so (``candidate = True``; a law derived from a candidate does not inherit it):
    the others (``"reynolds"``, a plug-in's new law) are for test plants or are fitted when
    asked for by name. The ``<law>_lift`` variant of a candidate is one too.

    Parameters
    ----------
    lift_variants : bool
        Include the candidates' ``<law>_lift`` variants (False: the base laws only).

    Returns
    -------
    tuple of str
        In registration order: the bundled base laws (the default law first), their lift
        variants, then plug-ins.
    """
    return tuple(name for name, law in FLUID_LAWS.items()
                 if declared_candidate(law)  # its own class says so, not a parent's
                 and (lift_variants or not isinstance(law, LiftLaw)))


# ---- the laws: one module each, registering itself beside its definition. The bundled laws'
# names are exported here, in the order of registration (the default law first); then every
# other module of this package is imported, so a new law's module registers with no list edited.
# isort: off
from eelsim.fluid.morison import MORISON, HydroCoefficients  # noqa: E402
from eelsim.fluid.galilean import GALILEAN, GalileanCoefficients  # noqa: E402
from eelsim.fluid.linear_quadratic import (  # noqa: E402
    LINEAR_QUADRATIC,
    LinearQuadraticCoefficients,
)
from eelsim.fluid.lighthill import LIGHTHILL, LighthillCoefficients  # noqa: E402
from eelsim.fluid.resistive import RESISTIVE, ResistiveCoefficients  # noqa: E402
from eelsim.fluid.reynolds import REYNOLDS, ReynoldsCoefficients  # noqa: E402
from eelsim.fluid.lift import LiftLaw, with_lift  # noqa: E402
# isort: on

import_package_modules(__name__, __path__)

# every bundled law can carry a lift (docs/model.md section 2, "Lift"): the <law>_lift variants
for _entry in FLUID_LAWS.registered():
    register_fluid_law(with_lift(_entry.obj),
                       f"{_entry.description}, plus a lift force (C_L)")

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
