"""Fluid laws (eelsim.fluid): the registry, each law's readable and batched forms, a new law end to end.

The batched form of a law is the code it writes into the generated kernel; here that text is run
as plain Python (it is Python) for random states and compared with the law's numpy forces. A toy
law with other coefficient names shows that adding a law takes one class and its registration:
robot file, model, dynamics and the batched kernel all follow.
"""

import dataclasses
import math
from typing import Annotated, ClassVar

import numpy as np
import pytest
from pydantic import Field

from eelsim.batch import codegen, run_batch
from eelsim.closed_loop import simulate_closed_loop
from eelsim.dynamics import accelerations, fluid_link_forces
from eelsim.fluid import (
    FLUID_LAWS,
    MORISON,
    FluidCoefficients,
    FluidLaw,
    HydroCoefficients,
    LinkFluid,
    LinkForces,
    LinkMotion,
    get_fluid_law,
    register_fluid_law,
)
from eelsim.fluid.base import law_coefficient_columns
from eelsim.model import SwimmerModel
from eelsim.robot import Robot, load_robot
from eelsim.scenario import load_scenario

_Positive = Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


class ToyCoefficients(FluidCoefficients):
    """Linear drag per metre of link (k_t, k_n), added mass per area of section (k_a)."""

    law_name: ClassVar[str] = "toy_linear"
    k_t: _Positive
    k_n: _Positive
    k_a: _Positive


@dataclasses.dataclass(frozen=True)
class ToyLinks(LinkFluid):
    toy_t: np.ndarray
    toy_n: np.ndarray

    def kernel_values(self):
        return {"toy_t": self.toy_t, "toy_n": self.toy_n}


class ToyLaw(FluidLaw):
    """Linear drag only, no current term, a linear yaw damping: not physics, a test of the seams."""

    name: ClassVar[str] = "toy_linear"
    coefficients: ClassVar[type[FluidCoefficients]] = ToyCoefficients
    default_bounds: ClassVar[tuple[tuple[float, float], ...]] = ((0, 10), (0, 50), (0, 1e4))
    kernel_rows: ClassVar[tuple[str, ...]] = ("toy_t", "toy_n")

    def link_coefficients(self, half_length_m, half_axis_vertical_m, half_axis_horizontal_m,
                          coefficients, water_density_kg_m3):
        l_ = np.asarray(half_length_m, dtype=float)
        a = np.asarray(half_axis_vertical_m, dtype=float)
        k_t, k_n, k_a = law_coefficient_columns(coefficients, 3)
        return ToyLinks(mu_n=k_a * a * a * l_, lambda_1=0.0 * l_, toy_t=k_t * 2 * l_,
                        toy_n=k_n * 2 * l_)

    def forces(self, fluid, motion, current_m_s):
        s, c = motion.sin, motion.cos
        vt = c * motion.rel_vx + s * motion.rel_vy
        vn = -s * motion.rel_vx + c * motion.rel_vy
        fx = -fluid.toy_t * vt * c + fluid.toy_n * vn * s
        fy = -fluid.toy_t * vt * s - fluid.toy_n * vn * c
        return LinkForces(fx, fy, -fluid.toy_n * 1e-3 * motion.omega, {"drag": (fx, fy)})

    def emit_link_forces(self, code, link, still_water):
        w = code.w
        code.line("fl_vt = c * lvx + s * lvy")
        code.line("fl_vn = c * lvy - s * lvx")
        code.line(f"fl_ft = {w('toy_t', link)} * fl_vt")
        code.line(f"fnn = {w('toy_n', link)} * fl_vn")
        code.line("fxn = fl_ft * c - fnn * s")
        code.line("fyn = fl_ft * s + fnn * c")
        code.line(f"tqn = {w('toy_n', link)} * 1e-3 * om")


TOY = ToyLaw()


@pytest.fixture
def toy_law():
    register_fluid_law(TOY)
    yield TOY
    FLUID_LAWS.remove(TOY.name)


def _lane(fluid, r):
    """Run ``r``'s per-link coefficients (a lift variant's hold its base law's: recurse)."""
    return type(fluid)(**{f.name: _lane(value, r) if isinstance(value, LinkFluid) else value[r]
                          for f in dataclasses.fields(fluid)
                          for value in [getattr(fluid, f.name)]})


