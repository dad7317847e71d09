"""``coefficients.json``: the one module that writes and reads it (docs/data.md, "Fitted models").

The file holds its format, the robot fitted (:func:`robot_record`: name, N and a fingerprint of
its geometry, so that coefficients are not used on another robot by mistake) and one fit per
motion type: a :class:`FittedModel` (the fluid law, the joint model and every parameter by name,
the ambient current when fitted) with how it was found (:func:`fit_entry`). ``eelbot report`` adds
its sections (uncertainty, identifiability, ...) through ``extra``. Readers: ``eelbot validate``
(:func:`read_coefficients`, which also takes the coefficients as numbers), the planner's
coefficient model (:func:`read_coefficients_file`, :func:`fitted_models` and the report's
bootstrap, :func:`reported_uncertainty`) and the coverage benchmark
(:func:`prediction_band_coverage`, :func:`reported_uncertainty`).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from eelhost.errors import UserError
from eelhost.estimation.joint_fit import JointFit, ParameterError, joint_fit, joint_model_name
from eelhost.estimation.space import CURRENT_NAMES, ParameterSpace
from eelhost.files import atomic_write
from eelsim.fluid import FluidCoefficients, get_fluid_law, law_of
from eelsim.joints import JOINT_MODELS
from eelsim.robot import Robot

log = logging.getLogger(__name__)


COEFFICIENTS_FORMAT = "eelbot-coefficients/3"
# /1: Morison coefficients only, by name; /2: no ambient current (still water besides the
# declared currents); both still read. /3 is new so that readers of /2, which would ignore a
# fitted current and predict in the wrong water, refuse the file instead.
READABLE_COEFFICIENTS_FORMATS = (
    "eelbot-coefficients/1", "eelbot-coefficients/2", COEFFICIENTS_FORMAT
)


class CoefficientsError(UserError, ValueError):
    """Coefficients that cannot be read (a malformed file or "Cf,Cd,Ca,Cm" argument)."""


@dataclass(frozen=True, eq=False)
class FittedModel:
    """One fitted point of a parameter space: what ``coefficients.json`` stores per fit.

    Attributes
    ----------
    space : ParameterSpace
    values : ndarray, shape (K,)
    """

    space: ParameterSpace
    values: np.ndarray

    @property
    def coefficients(self) -> FluidCoefficients:
        """The fluid law's coefficients."""
        return self.space.coefficients(self.values)

    @property
    def current_m_s(self) -> tuple[float, float]:
        """The fitted ambient current (v_x, v_y), m/s ((0, 0) when none is fitted)."""
        vx, vy = self.space.current_array(self.values)
        return float(vx), float(vy)

    def current_text(self) -> str | None:
        """The fitted ambient current in words ("0.0049 m/s towards 123 deg"), None if not fitted."""
        if not self.space.current:
            return None
        vx, vy = self.current_m_s
        return f"{np.hypot(vx, vy):.4f} m/s towards {np.degrees(np.arctan2(vy, vx)):.0f} deg"

    def parameters(self) -> dict[str, float]:
        """Every parameter by name."""
        return self.space.as_dict(self.values)

    def robot(self, robot: Robot) -> Robot:
        """``robot`` as this model: the law, its coefficients and the joint parameters."""
        return self.space.robots(robot, self.values[None])[0].with_coefficients(self.coefficients)

    def to_json(self) -> dict[str, Any]:
        """JSON-ready: the model's names and its parameters by name.

        The coefficients, the joint parameters and, when fitted, the ambient current (with its
        speed and direction for the reader; docs/data.md, "coefficients.json").
        """
        values = self.parameters()
        out: dict[str, Any] = {
            "law": self.space.law.name,
            "joint_model": self.space.joints.model,
            "coefficients": {n: values[n] for n in self.space.coefficient_names},
            "joint_parameters": {n: values[n] for n in self.space.joints.names},
        }
        if self.space.current:
            vx, vy = self.current_m_s
            out["ambient_current"] = {
                **{n: values[n] for n in CURRENT_NAMES},
                # for the reader: the same current as speed and the direction it flows towards
                "speed_m_s": float(np.hypot(vx, vy)),
                "direction_deg": float(np.degrees(np.arctan2(vy, vx))),
            }
        return out

    @classmethod
    def from_json(cls, entry: Any, robot: Robot, where: str) -> FittedModel:
        """A fit as :meth:`to_json` writes it, or as files made before models were named.

        Those have ``coefficients`` alone: the Morison law's, on the robot's joints.

        Raises
        ------
        ParameterError
            Naming ``where`` and what is wrong.
        """
        if not isinstance(entry, dict) or not isinstance(entry.get("coefficients"), dict):
            raise ParameterError(f"{where}: expected a fit with its coefficients by name")
        try:
            law = get_fluid_law(str(entry.get("law", "morison")))
        except ValueError as err:
            raise ParameterError(f"{where}: law: {err}") from None
        joints = entry.get("joint_parameters", {}) or {}
        model = str(entry.get("joint_model", joint_model_name(robot)))
        if model not in JOINT_MODELS:
            raise ParameterError(
                f"{where}: joint_model: unknown joint model {model!r} "
                f"(known: {', '.join(sorted(JOINT_MODELS))})"
            )
        fit = joint_fit(robot, model)
        if tuple(joints) != fit.names:
            raise ParameterError(
                f"{where}: joint_parameters: {', '.join(joints) or 'none'} do not match the "
                f"joint model {model!r} of the robot (fits {', '.join(fit.names) or 'none'})"
            )
        current = entry.get("ambient_current")
        if current is None:
            current = {}
        elif not isinstance(current, dict):
            raise ParameterError(f"{where}: ambient_current: expected {', '.join(CURRENT_NAMES)}")
        else:  # the speed and direction are a reading aid, derived from the components
            current = {k: v for k, v in current.items() if k not in ("speed_m_s", "direction_deg")}
            missing = [n for n in CURRENT_NAMES if n not in current]
            unknown = [n for n in current if n not in CURRENT_NAMES]
            if missing or unknown:
                raise ParameterError(
                    f"{where}: ambient_current: expected {', '.join(CURRENT_NAMES)}"
                    + (f"; missing {', '.join(missing)}" if missing else "")
                    + (f"; unknown {', '.join(unknown)}" if unknown else "")
                )
        space = ParameterSpace(law, fit, current=bool(current))
        return cls(space, space.from_dict({**entry["coefficients"], **joints, **current}, where))

    @classmethod
    def of_coefficients(cls, coefficients: FluidCoefficients, robot: Robot) -> FittedModel:
        """The model of a coefficient record on a robot (its joint model, nothing fitted)."""
        space = ParameterSpace(law_of(coefficients), JointFit(joint_model_name(robot)))
        return cls(space, coefficients.as_array())



