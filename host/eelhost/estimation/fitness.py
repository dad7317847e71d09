"""The paper's trajectory error and fitness, and the validation errors (docs/model.md sections 6, 7).

For a training experiment j, the simulation runs the same task over the experiment's whole span (it
does not stop at the acceptance circle). Both trajectories are sampled at the same n = 7 time stamps,
evenly spaced over the recorded span and snapped to the physics grid; both velocities come from the
sampled positions the same way (``numpy.gradient``: central differences, one-sided at the ends):

    error_j = sum_k |x_exp,k - x_sim,k| + w sum_k |v_exp,k - v_sim,k|,   w = 5

The fitness of a candidate is max_j error_j (minimax). A failed simulation scores the paper's
penalty instead (H1 times the path left for too slow, H2 ill-conditioned, H3 self-collision), which
ranks every failure below every success.
"""

from __future__ import annotations

import numpy as np

N_SAMPLES_FIT = 7
N_SAMPLES_VALIDATE = 35
VELOCITY_WEIGHT = 5.0


def sample_times(t_first_s: float, t_last_s: float, n: int, dt_s: float = 0.01) -> np.ndarray:
    """``n`` evenly spaced times over [t_first, t_last], snapped to the physics grid, >= 0.

    Parameters
    ----------
    t_first_s, t_last_s : float
        The recorded span.
    n : int
        Number of samples.
    dt_s : float
        Physics step.

    Returns
    -------
    ndarray, shape (n,)
    """
    t = np.linspace(t_first_s, t_last_s, n)
    snapped = np.round(t / dt_s) * dt_s
    lo = max(0.0, float(np.ceil(t_first_s / dt_s - 1e-9)) * dt_s)
    hi = float(np.floor(t_last_s / dt_s + 1e-9)) * dt_s
    return np.clip(snapped, lo, hi)


def sampled_velocity(times_s: np.ndarray, positions_m: np.ndarray) -> np.ndarray:
    """Velocities from sampled positions (central differences, one-sided at the ends)."""
    return np.gradient(
        np.asarray(positions_m, dtype=float), np.asarray(times_s, dtype=float), axis=-2
    )


def trajectory_error(
    times_s: np.ndarray,
    exp_positions_m: np.ndarray,
    sim_positions_m: np.ndarray,
    weight: float = VELOCITY_WEIGHT,
) -> np.ndarray:
    """The paper's error: summed position error plus ``weight`` times summed velocity error.

    Parameters
    ----------
    times_s : ndarray, shape (n,)
        Sample times.
    exp_positions_m : ndarray, shape (n, 2)
        The experiment's centre of mass at those times.
    sim_positions_m : ndarray, shape (..., n, 2)
        The simulation's, for one or many candidates.
    weight : float
        w.

    Returns
    -------
    ndarray, shape (...)
        error in m + w * (m/s) (the paper's mixed unit).
    """
    sim = np.asarray(sim_positions_m, dtype=float)
    exp = np.asarray(exp_positions_m, dtype=float)
    pos = np.linalg.norm(sim - exp, axis=-1).sum(axis=-1)
    vel = np.linalg.norm(sampled_velocity(times_s, sim) - sampled_velocity(times_s, exp), axis=-1)
    return pos + weight * vel.sum(axis=-1)


def validation_errors(
    times_s: np.ndarray,
    exp_positions_m: np.ndarray,
    sim_positions_m: np.ndarray,
    body_length_m: float,
) -> dict[str, float]:
    """E_x and E_v of the paper (mean of norms) and true RMS, in BL and BL/s.

    Parameters
    ----------
    times_s : ndarray, shape (n,)
        Sample times (n = 35 in the paper).
    exp_positions_m, sim_positions_m : ndarray, shape (n, 2)
    body_length_m : float

    Returns
    -------
    dict
        ``Ex_mean_BL``, ``Ev_mean_BL_s`` (the paper's formula, which it calls RMS),
        ``Ex_rms_BL``, ``Ev_rms_BL_s`` (root mean square of the norms).
    """
    dx = np.linalg.norm(np.asarray(sim_positions_m) - exp_positions_m, axis=-1) / body_length_m
    dv = (
        np.linalg.norm(
            sampled_velocity(times_s, sim_positions_m) - sampled_velocity(times_s, exp_positions_m),
            axis=-1,
        )
        / body_length_m
    )
    return {
        "Ex_mean_BL": float(dx.mean()),
        "Ev_mean_BL_s": float(dv.mean()),
        "Ex_rms_BL": float(np.sqrt(np.mean(dx**2))),
        "Ev_rms_BL_s": float(np.sqrt(np.mean(dv**2))),
    }