def _batched_forces(law, n, lanes, rng, still_water):
    """Random link states of ``lanes`` runs; the law's numpy forces and its kernel code's."""
    layout = codegen.make_layout(n, lanes, law)
    low, high = law.bounds[:, 0], law.bounds[:, 1]
    coeffs = rng.uniform(low, high, (lanes, len(low)))
    half = rng.uniform(0.03, 0.08, (lanes, n))
    a = rng.uniform(0.015, 0.04, (lanes, n))
    b = rng.uniform(0.005, 0.015, (lanes, n))
    fluid = law.link_coefficients(half, a, b, coeffs[:, None, :], 1000.0)
    current = np.zeros((lanes, 2)) if still_water else rng.normal(0, 0.05, (lanes, 2))
    theta = rng.uniform(-4, 4, (lanes, n))
    omega = rng.normal(0, 2.0, (lanes, n))
    rel = rng.normal(0, 0.2, (lanes, n, 2))
    work = np.zeros((layout.work_rows + layout.out_rows) * lanes)

    def put(name, link, values):
        row = layout.work[name] + link
        work[row * lanes : (row + 1) * lanes] = values

    for j in range(n):
        put("mu", j, fluid.mu_n[:, j])
        put("half_length", j, half[:, j])
        for name, values in fluid.kernel_values().items():
            put(name, j, values[:, j])
    put("vcx", 0, current[:, 0])
    put("vcy", 0, current[:, 1])
    got = np.zeros((lanes, n, 4))  # fx, fy, n . F, torque
    want = np.zeros((lanes, n, 4))
    for j in range(n):
        emitter = codegen._Emitter(layout)
        codegen.emit_law_forces(emitter, j, still_water)
        program = compile("\n".join(text.strip() for text in emitter.lines), law.name, "exec")
        for r in range(lanes):
            local = {"work": work, "r": r, "s": np.sin(theta[r, j]), "c": np.cos(theta[r, j]),
                     "om": omega[r, j], "h": half[r, j], "lvx": rel[r, j, 0], "lvy": rel[r, j, 1]}
            exec(program, {"np": np, "_vsqrt": math.sqrt}, local)
            got[r, j] = [-local["fxn"], -local["fyn"], -local["fnn"], -local["tqn"]]
    for r in range(lanes):
        one = _lane(fluid, r)
        motion = LinkMotion(np.sin(theta[r]), np.cos(theta[r]), omega[r], rel[r, :, 0],
                            rel[r, :, 1])
        f = law.forces(one, motion, current[r])
        normal = -np.sin(theta[r]) * f.fx + np.cos(theta[r]) * f.fy
        want[r] = np.stack([f.fx, f.fy, normal, f.torque], axis=1)
    return got, want


@pytest.mark.parametrize("law", [*FLUID_LAWS.values(), TOY], ids=lambda law: law.name)
@pytest.mark.parametrize("n_links", [3, 6, 8])
@pytest.mark.parametrize("still_water", [False, True])
def test_each_laws_kernel_code_computes_its_numpy_forces(law, n_links, still_water):
    got, want = _batched_forces(law, n_links, 4, np.random.default_rng(n_links), still_water)
    scale = np.maximum(1.0, np.abs(want))
    assert np.all(np.abs(got - want) <= 1e-12 * scale)
    assert np.any(np.abs(want[..., :2]) > 1e-3)  # the states were not trivially at rest


def test_morison_parts_sum_to_the_force_and_the_current_term_vanishes_in_still_water(model):
    x = np.concatenate([[0.1, 0.3, -0.2, 0.4, 0.0, -0.5], [0.2, 0.1], np.linspace(-1, 1, 6),
                        [0.05, -0.02]])
    moving = fluid_link_forces(model, x, (0.03, -0.02))
    dx, dy = moving.parts["drag"]
    cx, cy = moving.parts["current"]
    assert np.array_equal(moving.fx, dx + cx) and np.array_equal(moving.fy, dy + cy)
    still = fluid_link_forces(model, x)
    assert np.all(still.parts["current"][0] == 0.0) and np.all(still.parts["current"][1] == 0.0)


def test_morison_default_bounds_hold_the_papers_fitted_coefficients():
    bounds = get_fluid_law("morison").bounds
    assert MORISON.coefficient_names == ("C_f", "C_d", "C_a", "C_m")
    for fitted in ([0.008, 0.776, 0.618, 0.007], [0.009, 0.978, 1.169, 0.001]):
        assert np.all((bounds[:, 0] <= fitted) & (fitted <= bounds[:, 1]))


def test_coefficients_convert_to_arrays_and_back_with_their_names_in_errors():
    c = HydroCoefficients(C_f=0.008, C_d=0.776, C_a=0.618, C_m=0.007)
    assert HydroCoefficients.from_array(c.as_array()) == c
    with pytest.raises(ValueError, match=r"expected 4 coefficients \(C_f, C_d, C_a, C_m\), got 3"):
        HydroCoefficients.from_array([1, 2, 3])


def test_an_unknown_law_is_refused_naming_the_known_ones():
    # the list is the registry's, sorted: a plant law registered by another module (the virtual
    # tank's foil) may join it, so the twin's own laws are checked by name, not the whole list
    with pytest.raises(ValueError, match="unknown fluid law 'potential_flow'; known laws: ") as info:
        get_fluid_law("potential_flow")
    known = str(info.value).split("known laws: ")[1].split(", ")
    assert known == sorted(known)
    for law in ("galilean", "lighthill", "linear_quadratic", "morison", "resistive", "reynolds"):
        assert law in known and f"{law}_lift" in known


def test_a_second_law_under_a_taken_name_is_refused(toy_law):
    clash = ToyLaw()
    with pytest.raises(ValueError, match="'toy_linear' is already registered"):
        register_fluid_law(clash)


