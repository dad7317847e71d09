"""The parameter modules' names from before they were split (kept for old import paths).

What a fit searches is :mod:`eelhost.estimation.space`; the joint model of a fit,
:mod:`eelhost.estimation.joint_fit`; a fitted model as ``coefficients.json`` stores it,
:mod:`eelhost.estimation.coefficients_file`. Nothing in ``eelhost`` imports this module; new code
imports those.
"""

from __future__ import annotations

from eelhost.estimation.coefficients_file import FittedModel
from eelhost.estimation.joint_fit import (
    FIXED_JOINT_MODELS,
    JointFit,
    ParameterError,
    bundled_joints,
    joint_fit,
    joint_model_name,
    joint_model_name_of,
)
from eelhost.estimation.space import (
    CURRENT_BOUND_M_S,
    CURRENT_NAMES,
    ParameterSpace,
    box_from_unit,
    box_to_unit,
    spaces_of,
)

__all__ = ["CURRENT_BOUND_M_S", "CURRENT_NAMES", "FIXED_JOINT_MODELS", "FittedModel", "JointFit",
           "ParameterError", "ParameterSpace", "box_from_unit", "box_to_unit", "bundled_joints",
           "joint_fit", "joint_model_name", "joint_model_name_of", "spaces_of"]