class FitEntry(Protocol):
    """What :func:`write_coefficients` writes per motion type (a fit's result: :func:`fit_entry`)."""

    def to_json(self) -> dict[str, Any]:
        """The fit's entry under ``fits``."""
        ...


def fit_entry(
    method: str, model: FittedModel, fitness: float, evaluations: int, simulations: int,
    history: Sequence[Sequence[float]],
) -> dict[str, Any]:
    """A fit's entry under ``fits``: the model by name and how it was found.

    Parameters
    ----------
    method : str
        The estimator that found it (with its polish, e.g. "cmaes-bipop+minimax").
    model : FittedModel
    fitness : float
    evaluations : int
        Candidates evaluated.
    simulations : int
        Closed-loop runs of the whole fit.
    history : sequence of (generation, best fitness, simulations)
    """
    return {
        "method": method,
        **model.to_json(),
        "fitness": fitness,
        "evaluations": evaluations,
        "simulations": simulations,
        "history": [list(h) for h in history],
    }


def robot_record(robot: Robot) -> dict[str, Any]:
    """What ``coefficients.json`` records of the robot fitted: name, N and a geometry fingerprint.

    The fingerprint is the SHA-256 of the links' geometry, masses and inertias and the water's
    density (what the coefficients were fitted through; docs/data.md, "Fitted models"), not of
    the coefficients or joint parameters, which a fit replaces.
    """
    arrays = robot.link_arrays()
    geometry = {"n_links": robot.n_links, "water_density_kg_m3": robot.water_density_kg_m3,
                **{name: [repr(float(v)) for v in getattr(arrays, name)]
                   for name in ("half_length_m", "half_axis_vertical_m",
                                "half_axis_horizontal_m", "mass_kg", "yaw_inertia_kg_m2")}}
    digest = hashlib.sha256(json.dumps(geometry, sort_keys=True).encode()).hexdigest()
    return {"name": robot.name, "n_links": robot.n_links, "geometry_sha256": digest}


