"""Joint models, chosen in the robot file (``[joints] model = "pd"`` or ``"servo"``).

A joint model owns its parameters (the ``[joints]`` table's record, and the ones an estimator may
fit, with bounds), its readable numpy law and its batched form for the generated kernel, and what
explicit RK4 needs of the step (:class:`JointModel`; docs/model.md section 4, "Joint models").
One module per model, which registers the model beside its definition with
:func:`register_joint_model` in :data:`JOINT_MODELS` (an :class:`eelsim.registry.Registry`);
another package adds its own through the ``eelbot.joint_models`` entry-point group
(docs/architecture.md, "Extension points").

- ``"pd"`` (the default; the paper's): a PD loop drives free joints with torques;
- ``"pd_limited"``: the PD loop clipped to the servo's torque-speed line, the stall torque and
  no-load speed fitted (joins the default comparison after its screen, with the laws it ranks
  best; every law on request);
- ``"servo"``: a hobby position servo (position-loop gain, rate limit, motor lag, optional dead
  zone) whose joint angles follow its law; the torque it must give is computed and saturation
  is counted.

>>> from eelsim.joints import get_joint_model
>>> servo = get_joint_model("servo")
>>> servo.fit_names, servo.fit_bounds
"""

from __future__ import annotations

from typing import Any, TypeVar

from eelsim.joints.base import (
    JointModel,
    JointParameters,
    largest_stable_step,
    parameters_of,
)
from eelsim.registry import Registry, check_kernel_named, import_package_modules

DEFAULT_JOINT_MODEL = "pd"
"""The model of a robot file whose ``[joints]`` table names none: the paper's PD loop."""

def _check_model(name: str, model: JointModel) -> None:
    """Refuse a model that cannot be registered under ``name`` (:func:`register_joint_model`)."""
    check_kernel_named(name, model, JointModel, "joint model")
    if model.parameters.model_name != model.name:
        raise ValueError(
            f"its parameter record {model.parameters.__name__} says "
            f"model_name = {model.parameters.model_name!r}"
        )


_Model = TypeVar("_Model", bound=JointModel)

JOINT_MODELS: Registry[JointModel] = Registry(
    "joint model", "eelbot.joint_models", check=_check_model, plural="models"
)
"""The registered joint models, by name (:mod:`eelsim.registry`; plug-ins: group
``eelbot.joint_models``)."""


def register_joint_model(model: _Model, description: str | None = None) -> _Model:
    """Make ``model`` available by its name (robot files, batches, the estimator).

    Called beside the model's definition: ``PD = register_joint_model(PDJoints(), "...")``.

    Parameters
    ----------
    model : JointModel
    description : str, optional
        One line for help texts (default: the model's class docstring's first line).

    Returns
    -------
    JointModel
        The model itself.

    Raises
    ------
    eelsim.registry.RegistryError
        (a ValueError) When the name is not an identifier (it names kernel modules) or is taken
        by another model, or the model's parameter record does not name it.
    """
    JOINT_MODELS.add(model.name, model, description)
    return model


def get_joint_model(name: str) -> JointModel:
    """The registered joint model called ``name``.

    Parameters
    ----------
    name : str

    Returns
    -------
    JointModel

    Raises
    ------
    eelsim.registry.UnknownNameError
        (a ValueError) For an unknown name; the message lists the known ones.
    """
    return JOINT_MODELS[name]


def joint_model_of(parameters: JointParameters) -> JointModel:
    """The model whose parameters ``parameters`` are.

    Parameters
    ----------
    parameters : JointParameters

    Returns
    -------
    JointModel
    """
    return get_joint_model(type(parameters).model_name)


def default_grid_models(own: str | None = None) -> list[str]:
    """The joint models an estimator's comparison tries unless told which, by name.

    Every model that is ``offered_by_default``, and ``own`` (the robot file's model) whatever
    it says.

    Parameters
    ----------
    own : str, optional

    Returns
    -------
    list of str
        Sorted.
    """
    names = {n for n, m in JOINT_MODELS.items() if m.offered_by_default}
    if own is not None:
        names.add(own)
    return sorted(names)


def after_screen_models(grid: list[str] | tuple[str, ...] = ()) -> list[str]:
    """The joint models that join an estimator's default comparison after its screen, by name.

    Every model that is ``offered_after_screen`` and not in ``grid`` (the joint models already
    compared: a robot file's own ``pd_limited`` is in its grid with every law).

    Parameters
    ----------
    grid : sequence of str

    Returns
    -------
    list of str
        Sorted.
    """
    return sorted(n for n, m in JOINT_MODELS.items() if m.offered_after_screen and n not in grid)


def joint_parameters(table: Any) -> Any:
    """Validate a robot file's ``[joints]`` table (a dict) against its ``model``'s record.

    Parameters
    ----------
    table : dict or JointParameters
        ``model`` (default ``"pd"``) and the model's fields; a record passes through.

    Returns
    -------
    JointParameters
    """
    return parameters_of(table, JOINT_MODELS, DEFAULT_JOINT_MODEL)


# ---- the models: one module each, registering itself beside its definition. The bundled models'
# names are exported here (the default first); then every other module of this package is
# imported, so a new model's module registers with no list edited.
from eelsim.joints.pd import PD, PDJointParameters, pd_gains, stiffness_hint  # noqa: E402
from eelsim.joints.pd_limited import PD_LIMITED, PDLimitedJointParameters  # noqa: E402
from eelsim.joints.servo import SERVO, ServoJointParameters  # noqa: E402

import_package_modules(__name__, __path__)

__all__ = [
    "DEFAULT_JOINT_MODEL",
    "JOINT_MODELS",
    "PD",
    "PD_LIMITED",
    "SERVO",
    "JointModel",
    "JointParameters",
    "default_grid_models",
    "PDJointParameters",
    "PDLimitedJointParameters",
    "ServoJointParameters",
    "get_joint_model",
    "joint_model_of",
    "joint_parameters",
    "largest_stable_step",
    "pd_gains",
    "register_joint_model",
    "stiffness_hint",
]
