"""Estimation end to end on a tiny virtual-tank dataset (short experiments, small budgets)."""

import json

import numpy as np
import pytest

from eelhost import progress
from eelhost.cli import main
from eelhost.data.experiments import load_dataset, manifest_text, write_experiment, write_manifest
from eelhost.data.virtual_tank import TABLE3, TankSettings, record_experiment
from eelhost.estimation.coefficients_file import read_coefficients
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.methods import FitSettings
from eelhost.estimation.optimise import Checkpoint, fit_ga
from eelhost.estimation.pipeline import fit_motion
from eelsim.camera import MEDIAN_PLACEMENTS
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

TRUTH = TABLE3["straight"]


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    """Three short straight experiments (0.6 m waypoints) recorded with the table-3 truth."""
    folder = tmp_path_factory.mktemp("tiny")
    robot = load_robot()
    names = []
    for i, name in enumerate(["straight_A0.87_w3.9", "straight_A0.61_w2.7", "straight_A0.78_w3.5"]):
        s = load_scenario(name).model_copy(update={"waypoints_m": [(0.6, 0.0)]})
        exp = record_experiment(
            robot, s, "straight", TRUTH, TankSettings(timestamp_jitter_s=0.0), seed=i
        )
        write_experiment(exp, folder)
        names.append(name)
    write_manifest(
        folder,
        manifest_text(
            "paper_robot.toml",
            {"straight": {"train": names[:2], "test": names[2:]}},
            [],
            {"straight": TRUTH},
        ),
    )
    return folder


@pytest.mark.slow
def test_batch_and_reference_backends_score_candidates_identically(tiny_dataset):
    ds = load_dataset(tiny_dataset)
    cands = np.array([TRUTH.as_array(), [0.02, 1.3, 0.3, 0.05]])
    ref = Evaluator(ds.robot, ds.train["straight"], backend="reference", workers=1).errors(cands)
    fast = Evaluator(ds.robot, ds.train["straight"], backend="batch").errors(cands)
    assert np.allclose(ref, fast, rtol=0, atol=1e-9)
    assert ref[0].max() < ref[1].max()  # the truth fits better than a wrong candidate


def test_runs_that_stop_once_nothing_more_can_count_score_as_runs_to_t_max(tiny_dataset):
    # Estimation ends a run at its goal once the last compared state is reached; scored by
    # running every candidate to T_max instead, nothing changes (failures after both the arrival
    # and the last sample do not count either way), and the runs really were shorter.
    import dataclasses

    ds = load_dataset(tiny_dataset)
    cands = np.array([TRUTH.as_array(), [0.02, 1.3, 0.3, 0.05], [0.001, 0.1, 0.1, 0.9],
                      [0.05, 2.5, 2.5, 0.0]])
    ev = Evaluator(ds.robot, ds.train["straight"], backend="batch")
    short = ev.errors(cands)
    full = Evaluator(ds.robot, ds.train["straight"], backend="batch")
    full.prepared = [
        dataclasses.replace(
            p,
            scenario=p.scenario.model_copy(update={"min_duration_s": 0.0}),
            options=dataclasses.replace(p.options, stop_at_goal=False),
        )
        for p in full.prepared
    ]
    assert np.array_equal(short, full.errors(cands))
    steps_short, steps_full = ev.simulate(cands).steps, full.simulate(cands).steps
    assert np.all(steps_short <= steps_full) and steps_short.sum() < 0.9 * steps_full.sum()
    assert ev.steps == 2 * steps_short.sum()  # the evaluator counts the steps of both calls


def test_run_lengths_are_guessed_from_the_nearest_earlier_candidate():
    from eelhost.estimation.batch_backend import RunLengths

    lengths = RunLengths(experiments=2, memory=3)
    assert lengths.predict(np.ones((1, 4))) is None  # nothing learnt yet
    lengths.record(np.array([[0.01, 1.0, 1.0, 0.1], [0.02, 2.0, 2.0, 0.5]]),
                   np.array([[100, 200], [300, 400]]))
    guess = lengths.predict(np.array([[0.019, 2.1, 1.9, 0.45], [0.011, 0.9, 1.0, 0.0]]))
    assert np.array_equal(guess, [[300, 400], [100, 200]])
    lengths.record(np.array([[0.05, 0.1, 0.1, 0.0], [0.06, 0.1, 0.1, 0.0]]),
                   np.array([[1, 1], [2, 2]]))
    # only the 3 most recent are kept: the first candidate is forgotten, the second is nearest
    assert np.array_equal(lengths.predict(np.array([[0.01, 1.0, 1.0, 0.1]])), [[300, 400]])


def test_default_method_recovers_the_truth_on_a_small_dataset(tiny_dataset):
    ds = load_dataset(tiny_dataset)
    res, ev = fit_motion(
        ds, "straight", FitSettings("cmaes", seed=0, budget=600, polish_iterations=8)
    )
    # the truth: table 3 in still water (the fit's ambient current is a nuisance it also fits)
    truth_fitness = float(ev.fitness(ev.space.vector(TRUTH.as_array(), ds.robot)[None])[0])
    assert res.fitness <= truth_fitness * 1.05 + 1e-3
    got, want = res.coefficients.as_array(), TRUTH.as_array()
    assert abs(got[1] - want[1]) / want[1] < 0.15  # C_d: the best pinned-down coefficient
    assert abs(got[2] - want[2]) / want[2] < 0.3  # C_a