def check_robot(
    data: dict[str, Any], robot: Robot, path: Path, allow_other_robot: bool = False
) -> None:
    """Refuse coefficients fitted on another robot than ``robot`` (unless allowed).

    Raises
    ------
    CoefficientsError
        Naming both robots (name, N, geometry fingerprint) and the option that allows it.
    """
    recorded = data.get("robot")
    if recorded is None:
        log.warning("%s records no robot (written before eelbot recorded one); not checked "
                    "against %s", path, robot.name)
        return
    if not isinstance(recorded, dict):
        raise CoefficientsError(f"{path}: robot: expected a table (name, n_links, geometry_sha256)")
    here = robot_record(robot)
    same = (recorded.get("n_links") == here["n_links"]
            and recorded.get("geometry_sha256") == here["geometry_sha256"])
    if same or allow_other_robot:
        if not same:
            log.warning("%s: fitted on robot %r, used on %r (--allow-other-robot)", path,
                        recorded.get("name"), robot.name)
        return

    def text(r: dict[str, Any]) -> str:
        return (f"{r.get('name')!r} (N = {r.get('n_links')}, geometry "
                f"{str(r.get('geometry_sha256'))[:12]})")

    raise CoefficientsError(
        f"{path}: fitted on robot {text(recorded)}, not on this robot {text(here)}; give the "
        "dataset or --robot it was fitted on, or --allow-other-robot to use it anyway"
    )


def write_coefficients(
    path: str | Path, fits: Mapping[str, FitEntry], extra: dict | None = None,
    robot: Robot | None = None,
) -> Path:
    """Write fitted models as JSON (readable by ``eelbot validate``; docs/estimation.md).

    Each fit names its fluid law and joint model and gives every parameter by name (the
    ambient current, when fitted, under ``ambient_current``); ``robot``, the robot fitted, is
    recorded by :func:`robot_record` so that readers refuse coefficients of another robot.
    """
    data: dict[str, Any] = {"format": COEFFICIENTS_FORMAT}
    if robot is not None:
        data["robot"] = robot_record(robot)
    data["fits"] = {m: r.to_json() for m, r in fits.items()}
    if extra:
        data.update(extra)
    path = Path(path)
    atomic_write(path, json.dumps(data, indent=2) + "\n")  # a full disk keeps the earlier file
    return path


def read_coefficients_file(path: Path) -> dict[str, Any]:
    """The JSON object of a ``coefficients.json`` of a readable format.

    Raises
    ------
    CoefficientsError
        An unreadable file, not an object, or a format this version does not read.
    """
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise CoefficientsError(f"{path}: cannot read coefficients: {err}") from None
    if not isinstance(data, dict):
        raise CoefficientsError(f"{path}: expected a JSON object with fits")
    fmt = data.get("format", READABLE_COEFFICIENTS_FORMATS[0])
    if fmt not in READABLE_COEFFICIENTS_FORMATS:
        raise CoefficientsError(
            f"{path}: format: expected one of {', '.join(READABLE_COEFFICIENTS_FORMATS)}, "
            f"got {fmt!r}"
        )
    return data


def fitted_models(
    data: dict[str, Any], robot: Robot, path: Path, allow_other_robot: bool = False
) -> dict[str, FittedModel]:
    """The fits of a ``coefficients.json`` object, each in the model it names, checked.

    The robot the file records must be ``robot`` (:func:`check_robot`) unless
    ``allow_other_robot``. Every coefficient passes its law's own checks here (e.g.
    non-negative), so a bad value is refused naming the file and the key before anything swims
    with it.

    Raises
    ------
    CoefficientsError
        Naming the file, the fit and what is wrong.
    """
    check_robot(data, robot, path, allow_other_robot)
    fits = data.get("fits")
    if not isinstance(fits, dict) or not fits:
        raise CoefficientsError(f"{path}: fits: expected fitted coefficient sets")
    models = {}
    for motion, entry in fits.items():
        where = f"{path}: fits.{motion}"
        try:
            models[motion] = model = FittedModel.from_json(entry, robot, where)
            model.coefficients  # noqa: B018 (the law's checks, pydantic)
        except ParameterError as err:
            raise CoefficientsError(str(err)) from None
        except ValueError as err:
            first = "; ".join(line.strip() for line in str(err).splitlines()[:3])
            raise CoefficientsError(
                f"{where}.coefficients: not a {entry.get('law', 'morison')} coefficient set "
                f"({first})"
            ) from None
    return models


