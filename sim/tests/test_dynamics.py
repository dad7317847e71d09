import numpy as np
import pytest
from closed_form_oracle import closed_form_accelerations
from sim_helpers import random_state

from eelsim.dynamics import (
    accelerations,
    link_positions,
    link_velocities,
    mass_matrix,
    split_state,
)
from eelsim.model import SwimmerModel, link_coefficients
from eelsim.robot import HydroCoefficients


def _oracle(model, x, u, vc):
    f = model.fluid
    return closed_form_accelerations(
        model.n_links,
        model.half_length_m[0],
        model.mass_kg[0],
        f.c_t[0],
        f.c_n[0],
        f.mu_n[0],
        f.lambda_1[0],
        f.lambda_2[0],
        f.lambda_3[0],
        x,
        u,
        vc,
    )


@pytest.mark.parametrize("current", [(0.0, 0.0), (0.03, 0.0), (-0.05, 0.04)])
def test_compact_form_matches_papers_closed_form_on_random_states(model, current):
    rng = np.random.default_rng(42)
    for _ in range(20):
        x = random_state(rng, model.n_links)
        u = rng.normal(0, 0.4, model.n_links - 1)
        tdd, pdd = accelerations(model, x, u, current)
        tdd_o, pdd_o = _oracle(model, x, u, np.array(current))
        scale = max(1.0, np.abs(tdd_o).max())
        assert np.allclose(tdd, tdd_o, rtol=0, atol=1e-9 * scale)
        assert np.allclose(pdd, pdd_o, rtol=0, atol=1e-9 * max(1.0, np.abs(pdd_o).max()))


@pytest.mark.parametrize("n_links", [2, 3, 10])
def test_compact_form_matches_closed_form_for_other_link_counts(robot, n_links):
    other = robot.model_copy(update={"n_links": n_links})
    model = SwimmerModel.from_robot(other)
    rng = np.random.default_rng(n_links)
    x = random_state(rng, n_links)
    u = rng.normal(0, 0.3, n_links - 1)
    tdd, pdd = accelerations(model, x, u, (0.02, -0.01))
    tdd_o, pdd_o = _oracle(model, x, u, np.array([0.02, -0.01]))
    assert np.allclose(tdd, tdd_o, atol=1e-9 * max(1, np.abs(tdd_o).max()), rtol=0)
    assert np.allclose(pdd, pdd_o, atol=1e-9, rtol=0)


def test_link_centres_are_chained_head_ahead_and_average_to_centre_of_mass(model):
    rng = np.random.default_rng(0)
    x = random_state(rng, model.n_links)
    theta, p, _, _ = split_state(model, x)
    X, Y = link_positions(model, x)
    lh = model.half_length_m
    assert np.allclose(np.diff(X), lh[:-1] * np.cos(theta[:-1]) + lh[1:] * np.cos(theta[1:]))
    assert np.allclose(np.diff(Y), lh[:-1] * np.sin(theta[:-1]) + lh[1:] * np.sin(theta[1:]))
    assert np.allclose([X.mean(), Y.mean()], p)


def test_link_velocities_are_time_derivatives_of_link_positions(model):
    rng = np.random.default_rng(1)
    x = random_state(rng, model.n_links)
    n = model.n_links
    h = 1e-6
    xdot = np.concatenate([x[n + 2 :], np.zeros(n + 2)])
    Xp, Yp = link_positions(model, x + h * xdot)
    Xm, Ym = link_positions(model, x - h * xdot)
    vx, vy = link_velocities(model, x)
    assert np.allclose((Xp - Xm) / (2 * h), vx, atol=1e-8)
    assert np.allclose((Yp - Ym) / (2 * h), vy, atol=1e-8)


def test_mass_matrix_is_symmetric_positive_definite(model):
    rng = np.random.default_rng(2)
    for _ in range(10):
        m = mass_matrix(model, random_state(rng, model.n_links))
        assert np.allclose(m, m.T, atol=1e-15)
        assert np.linalg.eigvalsh(m).min() > 0


def test_unequal_links_keep_mass_weighted_centre_of_mass(robot):
    data = robot.model_dump()
    data["head"] = {"mass_kg": 0.4, "half_length_m": 0.07}
    data["tail"] = {"mass_kg": 0.1, "half_axis_vertical_m": 0.01}
    other = type(robot).model_validate(data)
    model = SwimmerModel.from_robot(other)
    assert model.mass_kg[-1] == 0.4 and model.mass_kg[0] == 0.1
    x = random_state(np.random.default_rng(3), model.n_links)
    X, Y = link_positions(model, x)
    w = model.mass_kg / model.mass_kg.sum()
    assert np.allclose([w @ X, w @ Y], x[model.n_links : model.n_links + 2])
    m = mass_matrix(model, x)
    assert np.linalg.eigvalsh(m).min() > 0


def test_wrong_torque_shape_is_refused_with_the_expected_shape(model):
    x = random_state(np.random.default_rng(0), model.n_links)
    with pytest.raises(ValueError, match=r"torques must have shape \(5,\)"):
        accelerations(model, x, np.zeros(6))


def test_coefficients_reproduce_kelasidi_generic_robot_values():
    c = link_coefficients(
        0.07, 0.03, 0.05, HydroCoefficients(C_f=0.03, C_d=0.0, C_a=1.0, C_m=1.0), 1000.0
    )
    assert float(c.c_t) == pytest.approx(0.2639, abs=5e-5)
    assert float(c.mu_n) == pytest.approx(0.3958, abs=5e-5)
    assert float(c.lambda_1) == pytest.approx(2.2988e-7, rel=5e-5)
    assert float(c.lambda_2) == pytest.approx(4.3103e-4, rel=5e-5)
    assert float(c.lambda_3) == pytest.approx(2.2629e-5, rel=5e-5)