def test_ga_resumed_after_a_kill_equals_the_uninterrupted_run_on_real_simulations(
    tiny_dataset, tmp_path
):
    ds = load_dataset(tiny_dataset)
    ev = Evaluator(ds.robot, ds.train["straight"], backend="batch")
    whole = fit_ga(ev.fitness, ev.space, seed=3, pop_size=8, generations=4)

    class Killed(Exception):
        pass

    def kill(gen, _b, _s):
        if gen == 1:
            raise Killed

    ck = tmp_path / "ck.npz"
    with pytest.raises(Killed):
        fit_ga(
            ev.fitness,
            ev.space,
            seed=3,
            pop_size=8,
            generations=4,
            checkpoint=Checkpoint(ck, {"s": 3}),
            progress=kill,
        )
    resumed = fit_ga(
        ev.fitness,
        ev.space,
        seed=3,
        pop_size=8,
        generations=4,
        checkpoint=Checkpoint(ck, {"s": 3}),
        resume=True,
    )
    assert resumed.fitness == whole.fitness and np.array_equal(resumed.values, whole.values)


@pytest.mark.slow
def test_evaluation_spread_over_a_local_dask_cluster_gives_the_same_fitness(tiny_dataset):
    import distributed  # a dev dependency, installed by the test command

    from eelhost.estimation.cluster import dask_map

    ds = load_dataset(tiny_dataset)
    cands = np.array([TRUTH.as_array(), [0.01, 0.9, 0.7, 0.01]])
    local = Evaluator(ds.robot, ds.train["straight"], backend="reference", workers=1).fitness(cands)
    with (
        distributed.LocalCluster(
            n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        spread = Evaluator(
            ds.robot, ds.train["straight"], backend="reference", map_function=dask_map(client)
        ).fitness(cands)
    assert np.array_equal(local, spread)


def test_estimate_and_validate_commands_write_coefficients_and_table(
    tiny_dataset, tmp_path, capsys, monkeypatch
):
    out = tmp_path / "fit"
    monkeypatch.setattr(progress, "PLAIN_INTERVAL_S", 0.0)  # a line per generation
    assert (
        main(
            [
                "--progress",
                "plain",
                "estimate",
                str(tiny_dataset),
                "--motion",
                "straight",
                "--budget",
                "24",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    coeffs = json.loads((out / "coefficients.json").read_text())
    assert set(coeffs["fits"]) == {"straight"} and coeffs["fits"]["straight"]["fitness"] > 0
    printed, progress_log = capsys.readouterr()
    sims = coeffs["fits"]["straight"]["simulations"]  # one count: printed, logged and recorded
    assert f"{coeffs['fits']['straight']['evaluations']} candidates, {sims} simulations" in printed
    assert f"sims {sims}, " in progress_log.splitlines()[-1]
    assert "straight" in read_coefficients(str(out / "coefficients.json"), load_robot())
    val = tmp_path / "val"
    assert (
        main(["validate", str(out / "coefficients.json"), str(tiny_dataset), "--out", str(val)])
        == 0
    )
    table = (val / "table4.csv").read_text().splitlines()
    assert table[0].startswith("name,motion,coefficients,Ex_mean_BL") and len(table) == 2
    assert (val / "paths_straight.png").exists()


def test_validate_refuses_a_malformed_coefficients_argument(tiny_dataset, capsys):
    assert main(["validate", "0.1,0.2", str(tiny_dataset)]) == 2
    assert "expected 4 numbers (C_f,C_d,C_a,C_m)" in capsys.readouterr().err


@pytest.mark.parametrize("median", MEDIAN_PLACEMENTS)
def test_truth_scores_zero_when_the_twin_is_seen_through_the_recordings_camera(median):
    robot = load_robot()
    s = load_scenario("turning_A0.61_w2.7").model_copy(update={"waypoints_m": [(0.4, 0.2)]})
    # no clock offset, no jitter, no pixel rounding: only the camera's frames and median filter
    clean = TankSettings(timestamp_jitter_s=0.0, control_jitter_s=0.0, pixel_m=0.0, median=median)
    exp = record_experiment(robot, s, "turning", TABLE3["turning"], clean, seed=4)
    assert exp.recording_camera().median == median
    truth = TABLE3["turning"].as_array()[None]
    seen = Evaluator(robot, [exp], backend="batch").errors(truth)
    true_com = Evaluator(robot, [exp], backend="batch", observe=False).errors(truth)
    assert seen[0, 0] < 1e-12  # the estimator observes the twin exactly as the tank recorded it
    # the causal median's lag would otherwise count as model error; the centred one has none
    assert true_com[0, 0] > (0.01 if median == "causal" else 1e-4)


def test_coefficients_given_as_numbers_are_the_laws_alone_on_a_servo_robots_own_joints():
    servo = load_robot("servo_robot.toml")
    fit = read_coefficients("0.008,0.776,0.618,0.007", servo)["joint"]
    assert fit.space.names == ("C_f", "C_d", "C_a", "C_m")
    assert fit.robot(servo).joints == servo.joints
