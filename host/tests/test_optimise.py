import numpy as np
import pytest

from eelhost.estimation.local import polish_least_squares
from eelhost.estimation.optimise import Checkpoint, CheckpointError, fit_cmaes, fit_ga
from eelhost.estimation.space import ParameterSpace
from eelsim.fluid import get_fluid_law

TARGET = np.array([0.008, 0.776, 0.618, 0.007])
SPACE = ParameterSpace(get_fluid_law("morison"))
BOUNDS = SPACE.bounds


def bowl(c):
    """A cheap stand-in objective with its minimum at TARGET (relative squared distance)."""
    c = np.atleast_2d(c)
    return (((c - TARGET) / (BOUNDS[:, 1] - BOUNDS[:, 0])) ** 2).sum(axis=1)


class Killed(Exception):
    pass


def kill_after(generation):
    def progress(gen, _best, _sims):
        if gen == generation:
            raise Killed

    return progress


def test_bounds_hold_the_papers_table_3_and_unit_mapping_round_trips():
    for row in ([0.008, 0.776, 0.618, 0.007], [0.009, 0.978, 1.169, 0.001]):
        u = SPACE.to_unit(row)
        assert np.all((u > 0) & (u < 1))
        assert np.allclose(SPACE.from_unit(u), row)


@pytest.mark.parametrize("method", ["ga", "cmaes"])
def test_resume_after_a_kill_gives_the_same_result_as_an_uninterrupted_run(tmp_path, method):
    def run(checkpoint=None, resume=False, progress=None):
        if method == "ga":
            return fit_ga(bowl, SPACE, seed=5, pop_size=12, generations=6, checkpoint=checkpoint,
                          resume=resume, progress=progress)
        return fit_cmaes(bowl, SPACE, seed=5, max_evaluations=96, popsize=8,
                         checkpoint=checkpoint, resume=resume, progress=progress)

    straight = run()
    settings = {"method": method, "seed": 5}
    ck = Checkpoint(tmp_path / "ck.npz", settings)
    with pytest.raises(Killed):
        run(checkpoint=ck, progress=kill_after(2))
    np.random.seed(12345)  # noqa: NPY002 (a new process starts with other global random state)
    resumed = run(checkpoint=Checkpoint(tmp_path / "ck.npz", settings), resume=True)
    assert resumed.fitness == straight.fitness
    assert np.array_equal(resumed.values, straight.values)
    assert [h[:2] for h in resumed.history] == [h[:2] for h in straight.history]


@pytest.mark.parametrize("method", ["ga", "cmaes"])
def test_simulation_count_goes_on_across_a_resume_and_matches_the_candidates(tmp_path, method):
    class Counting:  # a new one per "process", as the evaluator of a resumed fit is
        def __init__(self):
            self.runs = 0

        def __call__(self, c):
            self.runs += len(np.atleast_2d(c))
            return bowl(c)

    def run(objective, checkpoint=None, resume=False, progress=None):
        common = dict(checkpoint=checkpoint, resume=resume, progress=progress,
                      simulations=lambda: objective.runs)
        if method == "ga":
            return fit_ga(objective, SPACE, seed=5, pop_size=12, generations=6, **common)
        return fit_cmaes(objective, SPACE, seed=5, max_evaluations=96, popsize=8, **common)

    straight = run(Counting())
    settings = {"method": method, "seed": 5}
    with pytest.raises(Killed):
        run(Counting(), checkpoint=Checkpoint(tmp_path / "ck.npz", settings), progress=kill_after(2))
    seen = []
    resumed = run(Counting(), Checkpoint(tmp_path / "ck.npz", settings), True,
                  lambda gen, best, sims: seen.append(sims))
    assert resumed.history == straight.history  # counts included
    assert resumed.simulations == straight.simulations == straight.evaluations  # one run each
    assert seen[-1] == resumed.simulations and resumed.to_json()["simulations"] == seen[-1]


def test_checkpoint_from_other_settings_is_refused(tmp_path):
    Checkpoint(tmp_path / "ck.npz", {"seed": 1}).save({"x": 1})
    with pytest.raises(ValueError, match="other settings"):
        Checkpoint(tmp_path / "ck.npz", {"seed": 2}).load()


def test_cmaes_and_ga_approach_the_minimum_of_a_simple_bowl():
    ga = fit_ga(bowl, SPACE, seed=1, pop_size=30, generations=25)
    es = fit_cmaes(bowl, SPACE, seed=1, max_evaluations=600, popsize=10)
    assert es.fitness < 1e-6 and ga.fitness < 1e-2
    assert es.fitness < ga.fitness  # CMA-ES is the better method on smooth problems
    assert ga.history[-1][1] <= ga.history[0][1]


