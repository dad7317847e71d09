"""Robot description: a TOML file, validated on load.

A robot file gives the geometry and mass of the links (with optional head and tail overrides), the
water density, the fluid law and its coefficients (``[hydrodynamics]``: ``law``, default
``"morison"``, and e.g. the paper's e = (C_f, C_d, C_a, C_m); see :mod:`eelsim.fluid`), the joint
model and its parameters and limits (``[joints]``: ``model``, default ``"pd"``, the paper's PD
gains, or ``"servo"``, a hobby servo; see :mod:`eelsim.joints`), and an ``[assumptions]`` table
naming every value that was assumed rather than measured, with the reason. Unknown keys are refused at every level; every number must be finite.
Errors name the file and the dotted key that is wrong (docs/model.md section 8).

The bundled default, ``paper_robot.toml``, is the robot of Raj & Thakur (N = 6, BL about 0.64 m).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from numpy.typing import NDArray
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SerializationInfo,
    SerializeAsAny,
    SerializerFunctionWrapHandler,
    ValidationError,
    field_serializer,
    field_validator,
    model_validator,
)

from eelsim.fluid import (
    DEFAULT_FLUID_LAW,
    FluidCoefficients,
    FluidLaw,
    HydroCoefficients,
    get_fluid_law,
    law_of,
)
from eelsim.joints import (
    DEFAULT_JOINT_MODEL,
    JointModel,
    JointParameters,
    joint_model_of,
    joint_parameters,
)
from eelsim.tomlfile import parse_toml, read_toml, validation_message

__all__ = [
    "BUNDLED_ROBOTS",
    "DEFAULT_ROBOT",
    "SERVO_ROBOT",
    "HydroCoefficients",
    "JointParameters",
    "LinkArrays",
    "LinkOverride",
    "LinkSpec",
    "Robot",
    "RobotFileError",
    "bundled_robot",
    "load_robot",
    "parse_robot",
    "robot_file_text",
]

FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
PositiveFloat = Annotated[float, Field(gt=0.0, allow_inf_nan=False)]

DEFAULT_ROBOT = "paper_robot.toml"
SERVO_ROBOT = "servo_robot.toml"
"""The paper's robot with hobby-servo joints (``[joints] model = "servo"``), bundled too."""
BUNDLED_ROBOTS = (DEFAULT_ROBOT, SERVO_ROBOT)


class RobotFileError(ValueError):
    """A robot description that cannot be used; the message names the file and the key."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class LinkSpec(_Strict):
    """Geometry and mass of one link (an elliptic cylinder of length 2 l).

    Attributes
    ----------
    half_length_m : float
        l, half the link length.
    half_axis_vertical_m : float
        a, the major (vertical) half-axis of the elliptical cross-section.
    half_axis_horizontal_m : float
        b, the minor (horizontal) half-axis.
    mass_kg : float
        m, the link's mass; its yaw inertia is m l^2 / 3 unless ``yaw_inertia_kg_m2`` is given.
    yaw_inertia_kg_m2 : float, optional
        J, the link's yaw inertia about its centre.
    """

    half_length_m: PositiveFloat
    half_axis_vertical_m: PositiveFloat
    half_axis_horizontal_m: PositiveFloat
    mass_kg: PositiveFloat
    yaw_inertia_kg_m2: PositiveFloat | None = None

    def yaw_inertia_or_default_kg_m2(self) -> float:
        """J: ``yaw_inertia_kg_m2`` when given, else that of a slender rod, m l^2 / 3.

        The one place that default lives (docs/model.md section 1).
        """
        if self.yaw_inertia_kg_m2 is not None:
            return self.yaw_inertia_kg_m2
        return self.mass_kg * self.half_length_m**2 / 3.0


@dataclass(frozen=True)
class LinkArrays:
    """The links of a robot as arrays of shape (N,), tail first (what the dynamics need).

    Attributes
    ----------
    half_length_m, half_axis_vertical_m, half_axis_horizontal_m, mass_kg : ndarray
        l, a, b and m of each link.
    yaw_inertia_kg_m2 : ndarray
        J of each link (:meth:`LinkSpec.yaw_inertia_or_default_kg_m2`).
    """

    half_length_m: NDArray[np.float64]
    half_axis_vertical_m: NDArray[np.float64]
    half_axis_horizontal_m: NDArray[np.float64]
    mass_kg: NDArray[np.float64]
    yaw_inertia_kg_m2: NDArray[np.float64]


class LinkOverride(_Strict):
    """Per-link values that replace the body link's for the head or the tail (all optional)."""

    half_length_m: PositiveFloat | None = None
    half_axis_vertical_m: PositiveFloat | None = None
    half_axis_horizontal_m: PositiveFloat | None = None
    mass_kg: PositiveFloat | None = None
    yaw_inertia_kg_m2: PositiveFloat | None = None


