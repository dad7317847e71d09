"""The generated stage compiled as C (eelsim.batch.c_stage) against numba's compilation of the same text.

The C text is a translation of the generated Python; these tests check the translation on its own
(every construct of the subset, with NaN, infinities and signed zeros, against Python running
the same source), whole closed-loop batches against the numba-compiled stage, and the error
paths: unknown choices, constructs outside the subset, a compiler that fails.
"""

import ctypes

import numpy as np
import pytest

from eelsim import batch
from eelsim.batch import BatchSpec, c_stage, loading, run_spec
from eelsim.camera import CameraModel
from eelsim.closed_loop import LoopOptions
from eelsim.robot import HydroCoefficients, load_robot
from eelsim.scenario import load_scenario
from eelsim.timing import LoopTiming

# every construct the generator uses, in one function of the subset
_SUBSET = '''
def _probe(work, t_s, plain):
    """docstring: skipped (plain is one of the flag arguments, an int64 in C)"""
    if plain:
        for r in range(4):
            a = work[0 + r]
            b = work[4 + r]
            work[8 + r] = min(a, b)
            work[12 + r] = max(a, b, 0.25)
            work[16 + r] = abs(a) - -b
            work[20 + r] = np.floor(a * t_s + 0.5)
            work[24 + r] = 1.0 if a <= b else (np.inf if a > 2.0 else -3.5e-300)
            work[28 + r] = (a / b) - (a - b) * 0.5  # contraction to an FMA is exact here
            work[32 + r] = 1.0 if a == b else (2.0 if a != a else 0.0)
    else:
        for i in range(36):
            work[i] = 7.0
'''


def _python_probe(work, t_s, flag):
    namespace = {"np": np}
    exec(_SUBSET, namespace)  # the subset is Python: this is the meaning the C must keep
    namespace["_probe"](work, t_s, flag)


def _c_probe(tmp_path):
    library, symbols = c_stage.build(_SUBSET, ("_probe",), tmp_path)
    fn = getattr(ctypes.CDLL(str(library)), symbols["_probe"])
    fn.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.c_double, ctypes.c_int64]
    fn.restype = None

    def call(work, t_s, flag):
        fn(work.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), t_s, int(flag))

    return call


needs_cc = pytest.mark.skipif(c_stage.find_compiler() is None,
                              reason="no C compiler (install gcc; scripts/setup.sh does as root)")


@needs_cc
def test_translated_subset_computes_what_python_computes_with_nan_inf_and_signed_zero(tmp_path):
    c_probe = _c_probe(tmp_path)
    special = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1.0, -2.5, 3.0, 1e-300, 2.0]
    pairs = [(a, b) for a in special for b in special]
    for start in range(0, len(pairs), 4):
        chunk = (pairs[start:start + 4] * 4)[:4]
        work = np.zeros(36)
        work[0:4] = [a for a, _ in chunk]
        work[4:8] = [b for _, b in chunk]
        expect = work.copy()
        with np.errstate(all="ignore"):
            _python_probe(expect, 0.75, True)
        c_probe(work, 0.75, True)
        # the same values, NaN where Python has NaN (min/max keep Python's rule) and the same
        # sign of zero (a NaN's own sign bit is not specified by either)
        same = (work == expect) | (np.isnan(work) & np.isnan(expect))
        assert same.all(), (chunk, work, expect)
        number = ~np.isnan(expect)
        assert np.array_equal(np.signbit(work[number]), np.signbit(expect[number]))
    work = np.zeros(36)
    c_probe(work, 0.0, False)
    assert (work == 7.0).all()


@needs_cc
def test_a_library_built_before_is_found_from_the_python_text_without_translating_again(
        tmp_path, monkeypatch):
    first = c_stage.build(_SUBSET, ("_probe",), tmp_path)

    def no_translation(*args, **kwargs):
        raise AssertionError("translated again although the library exists")

    with monkeypatch.context() as patch:
        patch.setattr(c_stage, "c_source", no_translation)
        assert c_stage.build(_SUBSET, ("_probe",), tmp_path) == first
        # another Python text is not the same library: it is translated (and refused here)
        with pytest.raises(AssertionError, match="translated again"):
            c_stage.build(_SUBSET.replace("2.0", "3.0"), ("_probe",), tmp_path)
    # an index whose library is gone is not trusted: the library is built again
    first[0].unlink()
    again = c_stage.build(_SUBSET, ("_probe",), tmp_path)
    assert again == first and again[0].exists()


