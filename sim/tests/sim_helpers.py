"""Helpers shared by the twin's tests (not named conftest: pytest has one conftest per folder)."""

import numpy as np


def random_state(rng, n, angle=0.6, rate=2.0, speed=0.2):
    return np.concatenate(
        [
            rng.normal(0, angle, n),
            rng.normal(0, 1, 2),
            rng.normal(0, rate, n),
            rng.normal(0, speed, 2),
        ]
    )
