"""The minimax trust-region polish (estimation/local.py)."""

import numpy as np

from eelhost.estimation.local import polish_minimax
from eelhost.estimation.space import ParameterSpace
from eelsim.robot import load_robot

TARGET_U = np.array([0.3, 0.3, 0.4, 0.4])


def _evaluate(space, edge_u):
    """Two residual 2-vectors pointing to TARGET_U; every run fails beyond ``edge_u`` in u_0."""

    def evaluate(x):
        u = space.to_unit(np.atleast_2d(x))
        d = u - TARGET_U
        vectors = np.stack([d[:, :2], d[:, 2:]], axis=1)[:, None]  # (C, E=1, m=2, 2)
        errors = np.linalg.norm(vectors, axis=-1).sum(axis=-1)  # (C, 1)
        failed = u[:, 0] > edge_u
        errors[failed] = 1e6  # a penalty: no residuals
        vectors[failed] = np.nan
        return errors, vectors

    return evaluate


def test_a_parameter_whose_forward_perturbation_fails_is_probed_backwards_not_frozen():
    # the start sits exactly on the edge of a failing region (e.g. a run just arriving before
    # the too-slow limit): its forward perturbation fails, the backward one does not
    space = ParameterSpace.for_robot(load_robot())
    start_u = np.full(4, 0.5)
    res = polish_minimax(_evaluate(space, 0.5), space, space.from_unit(start_u), 30)
    np.testing.assert_allclose(space.to_unit(res.values), TARGET_U, atol=1e-3)
