"""The candidate family against the plant-only foil water (issue 32; docs/estimation.md, "Lift and
added mass: what the candidates could not hold"): the lift variants' lift and drag rise
(``eelsim.fluid.lift``) and the foil law (``eelhost.data.plant_laws``) are written independently;
where their physics is the same, their forces must be too.
"""

import numpy as np
import pytest

from eelhost.data.plant_laws import FOIL, FoilCoefficients
from eelhost.data.plants import PLANTS
from eelsim.fluid import candidate_laws, get_fluid_law
from eelsim.fluid.base import LinkMotion
from eelsim.robot import load_robot


def _link_forces(law, coefficients, motion):
    robot = load_robot()
    n = len(motion.sin)
    link = robot.link
    fluid = law.link_coefficients(np.full(n, link.half_length_m),
                                  np.full(n, link.half_axis_vertical_m),
                                  np.full(n, link.half_axis_horizontal_m),
                                  np.asarray(coefficients, dtype=float), 1000.0)
    return fluid, law.forces(fluid, motion, np.zeros(2))


def test_the_foil_water_without_zero_angle_drag_is_linear_quadratic_lift_with_no_base_drag():
    # the foil's lift q S C_L sin a cos a is the variant's rho S C_L' w_t w_n / |w| with
    # C_L' = C_L / 2; its sin^2 a drag on the lateral area is the drag rise with C_D_alpha = C_D2,
    # its yaw damping the drag rise's cross-flow moment; added mass and reactive terms the same
    rng = np.random.default_rng(4)
    n = 200
    theta, om = rng.uniform(-np.pi, np.pi, n), rng.normal(0, 3, n)
    rel = rng.normal(0, 0.1, (n, 2))
    rel[:5] *= np.array([1.0, 1e-3])  # a few links nearly along the flow
    motion = LinkMotion(np.sin(theta), np.cos(theta), om, rel[:, 0], rel[:, 1])
    foil = FoilCoefficients(C_D0=0.0, C_D2=1.3, C_L=0.9, C_a=0.7, C_m=0.02)
    law = get_fluid_law("linear_quadratic_lift")
    named = {"C_f_lin": 0.0, "C_d_lin": 0.0, "C_f_quad": 0.0, "C_d_quad": 0.0, "C_a": 0.7,
             "C_m": 0.02, "C_L": 0.45, "C_D_alpha": 1.3, "alpha_stall": np.pi / 2}
    plant_fluid, plant = _link_forces(FOIL, foil.as_array(), motion)
    fluid, candidate = _link_forces(law, [named[k] for k in law.coefficient_names], motion)
    np.testing.assert_allclose(fluid.mu_n, plant_fluid.mu_n, rtol=1e-14)
    np.testing.assert_allclose(fluid.lambda_1, plant_fluid.lambda_1, rtol=1e-14)
    scale = np.abs(plant.fx).max()
    for a, b in ((candidate.fx, plant.fx), (candidate.fy, plant.fy)):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(candidate.torque, plant.torque, rtol=0,
                               atol=1e-12 * np.abs(plant.torque).max())
    # with the foil's zero-angle drag the two differ (|w| w_t against the base's |w_t| w_t)
    _, with_d0 = _link_forces(FOIL, FoilCoefficients(**{**foil.model_dump(), "C_D0": 0.008})
                              .as_array(), motion)
    assert np.abs(with_d0.fx - candidate.fx).max() > 1e-6 * scale


@pytest.mark.parametrize("plant", sorted(n for n, p in PLANTS.items() if p.law == FOIL.name))
def test_every_candidate_laws_box_holds_the_foil_plants_added_mass(plant):
    # a bound is a modelling statement: water that carries no mass along is inside every box
    truths = PLANTS[plant].truths()
    for law_name in candidate_laws():
        law = get_fluid_law(law_name)
        bounds = dict(zip(law.coefficient_names, law.bounds, strict=True))
        for name in ("C_a", "C_m"):
            if name not in bounds:
                continue
            for truth in truths.values():
                value = truth.model_dump()[name]
                assert bounds[name][0] <= value <= bounds[name][1], (law_name, name, value)


def test_the_split_laws_linear_drags_may_vanish():
    # the high-Reynolds-number limit (purely quadratic drag) is inside the split laws' boxes
    for law_name, names in (("linear_quadratic", ("C_f_lin", "C_d_lin")),
                            ("resistive", ("C_t_lin", "C_n_lin"))):
        law = get_fluid_law(law_name)
        bounds = dict(zip(law.coefficient_names, law.bounds, strict=True))
        assert all(bounds[name][0] == 0.0 for name in names)
