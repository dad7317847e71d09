"""The joint model of a fit: which ``[joints]`` table a candidate swims with, and what it varies.

The paper's PD gains stay as the robot file has them (the PD model declares
``fitted_by_estimator = False``); the twin's other joint models fit their ``fit_parameters``
(names and bounds from the joint model, e.g. the servo's lag and motor time constant;
docs/model.md section 4). A candidate of the model comparison may impose another joint model
than the robot file's: it carries that model's ``[joints]`` table, from the bundled robot file
that uses it (docs/estimation.md, "Choosing the model"). :class:`JointFit` is this part of a
:class:`~eelhost.estimation.space.ParameterSpace`; this module is the lowest of the parameter
modules, so :class:`ParameterError` lives here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache

import numpy as np

from eelsim.joints import JointParameters, get_joint_model
from eelsim.robot import BUNDLED_ROBOTS, Robot, load_robot


class ParameterError(ValueError):
    """Parameters that do not fit a model (unknown or missing names, wrong count)."""


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

    A model that no bundled robot file uses but that extends one a file uses (``pd_limited``
    extends ``pd``: ``JointModel.table_from``) takes that file's table as its own.

    Raises
    ------
    ParameterError
        When no bundled robot file uses it or a model it extends.
    """
    for name in BUNDLED_ROBOTS:
        joints = load_robot(name).joints
        if joint_model_name_of(joints) == model:
            return joints
    for name in BUNDLED_ROBOTS:
        made = get_joint_model(model).table_from(load_robot(name).joints)
        if made is not None:
            return made
    raise ParameterError(
        f"joint model {model!r}: no bundled robot file uses it ({', '.join(BUNDLED_ROBOTS)})"
    )


def joint_model_name_of(joints: JointParameters) -> str:
    """The name of the joint model of a ``[joints]`` table."""
    return str(getattr(joints, "model_name", "") or "pd")


def joint_fit(robot: Robot, model: str | None = None) -> JointFit:
    """The joint model ``model`` (default: the robot's) on ``robot``, and what a fit varies.

    The robot's own model keeps its joint table; another one makes its table from the robot's
    where it extends the robot's model (``JointModel.table_from``: the PD loop on the servo line
    from a PD robot file, with that file's gains), else brings the table of the bundled robot
    file that uses it (:func:`bundled_joints`). The fitted parameters are the model's
    ``fit_parameters``, none for a model that declares ``fitted_by_estimator = False`` (the
    paper's PD).
    """
    own = joint_model_name(robot)
    name = own if model is None else model
    table = (None if name == own
             else get_joint_model(name).table_from(robot.joints) or bundled_joints(name))
    joints = get_joint_model(name)
    if not joints.fitted_by_estimator:
        return JointFit(name, table=table)
    return JointFit(name, joints.fit_names, joints.fit_bounds, table)
