"""Joint models, chosen in the robot file (``[joints] model = "pd"`` or ``"servo"``).

A joint model owns its parameters (the ``[joints]`` table's record, and the ones an estimator may
fit, with bounds), its readable numpy law and its batched form for the generated kernel, and what
explicit RK4 needs of the step (:class:`JointModel`; docs/model.md section 4, "Joint models").
One module per model; each registers itself here, at the bottom of this file.

- ``"pd"`` (the default; the paper's): a PD loop drives free joints with torques;
- ``"servo"``: a hobby position servo (position-loop gain, rate limit, motor lag, optional dead
  zone) whose joint angles follow its law; the torque it must give is computed and saturation
  is counted.

>>> from eelsim.joints import get_joint_model
>>> servo = get_joint_model("servo")
>>> servo.fit_names, servo.fit_bounds
"""

from __future__ import annotations

from typing import Any

from eelsim.joints.base import (
    JointModel,
    JointParameters,
    largest_stable_step,
    parameters_of,
)

DEFAULT_JOINT_MODEL = "pd"
"""The model of a robot file whose ``[joints]`` table names none: the paper's PD loop."""

JOINT_MODELS: dict[str, JointModel] = {}
"""The registered joint models, by name."""


def register_joint_model(model: JointModel) -> JointModel:
    """Make ``model`` available by its name (robot files, batches, the estimator).

    Parameters
    ----------
    model : JointModel

    Returns
    -------
    JointModel
        The model itself.

    Raises
    ------
    ValueError
        When the name is not an identifier (it names kernel modules) or is taken by another
        model, or the model's parameter record does not name it.
    """
    if not model.name.isidentifier():
        raise ValueError(f"a joint model's name must be an identifier, got {model.name!r}")
    if model.name in JOINT_MODELS and JOINT_MODELS[model.name] is not model:
        raise ValueError(f"a joint model named {model.name!r} is already registered")
    if model.parameters.model_name != model.name:
        raise ValueError(
            f"joint model {model.name!r}: its parameter record {model.parameters.__name__} says "
            f"model_name = {model.parameters.model_name!r}"
        )
    JOINT_MODELS[model.name] = model
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
    ValueError
        For an unknown name; the message lists the known ones.
    """
    try:
        return JOINT_MODELS[name]
    except KeyError:
        known = ", ".join(sorted(JOINT_MODELS))
        raise ValueError(f"unknown joint model {name!r}; known models: {known}") from None


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


# ---- the models (one module each)
from eelsim.joints.pd import PD, PDJointParameters, pd_gains, stiffness_hint  # noqa: E402
from eelsim.joints.servo import SERVO, ServoJointParameters  # noqa: E402

for _model in (PD, SERVO):
    register_joint_model(_model)

__all__ = [
    "DEFAULT_JOINT_MODEL",
    "JOINT_MODELS",
    "PD",
    "SERVO",
    "JointModel",
    "JointParameters",
    "PDJointParameters",
    "ServoJointParameters",
    "get_joint_model",
    "joint_model_of",
    "joint_parameters",
    "largest_stable_step",
    "pd_gains",
    "register_joint_model",
    "stiffness_hint",
]