def test_the_translator_refuses_a_construct_outside_the_subset_naming_its_line():
    source = "def _f(work):\n    for r in range(4):\n        work[r] = work[r] ** 2\n"
    with pytest.raises(c_stage.CStageError, match=r"line 3: no C for 'work\[r\] \*\* 2'"):
        c_stage.translate(source, "_f", "f")
    with pytest.raises(c_stage.CStageError, match="no function '_g'"):
        c_stage.translate(source, "_g", "g")


@needs_cc
def test_c_stage_and_numba_stage_give_the_same_runs(robot):
    # a mixed batch: current and waypoint switching (path2), a servo line, timing jitter and
    # heading noise, other coefficients; every run, sample, arrival and flag
    path2 = load_scenario("path2").model_copy(update={"duration_s": 12.0})
    turning = load_scenario("turning").model_copy(update={"duration_s": 6.0})
    options = LoopOptions(servo_limits=True, camera=CameraModel(heading_noise_rad=0.01),
                          timing=LoopTiming(extra_delay_s=0.05, jitter_s=0.05))
    coefficients = [HydroCoefficients(C_f=0.008, C_d=0.776, C_a=0.618, C_m=0.007),
                    HydroCoefficients(C_f=0.02, C_d=1.5, C_a=1.2, C_m=0.02)] * 3
    spec = BatchSpec.build(robot, [path2, turning] * 3, coefficients, options,
                           seeds=[0, 1, 2, 3, 4, 5])
    assert_the_stages_agree(spec, np.arange(0, 1201, 50))


@needs_cc
def test_c_stage_and_numba_stage_give_the_same_servo_runs():
    # the servo joint model's kernel (servo law, prescribed-shape solve, the torques the servos
    # must give): a current and waypoint switching, jitter and noise, other coefficients, and a
    # servo weak enough that some steps saturate
    robot = load_robot("servo_robot.toml")
    robot = robot.with_joints(robot.joints.model_copy(update={"servo_max_torque_nm": 0.3}))
    path2 = load_scenario("path2").model_copy(update={"duration_s": 8.0})
    turning = load_scenario("turning").model_copy(update={"duration_s": 6.0})
    options = LoopOptions(camera=CameraModel(heading_noise_rad=0.01),
                          timing=LoopTiming(extra_delay_s=0.05, jitter_s=0.05))
    coefficients = [HydroCoefficients(C_f=0.008, C_d=0.776, C_a=0.618, C_m=0.007),
                    HydroCoefficients(C_f=0.02, C_d=1.5, C_a=1.2, C_m=0.02)] * 2
    spec = BatchSpec.build(robot, [path2, turning] * 2, coefficients, options,
                           seeds=[0, 1, 2, 3])
    c, nb = assert_the_stages_agree(spec, np.arange(0, 801, 40))
    assert np.array_equal(c.saturated_steps, nb.saturated_steps)
    assert np.allclose(c.max_torque_ratio, nb.max_torque_ratio, rtol=1e-9)
    assert (c.saturated_steps > 0).all()


def assert_the_stages_agree(spec, samples):
    """Both stages run ``spec`` to the same samples, flags, arrivals; returns (c, numba)."""
    model = spec.joint_model
    assert "_C_STAGE" in vars(batch.kernel_module(spec.n_links, batch.DEFAULT_LANES, "c",
                                                  spec.fluid_law, model))
    c = run_spec(spec, sample_steps=samples, threads=1, stage="c")
    nb = run_spec(spec, sample_steps=samples, threads=1, stage="numba")
    scale = np.maximum(1.0, np.nan_to_num(np.abs(nb.states)))
    gap = np.abs(np.nan_to_num(c.states - nb.states))
    assert (gap <= 1e-9 * scale).all()
    assert np.array_equal(np.isnan(c.states), np.isnan(nb.states))
    for name in ("failure", "reason_code", "final_step", "target_index"):
        assert np.array_equal(getattr(c, name), getattr(nb, name)), name
    assert np.allclose(c.arrival_time_s, nb.arrival_time_s, atol=1e-9, equal_nan=True)
    assert np.allclose(c.distance_left_m, nb.distance_left_m, atol=1e-9)
    assert c.final_step.min() > 500  # the runs went somewhere
    return c, nb


