"""The test plants: named virtual tanks whose physics the fitted model does not contain.

A test plant (:class:`Plant`) is how the virtual tank records (:class:`TankSettings`) and which
fluid law its water follows, with the truth it swims in; each differs from the fitted model (the
paper's PD joints, Morison water, identical links, causal median) in one way, except ``all``
(docs/estimation.md, "Test plants"). ``eelbot dataset --plant NAME`` records one;
``eelbot estimate-bench`` measures the estimator on every one.

The plants are a registry, :data:`PLANTS` (:class:`eelsim.registry.Registry`; docs/architecture.md,
"Extension points"): each is registered beside its definition with :func:`register_plant`, and
everything that offers a plant (the CLI's choices and help, the benchmarks, the parameterised
tests) reads it. A lab adds its own tank through the ``eelbot.plants`` entry-point group::

    [project.entry-points."eelbot.plants"]
    murky = "mylab.plants:MURKY"    # a Plant whose name is "murky"
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass

from eelhost.data.plant_laws import FOIL_DRAG, QUARTER_CHORD_WATER, STALL_WATER
from eelhost.data.virtual_tank import TABLE3, TankSettings
from eelsim.fluid import DEFAULT_FLUID_LAW, FLUID_LAWS, FluidCoefficients, get_fluid_law
from eelsim.registry import Registry
from eelsim.robot import SERVO_ROBOT, robot_file_text

__all__ = [
    "PLANTS",
    "SMALL_SERVO_STALL_NM",
    "Plant",
    "law_truths",
    "register_plant",
]

# Another law's truth: table 3's added mass and inertia, drag of the law's own form with typical
# values (docs/estimation.md, "Test plants").
_OTHER_LAW_DRAG: dict[str, dict[str, float]] = {
    # Blasius skin friction; a circular cylinder's cross-flow drag
    "reynolds": {"C_f_lam": 1.328, "C_d_inf": 1.0, "C_d_visc": 5.0},
    # skin friction as table 3's C_f, a cylinder's cross-flow drag, a moderate lift
    "foil": FOIL_DRAG,
    # the foil's drag; thin-aerofoil lift up to a 16 deg stall, then the stalled plate's
    "stall": STALL_WATER,
    # the foil's drag; the thin aerofoil's pitching lift at the quarter chord
    "quarter_chord": QUARTER_CHORD_WATER,
}


def law_truths(law: str) -> dict[str, FluidCoefficients]:
    """The true coefficients per motion type of a plant whose water follows ``law``.

    Laws with the paper's four coefficients take table 3's rows; others take table 3's added
    mass and inertia (C_a, C_m) and the drag values of ``_OTHER_LAW_DRAG``.

    Raises
    ------
    ValueError
        When the law is unknown or has no typical drag values here.
    """
    fluid = get_fluid_law(law)
    out: dict[str, FluidCoefficients] = {}
    for motion, row in TABLE3.items():
        paper = row.model_dump()
        # separate linear and quadratic drag equal to the paper's one coefficient: its law
        split = {f"{n}_{part}": paper[n] for n in ("C_f", "C_d") for part in ("lin", "quad")}
        known = {**paper, **split, **_OTHER_LAW_DRAG.get(law, {})}
        missing = [n for n in fluid.coefficient_names if n not in known]
        if missing:
            raise ValueError(
                f"plant law {law!r}: no true value for {', '.join(missing)} (give --truth)"
            )
        out[motion] = fluid.coefficients(**{n: known[n] for n in fluid.coefficient_names})
    return out


@dataclass(frozen=True)
class Plant:
    """A named test plant: how the tank records and which law its water follows.

    Attributes
    ----------
    name : str
        Its registered name (``eelbot dataset --plant NAME``).
    description : str
        One line: what differs from the fitted model.
    settings : TankSettings
    law : str
        The water's fluid law (its truth from :func:`law_truths`).
    truth_overrides : tuple of (str, float)
        Coefficients of the law set otherwise than :func:`law_truths` does (e.g. no added mass).
    """

    name: str
    description: str
    settings: TankSettings
    law: str = DEFAULT_FLUID_LAW
    truth_overrides: tuple[tuple[str, float], ...] = ()

    def truths(self) -> dict[str, FluidCoefficients]:
        """The true coefficients per motion type."""
        fluid = get_fluid_law(self.law)
        return {m: fluid.coefficients.model_validate({**c.model_dump(),
                                                      **dict(self.truth_overrides)})
                for m, c in law_truths(self.law).items()}


def _check_plant(name: str, plant: Plant) -> None:
    """Refuse an object that cannot be registered as the plant ``name`` (:func:`register_plant`)."""
    if not isinstance(plant, Plant):
        raise ValueError(f"expected an eelhost.data.plants.Plant, got {type(plant).__name__}")
    if plant.name != name:
        raise ValueError(f"the plant says its name is {plant.name!r}")
    if not isinstance(plant.settings, TankSettings):
        raise ValueError(f"its settings are a {type(plant.settings).__name__}, not TankSettings")
    if plant.law not in FLUID_LAWS:
        raise ValueError(f"its water's law {plant.law!r} is not a registered fluid law "
                         f"({', '.join(sorted(FLUID_LAWS))})")


PLANTS: Registry[Plant] = Registry("test plant", "eelbot.plants", check=_check_plant,
                                   plural="plants")
"""The registered test plants, by name (:mod:`eelsim.registry`; plug-ins: group ``eelbot.plants``)."""


def register_plant(plant: Plant) -> Plant:
    """Make ``plant`` available by its name (``eelbot dataset --plant``, ``estimate-bench``).

    Called beside the plant's definition: ``HEAD_TAIL = register_plant(Plant("head_tail", ...))``.

    Returns
    -------
    Plant
        The plant itself.

    Raises
    ------
    eelsim.registry.RegistryError
        (a ValueError) When the name is taken by another plant, or the object is not a
        :class:`Plant` of that name with a known fluid law.
    """
    PLANTS.add(plant.name, plant, plant.description)
    return plant


def _joints_of(robot_file: str) -> dict:
    """The ``[joints]`` table of a bundled robot file, as the robot file writes it."""
    return dict(tomllib.loads(robot_file_text(robot_file))["joints"])


SMALL_SERVO_STALL_NM = 0.02
"""The ``servo_limits`` plant's stall torque: a sub-micro servo (about 0.2 kg cm), whose line
binds on the paper's PD joints at the fast gaits (they ask up to 0.037 N m: at A 0.87, omega 3.9
the robot swims 0.29 m in 8 s instead of 0.48 m; at A 0.61, omega 2.7 it is unchanged)."""

STRAY_CURRENT_M_S = 0.005
"""The speed of the current plants' unmodelled current, m/s (docs/estimation.md, "Test plants")."""