def read_coefficients(
    spec: str, robot: Robot, allow_other_robot: bool = False
) -> dict[str, FittedModel]:
    """Fitted models from a JSON file written by :func:`write_coefficients`, or numbers.

    Files of the earlier format (Morison coefficients by name, no law) are read as the Morison
    law on the robot's joints. Numbers ("0.008,0.776,0.618,0.007") are the robot's fluid law's
    coefficients in its order, one set for every motion type ("joint").
    """
    path = Path(spec)
    if path.suffix == ".json":
        return fitted_models(read_coefficients_file(path), robot, path, allow_other_robot)
    # the law's coefficients alone, on the robot file's joints as they are (none fitted)
    space = ParameterSpace(robot.fluid_law, JointFit(joint_model_name(robot)))
    names = ",".join(space.names)
    try:
        values = np.array([float(v) for v in spec.split(",")])
    except ValueError:
        raise CoefficientsError(
            f"coefficients: expected a .json file or {names}, got {spec!r}"
        ) from None
    if values.size != space.size:
        raise CoefficientsError(
            f"coefficients: expected {space.size} numbers ({names}), got {values.size} in {spec!r}"
        )
    try:
        space.coefficients(values)  # the law's own checks (e.g. non-negative)
    except ValueError as err:
        raise CoefficientsError(f"coefficients: {spec!r}: {str(err).splitlines()[0]}") from None
    return {"joint": FittedModel(space, values)}


def _finite(value: Any) -> float | None:
    """``value`` as a float when it is a finite number (not a bool), else None."""
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    return None


def _finite_by_name(section: Any) -> dict[str, float]:
    """The finite numbers of an object of parameters by name (others are left out)."""
    if not isinstance(section, dict):
        return {}
    values = {str(name): _finite(v) for name, v in section.items()}
    return {name: v for name, v in values.items() if v is not None}


@dataclass(frozen=True)
class ReportedUncertainty:
    """One fit's entry of the ``uncertainty`` section, as ``eelbot report`` writes it.

    docs/data.md, "coefficients.json"; written from
    :meth:`eelhost.estimation.uncertainty.BootstrapResult.to_json`. Values that are not finite
    numbers are left out, so a reader falls back as if they were not reported.

    Attributes
    ----------
    level : float or None
        The intervals' level, in (0, 1) (None: not given or not a level).
    lower, upper : dict of str to float
        The intervals' ends, by parameter name.
    std : dict of str to float
        The bootstrap replicates' standard deviation (of the declared noise), by name.
    excess : float or None
        The fit's fitness over its noise floor.
    samples : object
        The bootstrap replicates as stored (a list of them by name, or one list per name), not
        checked here; None when not stored.
    """

    level: float | None
    lower: dict[str, float]
    upper: dict[str, float]
    std: dict[str, float]
    excess: float | None
    samples: Any

    @classmethod
    def from_json(cls, entry: Any) -> ReportedUncertainty:
        """The entry as found (anything not an object: nothing reported)."""
        entry = entry if isinstance(entry, dict) else {}
        level = _finite(entry.get("level"))
        return cls(
            level=level if level is not None and 0.0 < level < 1.0 else None,
            lower=_finite_by_name(entry.get("lower")),
            upper=_finite_by_name(entry.get("upper")),
            std=_finite_by_name(entry.get("std")),
            excess=_finite(entry.get("excess")),
            samples=entry.get("samples"),
        )


def reported_uncertainty(data: Mapping[str, Any]) -> dict[str, ReportedUncertainty]:
    """The ``uncertainty`` section of a ``coefficients.json`` object, per fit (motion type).

    Empty when the file has none (``eelbot estimate``, or a report without bootstrap); entries
    that are not objects are left out.
    """
    section = data.get("uncertainty")
    if not isinstance(section, dict):
        return {}
    return {str(motion): ReportedUncertainty.from_json(entry) for motion, entry in section.items()
            if isinstance(entry, dict)}


def prediction_band_coverage(data: Mapping[str, Any], path: str | Path) -> dict[str, float]:
    """The held-out positions' coverage by the report's prediction bands, per motion and "all".

    Raises
    ------
    CoefficientsError
        When the file has no ``prediction_band`` coverage (written by ``eelbot report`` with
        bootstrap replicates only), naming ``path``.
    """
    band = data.get("prediction_band")
    coverage = band.get("coverage") if isinstance(band, dict) else None
    if not isinstance(coverage, dict) or not coverage:
        raise CoefficientsError(f"{path}: prediction_band.coverage: none recorded (eelbot report "
                                "writes it when it bootstraps the fits)")
    found = _finite_by_name(coverage)
    if len(found) != len(coverage):
        raise CoefficientsError(f"{path}: prediction_band.coverage: expected a number per motion")
    return found