class Robot(_Strict):
    """A whole robot description. See the module docstring and ``docs/model.md``."""

    name: str
    n_links: int = Field(ge=2, le=64)
    water_density_kg_m3: PositiveFloat = 1000.0
    link: LinkSpec
    head: LinkOverride | None = None
    tail: LinkOverride | None = None
    hydrodynamics: SerializeAsAny[FluidCoefficients]
    joints: SerializeAsAny[JointParameters]
    assumptions: dict[str, str] = Field(default_factory=dict)

    @field_validator("hydrodynamics", mode="before")
    @classmethod
    def _coefficients_of_the_named_law(cls, value: Any) -> Any:
        """Validate the table against the coefficients of its ``law`` (default: morison)."""
        if isinstance(value, dict):
            fields = dict(value)
            name = fields.pop("law", DEFAULT_FLUID_LAW)
            if not isinstance(name, str):
                raise ValueError(f"law must be the name of a fluid law, got {name!r}")
            return get_fluid_law(name).coefficients.model_validate(fields)
        return value

    @field_serializer("hydrodynamics", mode="wrap")
    def _with_the_law_unless_default(
        self, value: FluidCoefficients, handler: SerializerFunctionWrapHandler,
        info: SerializationInfo,
    ) -> Any:
        """The table as in a robot file: ``law`` first, left out for the default law."""
        table = handler(value)
        if type(value).law_name == DEFAULT_FLUID_LAW:
            return table
        return {"law": type(value).law_name, **table}

    @field_validator("joints", mode="before")
    @classmethod
    def _parameters_of_the_named_joint_model(cls, value: Any) -> Any:
        """Validate the table against the parameters of its ``model`` (default: pd)."""
        return joint_parameters(value)

    @field_serializer("joints", mode="wrap")
    def _with_the_model_unless_default(
        self, value: JointParameters, handler: SerializerFunctionWrapHandler,
        info: SerializationInfo,
    ) -> Any:
        """The table as in a robot file: ``model`` first, left out for the default.

        Then the model's own fields, then the shared ones.
        """
        table = handler(value)
        ordered = {k: table[k] for k in type(value).table_order() if k in table}
        if type(value).model_name == DEFAULT_JOINT_MODEL:
            return ordered
        return {"model": type(value).model_name, **ordered}

    @model_validator(mode="after")
    def _assumptions_name_real_keys(self) -> Robot:
        for key in self.assumptions:
            if not _has_key(self, key):
                raise ValueError(f"assumptions: '{key}' names no key of the robot description")
        return self

    def links(self) -> list[LinkSpec]:
        """Return the N links, tail (link 1) first, with the head/tail overrides applied."""
        body = self.link.model_dump()
        out: list[LinkSpec] = []
        for i in range(self.n_links):
            values = dict(body)
            override = self.tail if i == 0 else self.head if i == self.n_links - 1 else None
            if override is not None:
                values.update({k: v for k, v in override.model_dump().items() if v is not None})
            out.append(LinkSpec(**values))
        return out

    def link_arrays(self) -> LinkArrays:
        """Return the links' geometry, masses and inertias as arrays, tail first."""
        links = self.links()
        return LinkArrays(
            half_length_m=np.array([lk.half_length_m for lk in links]),
            half_axis_vertical_m=np.array([lk.half_axis_vertical_m for lk in links]),
            half_axis_horizontal_m=np.array([lk.half_axis_horizontal_m for lk in links]),
            mass_kg=np.array([lk.mass_kg for lk in links]),
            yaw_inertia_kg_m2=np.array([lk.yaw_inertia_or_default_kg_m2() for lk in links]),
        )

    def body_length_m(self) -> float:
        """Return BL, the total length of the robot (sum of the link lengths)."""
        return float(sum(2.0 * lk.half_length_m for lk in self.links()))

    @property
    def fluid_law(self) -> FluidLaw:
        """The fluid law of the robot's hydrodynamic coefficients."""
        return law_of(self.hydrodynamics)

    @property
    def joint_model(self) -> JointModel:
        """The joint model of the robot's ``[joints]`` table."""
        return joint_model_of(self.joints)

    def with_joints(self, joints: JointParameters) -> Robot:
        """Return a copy of this robot with other joints (of any model)."""
        return self.model_copy(update={"joints": joints})

    def with_coefficients(self, coeffs: FluidCoefficients) -> Robot:
        """Return a copy of this robot with other hydrodynamic coefficients (of any law)."""
        return self.model_copy(update={"hydrodynamics": coeffs})