def test_kernel_code_that_writes_the_sweeps_own_locals_is_refused():
    class Clobbering(ToyLaw):
        def emit_link_forces(self, code, link, still_water):
            super().emit_link_forces(code, link, still_water)
            code.line("s = 0.0")

    layout = codegen.make_layout(3, 4, Clobbering())
    with pytest.raises(ValueError, match=r"fluid law 'toy_linear'.*assigns \['s'\]"):
        codegen.emit_law_forces(codegen._Emitter(layout), 0, False)


def test_kernel_code_that_carries_a_temporary_from_link_to_link_is_refused():
    # each link's force code runs in a lane loop of its own (loop 2ab), so a temporary kept
    # from the link before would read whatever the last lane of another loop left there
    class Carrying(ToyLaw):
        def emit_link_forces(self, code, link, still_water):
            super().emit_link_forces(code, link, still_water)
            code.line("fxn = fxn + fl_sum")
            code.line("fl_sum = fxn")

    layout = codegen.make_layout(3, 4, Carrying())
    with pytest.raises(ValueError, match=r"fluid law 'toy_linear'.*link 1 reads \['fl_sum'\] "
                       "before assigning"):
        codegen.emit_law_forces(codegen._Emitter(layout), 1, False)


@pytest.mark.slow
def test_a_new_law_works_from_the_robot_description_to_the_batched_kernel(toy_law):
    # the robot's [hydrodynamics] names the law and its own coefficients; the model, the
    # dynamics and the batched kernel take them from there, and the kernel agrees with the
    # reference
    data = load_robot().model_dump()
    data["hydrodynamics"] = {"law": "toy_linear", "k_t": 2.0, "k_n": 30.0, "k_a": 500.0}
    robot = Robot.model_validate(data)
    assert isinstance(robot.hydrodynamics, ToyCoefficients)
    assert robot.model_dump()["hydrodynamics"]["law"] == "toy_linear"  # round trip keeps it
    assert Robot.model_validate(robot.model_dump()) == robot
    model = SwimmerModel.from_robot(robot)
    assert model.fluid_law is toy_law
    x = np.concatenate([[0.1, 0.3, -0.2, 0.4, 0.0, -0.5], [0.0, 0.0], np.ones(6), [0.1, 0.0]])
    tdd, pdd = accelerations(model, x, np.zeros(5))
    assert np.all(np.isfinite(tdd)) and pdd[0] < 0  # drag slows the forward motion
    s = load_scenario("straight").model_copy(update={"duration_s": 1.0})
    ref = simulate_closed_loop(robot, s)
    res = run_batch(robot, s, sample_steps=np.arange(len(ref.t_s)), threads=1)
    assert np.allclose(res.states[0], ref.states, rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match=r"shape \(R, 3\) or \(3,\) \(k_t, k_n, k_a\)"):
        run_batch(robot, s, coefficients=[0.008, 0.776, 0.618, 0.007])


def test_a_new_law_joins_the_comparison_only_when_it_declares_itself_a_candidate(toy_law):
    from eelsim.fluid import candidate_laws

    assert toy_law.name in FLUID_LAWS and toy_law.name not in candidate_laws()

    class Candidate(ToyLaw):
        name: ClassVar[str] = "toy_candidate"
        candidate: ClassVar[bool] = True
        coefficients = type("ToyCandidateCoefficients", (ToyCoefficients,),
                            {"__annotations__": {"law_name": ClassVar[str]},
                             "law_name": "toy_candidate"})

    register_fluid_law(Candidate(), "a toy law that asks to be compared")
    try:
        assert candidate_laws()[-1] == "toy_candidate"
    finally:
        FLUID_LAWS.remove("toy_candidate")


def test_a_law_derived_from_a_candidate_and_its_lift_variant_are_not_candidates():
    from eelsim.fluid import with_lift
    from eelsim.fluid.base import declared_candidate
    from eelsim.fluid.morison import MorisonLaw

    class Derived(MorisonLaw):
        """A user's variant of the paper's law, which does not say it is a candidate."""

        name: ClassVar[str] = "derived_morison"

    assert declared_candidate(MORISON) and declared_candidate(FLUID_LAWS["morison_lift"])
    assert not declared_candidate(Derived()) and not declared_candidate(with_lift(Derived()))


def test_a_lift_variant_of_a_users_law_leaves_the_bundled_variants_picklable():
    # the comparison's worker processes get coefficient records by pickle, which finds a class
    # by its module and name: a user's law derived from Morison's (the same coefficients class)
    # must not take morison_lift's names
    import pickle

    from eelsim.fluid import with_lift
    from eelsim.fluid.morison import MorisonLaw

    class Derived(MorisonLaw):
        """A user's variant of the paper's law."""

        name: ClassVar[str] = "derived_morison_pickles"

    bundled = FLUID_LAWS["morison_lift"]
    variant = with_lift(Derived())
    assert variant.coefficients is not bundled.coefficients
    for cls in (bundled.coefficients, type(bundled), variant.coefficients, type(variant)):
        assert pickle.loads(pickle.dumps(cls)) is cls