def test_least_squares_polish_finds_a_linear_least_squares_minimum_and_never_worsens():
    def residuals(c):
        return (np.atleast_2d(c) - TARGET) / (BOUNDS[:, 1] - BOUNDS[:, 0])

    start = np.array([0.02, 1.2, 0.9, 0.05])
    res = polish_least_squares(residuals, bowl, SPACE, start, float(bowl(start)[0]))
    assert np.allclose(res.values, TARGET, atol=1e-5)
    worse = polish_least_squares(lambda c: np.ones((len(np.atleast_2d(c)), 3)), bowl, SPACE,
                                 start, 0.0)
    assert np.array_equal(worse.values, start)  # a polish that does not improve the minimax is not taken


class _RunsAShellCommand:
    """What a crafted pickle holds: unpickling it runs ``touch MARKER``."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        import os

        return (os.system, (f"touch {self.marker}",))


def _planted(path, kind, marker, fingerprint="x"):
    import pickle

    payload = _RunsAShellCommand(marker)
    if kind == "pickle named .npz":
        path.write_bytes(pickle.dumps({"fingerprint": "x", "payload": payload}))
    else:  # an archive whose arrays are pickled objects (np.save pickles object arrays)
        x = np.empty(1, dtype=object)
        x[0] = payload
        with open(path, "wb") as f:
            np.savez(f, format=np.array("eelbot-checkpoint/2"), fingerprint=np.array(fingerprint),
                     x=x)
    return path


@pytest.mark.parametrize("kind", ["pickle named .npz", "npz of object arrays"])
def test_a_planted_pickle_checkpoint_runs_nothing_and_is_refused_naming_the_file(tmp_path, kind):
    marker = tmp_path / "ran"
    checkpoint = Checkpoint(tmp_path / "ck.npz", {"seed": 5})
    ck = _planted(checkpoint.path, kind, marker, checkpoint.fingerprint)  # fingerprint right
    with pytest.raises(CheckpointError, match="not a readable checkpoint") as err:
        fit_cmaes(bowl, SPACE, seed=5, max_evaluations=48, popsize=8, checkpoint=checkpoint,
                  resume=True)
    assert str(ck) in str(err.value) and "pickles are never read" in str(err.value)
    assert not marker.exists()
    import pickle

    pickle.loads(pickle.dumps(_RunsAShellCommand(tmp_path / "live")))  # the payload is live
    assert (tmp_path / "live").exists()


def test_an_old_pickle_checkpoint_is_not_read_and_named(tmp_path):
    marker = tmp_path / "ran"
    old = _planted(tmp_path / "ck.pkl", "pickle named .npz", marker)
    with pytest.raises(CheckpointError, match="earlier eelbot") as err:
        fit_ga(bowl, SPACE, seed=5, pop_size=12, generations=3,
               checkpoint=Checkpoint(tmp_path / "ck.npz", {"seed": 5}), resume=True)
    assert str(old) in str(err.value) and not marker.exists()


def test_a_checkpoint_is_plain_numbers_checked_against_its_fingerprint_first(tmp_path):
    ck = Checkpoint(tmp_path / "ck.npz", {"seed": 5})
    fit_ga(bowl, SPACE, seed=5, pop_size=12, generations=3, checkpoint=ck)
    with np.load(ck.path, allow_pickle=False) as z:  # readable with pickle refused
        assert {"x", "f", "sizes", "simulations", "fingerprint"} <= set(z.files)
        assert z["x"].shape == (int(z["sizes"].sum()), SPACE.size)
    with pytest.raises(CheckpointError, match="other settings"):
        fit_ga(bowl, SPACE, seed=5, pop_size=12, generations=3,
               checkpoint=Checkpoint(ck.path, {"seed": 6}), resume=True)


def test_a_checkpoint_whose_candidates_the_optimiser_does_not_ask_again_is_refused(tmp_path):
    ck = Checkpoint(tmp_path / "ck.npz", {"seed": 5})
    fit_cmaes(bowl, SPACE, seed=5, max_evaluations=48, popsize=8, checkpoint=ck)
    with np.load(ck.path, allow_pickle=False) as z:
        arrays = {n: z[n] for n in ("x", "f", "sizes", "simulations")}
    arrays["x"][3] += 0.01  # edited by hand, or made by another version of pycma
    ck.save(arrays, force=True)
    with pytest.raises(CheckpointError, match="generation 0 of the checkpoint asked for other"):
        fit_cmaes(bowl, SPACE, seed=5, max_evaluations=48, popsize=8,
                  checkpoint=Checkpoint(ck.path, {"seed": 5}), resume=True)
