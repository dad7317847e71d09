"""The fit's zero-mean clock prior (docs/estimation.md, "The training clocks: a zero-mean prior")."""

from dataclasses import replace

import numpy as np
import pytest

from eelhost.data.virtual_tank import TABLE3, TankSettings, record_experiment
from eelhost.estimation.clock_prior import centred_offsets, shifted_recording
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.runs import ALIGN_S, clock_shifts
from eelhost.estimation.space import ParameterSpace
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

TRUTH = TABLE3["straight"]
CLEAN = TankSettings(timestamp_jitter_s=0.0, control_jitter_s=0.0, pixel_m=0.0)
# each recording's clock, s: within the declared +-0.1 s, their mean 0 (the prior's)
OFFSETS = (0.08, -0.03, -0.05)
GAITS = ("straight_A0.87_w3.9", "straight_A0.61_w3.9", "straight_A0.87_w2.7")


def grid_errors(best_s: float, shifts: np.ndarray) -> np.ndarray:
    """A V-shaped error over the grid whose least is at ``best_s`` (one candidate)."""
    return np.abs(shifts - best_s)[None, :] + 0.1


def test_the_offsets_mean_is_held_at_zero_and_their_differences_are_the_datas():
    shifts = clock_shifts(ALIGN_S)
    got = centred_offsets([grid_errors(0.05, shifts), grid_errors(-0.01, shifts)],
                          [shifts, shifts])
    assert got == pytest.approx(np.array([[0.03, -0.03]]), abs=1e-9)
    # a common lag of the model (every best offset 0.04 s later) changes nothing: the fit's
    # timing cannot buy itself a clock
    lagged = centred_offsets([grid_errors(0.09, shifts), grid_errors(0.03, shifts)],
                             [shifts, shifts])
    assert lagged == pytest.approx(got, abs=1e-9)
    # one recording alone is compared on its own clock; a failed run at 0
    assert centred_offsets([grid_errors(0.05, shifts)], [shifts]) == pytest.approx(0.0)
    failed = np.full((1, shifts.size), np.nan)
    assert centred_offsets([failed, grid_errors(0.02, shifts)], [shifts, shifts]) == \
        pytest.approx(np.array([[0.0, 0.0]]), abs=1e-9)
    # clipped to the declared bound
    wide = centred_offsets([grid_errors(0.1, shifts), grid_errors(-0.1, shifts),
                            grid_errors(-0.1, shifts)], [shifts] * 3)
    assert np.abs(wide).max() <= ALIGN_S + 1e-12


def test_an_offset_between_grid_points_is_read_between_them():
    shifts = clock_shifts(0.02)
    rec = np.arange(shifts.size, dtype=float)[:, None, None] * np.ones((1, 3, 2))
    got = shifted_recording(rec, shifts, np.array([-0.02, 0.005, 0.02, 0.5]))
    assert got[:, 0, 0] == pytest.approx([0.0, 2.5, 4.0, 4.0])


@pytest.fixture(scope="module")
def late_recordings():
    robot = load_robot()
    out = []
    for name, offset in zip(GAITS, OFFSETS, strict=True):
        task = load_scenario(name).model_copy(update={"waypoints_m": [(0.6, 0.0)]})
        exp = record_experiment(robot, task, "straight", TRUTH, CLEAN, seed=0)
        # the same frames on a camera clock ``offset`` late, declaring the paper's +-0.1 s
        out.append(replace(exp, t_s=exp.t_s + offset,
                           camera={**exp.camera, "timestamp_jitter_s": ALIGN_S}))
    return robot, out


def test_the_fit_recovers_known_clock_offsets_and_its_coefficients_are_not_pulled(
    late_recordings,
):
    robot, recs = late_recordings
    space = ParameterSpace.for_robot(robot)
    truth = space.vector(TRUTH.as_array(), robot)
    prior = Evaluator(robot, recs, clock_prior=True, space=space)
    recorded = Evaluator(robot, recs, clock_prior=False, space=space)
    sim = prior.simulate(truth[None])
    grids = [prior.aligned_errors(p, sim.positions_m[:, j]) for j, p in enumerate(prior.prepared)]
    found = centred_offsets(grids, [p.shifts_s for p in prior.prepared])[0]
    # each recording's offset, within a third of the 0.01 s grid
    assert found == pytest.approx(np.array(OFFSETS), abs=0.004)
    # at its clocks the truth fits every recording better than on the recorded clock, the
    # two that the offsets leave inside the recorded span almost exactly (the late one's last
    # sample reads past the recording's end)
    at_prior, at_recorded = prior.errors(truth[None])[0], recorded.errors(truth[None])[0]
    assert np.all(at_prior < at_recorded)
    assert at_prior[1:] == pytest.approx(0.0, abs=0.002)
    # the added mass scanned from 0.8 to 1.2 times the truth's: with the prior the truth's is
    # the best; on the recorded clock the late recording (minimax: the worst counts) pulls it
    i = space.names.index("C_a")
    scale = np.linspace(0.8, 1.2, 17)
    scan = np.repeat(truth[None], scale.size, axis=0)
    scan[:, i] *= scale
    assert scale[np.argmin(prior.fitness(scan))] == pytest.approx(1.0)
    assert scale[np.argmin(recorded.fitness(scan))] < 0.99