def test_an_unknown_stage_choice_is_refused_naming_where_it_came_from(monkeypatch):
    with pytest.raises(ValueError, match=r"stage must be one of auto, c, numba; got 'fortran'"):
        batch.stage_backend("fortran")
    monkeypatch.setenv(batch.STAGE_ENV, "gcc")
    with pytest.raises(ValueError, match=r"\$EELSIM_STAGE must be one of .*got 'gcc'"):
        batch.stage_backend()


def test_a_failing_c_compiler_is_an_error_when_asked_for_and_a_fallback_on_auto(monkeypatch):
    monkeypatch.setenv("CC", "false")  # a "compiler" that fails on anything
    monkeypatch.setattr(loading, "_KERNELS", {})
    monkeypatch.setattr(loading, "_C_UNAVAILABLE", [])
    with pytest.raises(c_stage.CStageError, match="C compiler 'false' failed"):
        batch.kernel_module(6, batch.DEFAULT_LANES, "c")
    with pytest.warns(RuntimeWarning, match="C stage is unavailable, numba compiles it"):
        module = batch.kernel_module(6, batch.DEFAULT_LANES, "auto")
    assert module.__name__.endswith("_l16_numba_morison")  # the numba-compiled kernel
    assert "_C_STAGE" not in vars(module)  # no binding to a C library in it
    assert batch.stage_backend("auto") == "numba"  # said once, then numba for this process


@pytest.mark.parametrize(("features", "march", "tuned"), [
    ("+avx2,+avx512f,+fma", "znver3", True),  # GCC 12 on a Zen 4: an AVX-512 CPU it does not know
    ("+avx2,+avx512f,+fma", "sapphirerapids", False),  # a CPU it knows keeps its own tuning
    ("+avx2,-avx512f,+fma", "znver3", False),  # no AVX-512
    ("+avx2,+avx512f,+fma", None, False),  # a compiler that cannot say (clang): plain flags
])
def test_the_avx512_tuning_is_added_only_on_an_avx512_cpu_the_compiler_does_not_know(
        tmp_path, monkeypatch, features, march, tuned):
    compiler = tmp_path / "cc"
    answer = f"printf '  -march=  \\t\\t{march}\\n'" if march else "exit 1"
    compiler.write_text(f"#!/bin/sh\n{answer}\n")
    compiler.chmod(0o755)
    monkeypatch.setattr(c_stage, "_host_cpu", lambda: f"some-cpu {features}")
    c_stage.compile_flags.cache_clear()
    try:
        flags = c_stage.compile_flags(str(compiler))
    finally:
        c_stage.compile_flags.cache_clear()  # the real host's answer again for later tests
    assert (flags != c_stage.C_FLAGS) == tuned
    assert set(flags) - set(c_stage.AVX512_TUNING) == set(c_stage.C_FLAGS)
    if tuned:  # the tuning right after -march=native, which it refines
        at = flags.index("-march=native")
        assert flags[at + 1 : at + 3] == c_stage.AVX512_TUNING


def test_c_variants_with_as_many_links_share_one_driver_that_reads_no_law_of_its_own():
    morison = batch.kernel_module(6, batch.DEFAULT_LANES, "c", "morison")
    quadratic = batch.kernel_module(6, batch.DEFAULT_LANES, "c", "linear_quadratic")
    assert morison._DRIVER is quadratic._DRIVER  # one driver, compiled once
    driver = morison._DRIVER
    assert driver.__name__.endswith(loading.driver_module_name(6, batch.DEFAULT_LANES))
    # nothing of a law or joint model in it: those rows arrive with each variant's call
    for name in ("FLUID_LAW", "JOINT_MODEL", "WORK_ROWS", "W_INERTIA", "W_LIMIT"):
        assert name not in vars(driver), name
    at = morison.V_WORK_ROWS  # (the template's indices, the same in every module)
    assert morison._VARIANT[at] == morison.WORK_ROWS
    assert quadratic._VARIANT[at] == quadratic.WORK_ROWS
    assert morison.WORK_ROWS != quadratic.WORK_ROWS  # the laws' own rows differ
    functions = slice(morison.V_STAGE, None)
    assert (morison._VARIANT[functions] != quadratic._VARIANT[functions]).all()  # own libraries


def test_a_variant_whose_layout_moved_a_row_the_driver_reads_is_refused():
    module = batch.kernel_module(6, batch.DEFAULT_LANES, "c", "morison")
    namespace = dict(vars(module), W_MU=module.W_MU + 1)  # a law's row put before mu
    with pytest.raises(RuntimeError, match="the variant's W_MU = .* differs from the driver's"):
        loading.bind_driver(namespace, "unused.so", {})
