"""The estimation chain: fit each motion type, validate, quantify uncertainty, write a report.

The methods (``method``: ``cmaes``, the default; ``ga``, the paper's; ``lsq``) are registered by
name in :mod:`eelhost.estimation.methods`, the one place a new estimator is added.

``motion`` is "straight" or "turning" (the paper's separate fits) or "joint" (one coefficient set
for the robot, fitted on the training experiments of both motion types).
"""

from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from eelhost.data.experiments import Dataset, Experiment
from eelhost.errors import UserError
from eelhost.estimation.evaluate import EstimationError, Evaluator
from eelhost.estimation.methods import FitProblem, method_names, run_fit
from eelhost.estimation.optimise import Checkpoint, FitResult
from eelhost.estimation.parameters import (
    FittedModel,
    JointFit,
    ParameterError,
    ParameterSpace,
    joint_model_name,
)
from eelhost.files import atomic_write
from eelsim.robot import Robot

log = logging.getLogger(__name__)

METHODS = method_names()  # as registered when this module is imported


COEFFICIENTS_FORMAT = "eelbot-coefficients/3"
# /1: Morison coefficients only, by name; /2: no ambient current (still water besides the
# declared currents); both still read. /3 is new so that readers of /2, which would ignore a
# fitted current and predict in the wrong water, refuse the file instead.
READABLE_COEFFICIENTS_FORMATS = (
    "eelbot-coefficients/1", "eelbot-coefficients/2", COEFFICIENTS_FORMAT
)


class CoefficientsError(UserError, ValueError):
    """Coefficients that cannot be read (a malformed file or "Cf,Cd,Ca,Cm" argument)."""


@dataclass(frozen=True)
class FitSettings:
    """How a fit is run.

    Attributes
    ----------
    method : str
        A registered method (:mod:`eelhost.estimation.methods`): "cmaes", "ga", ...
    seed : int
    budget : int
        Candidates for CMA-ES over all its runs (the GA's is population x generations).
    pop_size, generations : int
        GA settings (the paper's 150 and 130).
    polish_iterations : int
        Iterations of the local polish after CMA-ES (0: none).
    restarts : str
        CMA-ES restarts: "none", "ipop" or "bipop" (:func:`eelhost.estimation.optimise.fit_cmaes`).
    backend : str
        Evaluator backend ("auto", "batch", "reference").
    align_s : float
        Half-width of each experiment's clock-offset search during fitting (default 0: the
        paper's protocol). With few training experiments the offsets trade off against the
        coefficients (measured: C_a 48 % off on the bundled dataset), so it is off by default.
    fit_current : bool
        Fit the tank's unknown ambient current (v_x, v_y) with the coefficients, a nuisance
        shared by the experiments (:class:`~eelhost.estimation.parameters.ParameterSpace`;
        docs/estimation.md, "Nuisance parameters").
    jobs : int or None
        Worker processes of the model comparison's independent fits (docs/estimation.md,
        "Choosing the model"); None: one per core, 1: in this process. The scores do not
        depend on it.
    """

    method: str = "cmaes"
    seed: int = 0
    budget: int = 1500
    pop_size: int = 150
    generations: int = 130
    polish_iterations: int = 30
    backend: str = "auto"
    align_s: float = 0.0
    restarts: str = "bipop"
    fit_current: bool = True
    jobs: int | None = None


def training_experiments(dataset: Dataset, motion: str) -> list[Experiment]:
    """The training experiments of a motion type ("joint": of all motion types)."""
    if motion == "joint":
        return [e for exps in dataset.train.values() for e in exps]
    if motion not in dataset.train:
        raise EstimationError(
            f"dataset has no training experiments for motion {motion!r} (has {sorted(dataset.train)})"
        )
    return list(dataset.train[motion])


def fit_motion(
    dataset: Dataset,
    motion: str,
    settings: FitSettings,
    checkpoint_dir: str | Path | None = None,
    resume: bool = False,
    progress: Callable[[int, float, int], None] | None = None,
    start: np.ndarray | None = None,
    map_function: Callable | None = None,
    space: ParameterSpace | None = None,
    experiments: list[Experiment] | None = None,
) -> tuple[FitResult, Evaluator]:
    """Fit the parameters of one motion type.

    Parameters
    ----------
    dataset : Dataset
    motion : str
        "straight", "turning" or "joint".
    settings : FitSettings
    checkpoint_dir : str or Path, optional
        Where to keep the per-generation checkpoint.
    resume : bool
        Continue from a checkpoint.
    progress : callable, optional
        (generation, best fitness, simulations).
    start : ndarray, optional
        Start of the local methods, a vector of the space (default: the robot file's values).
    map_function : callable, optional
        Spreads the evaluation (e.g. a Dask client's map).
    space : ParameterSpace, optional
        The candidate model (default: the dataset robot's fluid law and joint model, with the
        ambient current when ``settings.fit_current``).
    experiments : list of Experiment, optional
        Fit these instead of the motion's training experiments (cross-validation folds).

    Returns
    -------
    (FitResult, Evaluator)
        The result (``evaluations`` counts candidates; the evaluator's ``simulations`` counts runs).
    """
    space = space or ParameterSpace.for_robot(dataset.robot, current=settings.fit_current)
    ev = Evaluator(
        dataset.robot,
        experiments if experiments is not None else training_experiments(dataset, motion),
        backend=settings.backend,
        align_s=settings.align_s,
        map_function=map_function,
        space=space,
    )
    ck = None
    if checkpoint_dir is not None:
        # (the comparison's worker count changes no result: a resume with another one continues)
        ident = {"dataset": str(dataset.folder.resolve()), "motion": motion,
                 "model": space.model_name,
                 **{k: v for k, v in settings.__dict__.items() if k != "jobs"}}
        tag = space.model_name.replace(" x ", "_")
        ck = Checkpoint(
            Path(checkpoint_dir) / f"checkpoint_{motion}_{tag}_{settings.method}.npz", ident
        )
    begin = space.start(dataset.robot) if start is None else np.asarray(start, dtype=float)
    problem = FitProblem(ev, settings, begin, ck, resume, progress)
    res = run_fit(problem)
    return res, ev


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
    path: str | Path, fits: dict[str, FitResult], extra: dict | None = None,
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
