"""One set of joint parameters for the robot, shared by the straight and turning fits.

docs/estimation.md, "The servo plants' near misses: one servo for the robot (session 15)". The
evaluators are stand-ins whose errors are distances in the unit cube (no simulation): the
straight gaits barely see the joint parameters, the turning gaits do.
"""

import numpy as np

from eelhost.estimation.joint_fit import joint_fit
from eelhost.estimation.optimise import FitResult
from eelhost.estimation.shared_joints import share_joints
from eelhost.estimation.space import ParameterSpace
from eelsim.fluid import get_fluid_law
from eelsim.robot import load_robot


class _Quadratic:
    """Errors |W (u - u*)| in the unit cube plus a floor (the data's noise), one experiment."""

    def __init__(self, space, target, weights):
        self.space, self.target, self.weights = space, np.asarray(target, float), weights
        self.prepared, self.simulations = [None], 0

    def evaluate(self, x):
        d = (self.space.to_unit(x) - self.space.to_unit(self.target)) * self.weights
        self.simulations += len(x)
        vectors = np.concatenate([d, np.full((len(x), 2), 0.1)], axis=1).reshape(len(x), 1, -1, 2)
        return np.linalg.norm(vectors, axis=-1).sum(axis=-1), vectors

    def fitness(self, x):
        return self.evaluate(np.atleast_2d(x))[0].max(axis=1)

    def with_space(self, space):
        return self  # the distances stay in the fit's own unit cube

    def count_from(self, other):
        self.simulations += other.simulations


def _fits(joint_model):
    robot = load_robot()
    space = ParameterSpace(get_fluid_law("morison"), joint_fit(robot, joint_model))
    k, nj = len(space.coefficient_names), len(space.joints.names)
    mid = space.bounds.mean(axis=1)
    fits, evs = {}, {}
    for motion, joints, seen in (("straight", 0.2, 0.01), ("turning", 0.7, 1.0)):
        target = mid.copy()
        if nj:
            target[k:] = space.from_unit(np.full(space.size, joints))[k:]
        ev = _Quadratic(space, target, np.r_[np.ones(k), np.full(nj, seen)])
        fits[motion] = FitResult("cmaes", space, target, float(ev.fitness(target)[0]))
        evs[motion] = ev
    return fits, evs, k, nj


def test_the_joints_the_turning_gaits_see_are_held_in_both_fits():
    fits, evs, k, nj = _fits("servo")
    shared, source = share_joints(fits, evs, lambda _: None)
    assert source == "turning"
    turning_joints = fits["turning"].values[k:k + nj]
    for motion in ("straight", "turning"):
        np.testing.assert_array_equal(shared[motion].values[k:k + nj], turning_joints)
        assert shared[motion].space is fits[motion].space  # the bounds are not narrowed
    # the straight gaits barely see the joints: their fit stays near its own fitness
    assert shared["straight"].fitness < 1.1 * fits["straight"].fitness


def test_a_model_without_fitted_joint_parameters_is_left_as_it_is():
    fits, evs, _, nj = _fits("pd")
    assert nj == 0
    shared, source = share_joints(fits, evs, lambda _: None)
    assert source is None and shared is fits
