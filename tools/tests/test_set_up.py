"""The set-up's kernel sets (scripts/setup.sh, scripts/warm_kernels.py)."""

import importlib.util
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def _warm_kernels():
    spec = importlib.util.spec_from_file_location("warm_kernels",
                                                  REPO / "scripts" / "warm_kernels.py")
    assert spec is not None and spec.loader is not None
    warm = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(warm)
    return warm


def test_the_tests_list_is_keyed_as_the_loader_keys_kernels():
    from eelsim.batch import stage_backend
    from eelsim.batch.loading import DEFAULT_LANES

    keys = _warm_kernels().kernel_keys("tests")
    stage = stage_backend()
    # the robot files stand for their joint models, a joint model's name for itself
    assert (6, DEFAULT_LANES, stage, "morison", "pd") in keys
    assert (6, DEFAULT_LANES, stage, "morison", "servo") in keys
    assert (6, DEFAULT_LANES, stage, "morison", "pd_limited") in keys
    assert (3, DEFAULT_LANES, stage, "morison", "servo") in keys
    assert (6, DEFAULT_LANES, "numba", "morison", "pd") in keys
    assert {key[1] for key in keys} == {DEFAULT_LANES}


def test_a_kernel_the_tests_list_lacks_is_named_unless_no_list_could_name_it():
    from eelsim.batch import stage_backend
    from eelsim.batch.loading import DEFAULT_LANES

    warm = _warm_kernels()
    stage = stage_backend()
    listed = (6, DEFAULT_LANES, stage, "morison", "pd")
    lacking = (4, DEFAULT_LANES, stage, "morison", "pd")
    other_lanes = (6, 8, stage, "morison", "pd")
    main_only = (6, DEFAULT_LANES, stage, "resistive_lift", "servo")
    a_tests_own_law = (6, DEFAULT_LANES, stage, "a_law_no_registry_has", "pd")
    assert warm.unlisted([listed, lacking, other_lanes, main_only, a_tests_own_law]) == sorted(
        [lacking, other_lanes, main_only])
    assert warm.unlisted([main_only], "main") == []


def test_setup_takes_a_kernel_set_and_refuses_another_word():
    done = subprocess.run(["bash", "scripts/setup.sh", "everything"], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert "usage: scripts/setup.sh [main|tests|system]" in done.stderr
    # `system`: the system packages only, nothing of the Python environment or the kernels
    done = subprocess.run(["bash", "scripts/setup.sh", "system"], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert ".venv" not in done.stdout and "kernel" not in done.stdout


def test_a_kernel_modules_file_name_gives_its_loader_key():
    keys = _warm_kernels().module_keys(["n6_l16_c_morison", "n6_l16_c_resistive_lift_servo",
                                        "n8_l16_numba_linear_quadratic_pd_limited",
                                        "eelsim_c_0f67ea4968ec8d8d", "n6_l16_c_morison.tmp12"])
    assert keys == {(6, 16, "c", "morison", "pd"), (6, 16, "c", "resistive_lift", "servo"),
                    (8, 16, "numba", "linear_quadratic", "pd_limited")}


def test_every_listed_kernels_module_name_reads_back_as_its_key():
    """The warm script's file-name reader is the inverse of the loader's naming."""
    from eelsim.batch.loading import kernel_module_name

    warm = _warm_kernels()
    keys = warm.kernel_keys("tests") | warm.kernel_keys("main")
    for key in keys:
        assert warm.module_keys([kernel_module_name(*key)]) == {key}


def test_the_first_round_compiles_each_driver_once_and_the_second_the_rest(monkeypatch):
    from eelsim.batch import loading

    warm = _warm_kernels()
    monkeypatch.setattr(loading, "_C_UNAVAILABLE", [])  # the C stage, whatever this machine has
    monkeypatch.setattr(loading.c_stage, "find_compiler", lambda: "cc")
    for name in ("main", "tests"):
        variants = list(dict.fromkeys(warm.variant_lists()[name]))
        first, rest = warm._rounds(variants)
        assert sorted(first + rest, key=repr) == sorted(variants, key=repr)  # each once
        c_first = [v for v in first if v[1] != "numba"]
        # one C variant per N in the first round (its driver), none of an N whose driver waits
        assert sorted(v[0] for v in c_first) == sorted({v[0] for v in variants if v[1] != "numba"})
        assert all(v[1] != "numba" for v in rest)
        assert [v[1] == "numba" for v in first] == sorted(v[1] == "numba" for v in first)[::-1]


def test_a_library_built_ahead_is_the_one_its_variant_then_loads(tmp_path, monkeypatch):
    from eelsim.batch import loading
    from eelsim.fluid import get_fluid_law
    from eelsim.joints import get_joint_model

    monkeypatch.setenv(loading.CACHE_ENV, str(tmp_path))
    warm = _warm_kernels()
    warm._c_library((6, "c", "galilean", "servo_robot.toml"))
    built = sorted(tmp_path.glob("*.so"))
    assert len(built) == 1
    text = loading.kernel_source(6, loading.DEFAULT_LANES, "c", get_fluid_law("galilean"),
                                 get_joint_model("servo"))
    assert sorted(tmp_path.glob("*.so")) == built  # found, not compiled again
    assert str(built[0]) in text