def _has_key(model: BaseModel, dotted: str) -> bool:
    node: Any = model
    for part in dotted.split("."):
        if isinstance(node, BaseModel) and part in type(node).model_fields:
            node = getattr(node, part)
        else:
            return False
    return True


def parse_robot(data: dict[str, Any], source: str = "<robot>") -> Robot:
    """Validate a robot description given as a dictionary.

    Parameters
    ----------
    data : dict
        The parsed TOML content.
    source : str
        Where the data came from, used in error messages.

    Returns
    -------
    Robot

    Raises
    ------
    RobotFileError
        When a key is unknown, missing, of the wrong type, out of range or not finite.
    """
    try:
        return Robot.model_validate(data)
    except ValidationError as err:
        raise RobotFileError(validation_message(source, err, "robot description")) from None


def load_robot(path: str | Path | None = None) -> Robot:
    """Load and validate a robot TOML file; ``None`` loads the bundled paper robot.

    Parameters
    ----------
    path : str or Path, optional
        The robot file. ``None`` or the bare name ``paper_robot.toml`` selects the bundled default;
        ``servo_robot.toml`` (when no such file is in the working folder) the bundled robot with
        servo joints.

    Returns
    -------
    Robot

    Raises
    ------
    RobotFileError
        When the file is missing, is not valid TOML, or fails validation; the message names the
        file and the offending key.
    """
    bundled = bundled_robot(path)
    if bundled is not None:
        source = f"<bundled {bundled}>"
        data = parse_toml(robot_file_text(path), source, RobotFileError)
    else:
        source = str(path)
        data = read_toml(Path(source), RobotFileError, "robot file")
    return parse_robot(data, source)


def bundled_robot(path: str | Path | None) -> str | None:
    """The bundled robot file a ``--robot`` value names, or None for a file of the user's.

    ``None`` and ``paper_robot.toml`` name the bundled default; ``servo_robot.toml`` the bundled
    servo robot when no such file is in the working folder (as :func:`load_robot` reads them).
    """
    name = DEFAULT_ROBOT if path is None else str(path)
    if name == DEFAULT_ROBOT or (name in BUNDLED_ROBOTS and not Path(name).exists()):
        return name
    return None


def robot_file_text(path: str | Path | None) -> str:
    """The text of the robot file :func:`load_robot` reads for ``path``, bundled ones included.

    Kept beside what was made with the robot (a take, a dataset), so the record names its robot.

    Raises
    ------
    OSError
        When a file of the user's cannot be read.
    """
    bundled = bundled_robot(path)
    if bundled is not None:
        return resources.files("eelsim.data").joinpath(bundled).read_text()
    return Path(str(path)).read_text()