_SERVO_JOINTS = _joints_of(SERVO_ROBOT)
"""The bundled servo robot file's joints: stiff position servos with lag."""

HEAD_TAIL = register_plant(Plant(
    "head_tail", "bulkier head and pointed tail", TankSettings(head_tail=True)))

# an undersized servo: the paper's soft PD joints ask at most 0.033 N m, 2.6 % of the robot
# file's 1.26 N m servo, whose line therefore never binds (docs/estimation.md)
SERVO_LIMITS = register_plant(Plant(
    "servo_limits", "PD joints on the torque-speed line of a 0.02 N m servo",
    TankSettings(servo_limits=True, servo_stall_torque_nm=SMALL_SERVO_STALL_NM)))

STRAY_CURRENT = register_plant(Plant(
    "stray_current",
    f"{STRAY_CURRENT_M_S} m/s unmodelled current, a new direction in every experiment",
    TankSettings(stray_current_m_s=STRAY_CURRENT_M_S)))

STEADY_CURRENT = register_plant(Plant(
    "steady_current", f"{STRAY_CURRENT_M_S} m/s unmodelled current towards 120 deg in every "
    "experiment (a tank's residual current)",
    TankSettings(stray_current_m_s=STRAY_CURRENT_M_S, stray_current_direction_deg=120.0)))

# the same current in a tank of stiff servo joints: the joint model whose lag and motor time
# constant trade against an along-track current (docs/estimation.md, "One current for the tank")
SERVO_CURRENT = register_plant(Plant(
    "servo_current", f"{STRAY_CURRENT_M_S} m/s unmodelled current towards 120 deg in every "
    "experiment, on the servo joints",
    TankSettings(joints=_SERVO_JOINTS, stray_current_m_s=STRAY_CURRENT_M_S,
                 stray_current_direction_deg=120.0)))

CENTRED_MEDIAN = register_plant(Plant(
    "centred_median", "recording filtered by a centred median", TankSettings(median="centred")))

STIFF_SERVOS = register_plant(Plant(
    "stiff_servos", "stiff position servos with lag", TankSettings(joints=_SERVO_JOINTS)))

# physical water needs joints that impose the gait: the paper's soft PD joints rely on the
# Morison law's linear drag to hold the wave and swim backwards in it (docs/estimation.md,
# "Test plants")
REYNOLDS = register_plant(Plant(
    "reynolds", "Reynolds-number-dependent drag (a law the estimator does not fit), on the "
    "servo joints", TankSettings(joints=_SERVO_JOINTS), "reynolds"))

# plant-only laws (eelhost.data.plant_laws), on the servo joints for the same reason
FOIL_LIFT = register_plant(Plant(
    "foil_lift", "lift and angle-of-attack-dependent drag on each link (a plant-only law), on "
    "the servo joints", TankSettings(joints=_SERVO_JOINTS), "foil"))

NO_ADDED_MASS = register_plant(Plant(
    "no_added_mass", "the foil water without added mass or added inertia (C_a = C_m = 0: the links "
    "carry no water along), on the servo joints", TankSettings(joints=_SERVO_JOINTS), "foil",
    (("C_a", 0.0), ("C_m", 0.0))))

STALLING_FOIL = register_plant(Plant(
    "stalling_foil", "the foil water whose lift stalls at 16 deg angle of attack, dropping to a "
    "flat plate's (a plant-only law), on the servo joints", TankSettings(joints=_SERVO_JOINTS),
    "stall"))

# a thin aerofoil's circulation from the three-quarter-chord flow and its lift at the quarter
# chord, with the lift slope of a wing of the links' aspect ratio: a lift that depends on the
# links' turning rate and turns them (docs/estimation.md, "Plant-only water: the quarter_chord law")
PITCHING_FOIL = register_plant(Plant(
    "pitching_foil", "the foil water with a pitching thin aerofoil's lift (circulation from the "
    "three-quarter-chord flow, acting at the quarter chord: a plant-only law), on the servo "
    "joints", TankSettings(joints=_SERVO_JOINTS), "quarter_chord"))

ALL = register_plant(Plant(
    "all", "head and tail, servo joints on their torque-speed line, the stray current, a "
    "centred median and Reynolds water at once",
    TankSettings(head_tail=True, servo_limits=True, stray_current_m_s=STRAY_CURRENT_M_S,
                 median="centred", joints=_SERVO_JOINTS), "reynolds"))
