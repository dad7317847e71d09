import json

import numpy as np
import pytest

from eelhost.data.experiments import (
    DataError,
    Experiment,
    import_tracker_csv,
    load_dataset,
    manifest_text,
    read_experiment,
    read_frames_csv,
    write_experiment,
    write_manifest,
)
from eelsim.robot import HydroCoefficients
from eelsim.scenario import load_scenario


def small_experiment(name="straight_A0.61_w2.7"):
    t = np.arange(0, 3, 1 / 30)
    pos = np.column_stack([0.05 * t, 0.01 * np.sin(t)])
    return Experiment(
        name=name,
        t_s=t,
        position_m=pos,
        heading_rad=np.zeros_like(t),
        scenario=load_scenario(name),
        motion="straight",
        camera={"fps": 30.0},
        timing={"control_period_s": 0.3},
    )


def test_experiment_round_trips_through_its_files_even_with_dots_in_the_name(tmp_path):
    exp = small_experiment()
    write_experiment(exp, tmp_path)
    back = read_experiment(tmp_path / exp.name)
    assert back.name == exp.name and back.scenario == exp.scenario
    assert np.allclose(back.t_s, exp.t_s) and np.allclose(
        back.position_m, exp.position_m, atol=1e-9
    )
    assert back.camera == {"fps": 30.0}


@pytest.mark.parametrize(
    ("text", "where", "what"),
    [
        ("t_s,x_m,y_m\n0,0,0\n0.1,abc,0\n", ":3:2", "x_m is not a number"),
        ("t_s,x_m,y_m\n0,0,0\n0.1,0\n", ":3", "expected 3 fields, found 2"),
        ("t_s,x_m,y_m\n0,0,0\n0.1,0,nan\n", ":3:3", "not finite"),
        ("t_s,x_m,y_m\n0,0,0\n0.2,0,0\n0.1,0,0\n", ":4:1", "time does not increase"),
        ("t_s,x_m,speed\n0,0,0\n", ":1:3", "unknown column 'speed'"),
        ("t_s,x_m\n0,0\n1,1\n", ":1", "missing required column 'y_m'"),
        ("", ":1", "empty file"),
    ],
)
def test_malformed_tracker_csv_is_refused_with_file_line_and_column(tmp_path, text, where, what):
    p = tmp_path / "track.csv"
    p.write_text(text)
    with pytest.raises(DataError) as info:
        read_frames_csv(p)
    assert f"{p}{where}" in str(info.value) and what in str(info.value)


def test_import_of_a_bad_csv_writes_nothing(tmp_path):
    src = tmp_path / "track.csv"
    src.write_text("t,x,y\n0,0,0\n0.1,0.01,0\n0.2,oops,0\n")
    out = tmp_path / "dataset"
    with pytest.raises(DataError, match=":4:2"):
        import_tracker_csv(src, load_scenario("straight"), "straight", out)
    assert not out.exists() or not any(out.iterdir())


def test_import_accepts_short_column_names_and_records_the_task(tmp_path):
    src = tmp_path / "run7.csv"
    src.write_text("t,x,y,heading\n0,0,0,0\n0.5,0.02,0,0.01\n1.0,0.05,0.001,0.02\n")
    exp = import_tracker_csv(src, load_scenario("turning"), "turning", tmp_path / "ds")
    back = read_experiment(tmp_path / "ds" / "run7")
    assert back.motion == "turning" and back.scenario.k_theta == 0.37
    assert np.allclose(back.heading_rad, [0, 0.01, 0.02]) and exp.source["imported_from"] == str(
        src
    )


def test_dataset_loads_its_manifest_robot_and_experiments(tmp_path):
    for name in ("straight_A0.61_w2.7", "straight_A0.87_w3.9"):
        write_experiment(small_experiment(name), tmp_path)
    truth = {"straight": HydroCoefficients(C_f=0.008, C_d=0.776, C_a=0.618, C_m=0.007)}
    write_manifest(
        tmp_path,
        manifest_text(
            "paper_robot.toml",
            {"straight": {"train": ["straight_A0.61_w2.7"], "test": ["straight_A0.87_w3.9"]}},
            [],
            truth,
        ),
    )
    ds = load_dataset(tmp_path)
    assert [e.name for e in ds.train["straight"]] == ["straight_A0.61_w2.7"]
    assert ds.truth["straight"].C_d == 0.776 and ds.robot.n_links == 6


def test_dataset_naming_a_missing_experiment_is_refused_with_the_manifest_key(tmp_path):
    write_manifest(
        tmp_path,
        manifest_text("paper_robot.toml", {"straight": {"train": ["nope"], "test": []}}, []),
    )
    with pytest.raises(
        DataError, match=r"manifest.toml: motions.straight.train: experiment 'nope'"
    ):
        load_dataset(tmp_path)


def test_experiment_metadata_with_a_bad_scenario_is_refused_naming_the_key(tmp_path):
    exp = small_experiment()
    write_experiment(exp, tmp_path)
    meta_path = tmp_path / f"{exp.name}.json"
    meta = json.loads(meta_path.read_text())
    meta["scenario"]["omega_rad_s"] = -1
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(DataError, match=r"scenario.omega_rad_s"):
        read_experiment(tmp_path / exp.name)
