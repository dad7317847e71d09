"""One ambient current for the tank, from the straight and turning experiments together."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from eelhost.data.experiments import load_dataset, manifest_text, write_experiment, write_manifest
from eelhost.data.virtual_tank import TABLE3, TankSettings, record_experiment
from eelhost.estimation.methods import FitSettings
from eelhost.estimation.pipeline import fit_motion
from eelhost.estimation.tank_current import cross_track_axes, share_tank_current, swim_axis
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

STRAIGHT = ["straight_A0.87_w3.9", "straight_A0.61_w2.7"]
TURNING = ["turning_A0.87_w3.9", "turning_A0.61_w2.7"]
STRAY_M_S, STRAY_DEG = 0.005, 120.0


def _short(name, turn_to=(0.52, 0.3)):
    far = (0.6, 0.0) if name.startswith("straight") else turn_to  # 0.6 m, the task's heading
    return load_scenario(name).model_copy(update={"waypoints_m": [far]})


@pytest.fixture(scope="module")
def tank(tmp_path_factory):
    """Two short straight and two short turning gaits in an undeclared steady current."""
    return _tank(tmp_path_factory.mktemp("tank_current"), (0.52, 0.3))


@pytest.fixture(scope="module")
def two_axes_tank(tmp_path_factory):
    """The same, the turning gaits turning to a waypoint at 60 deg and swimming on."""
    return _tank(tmp_path_factory.mktemp("tank_current_60"), (0.3, 0.52))


def _tank(folder, turn_to):
    robot = load_robot()
    settings = TankSettings(timestamp_jitter_s=0.0, control_jitter_s=0.0,
                            stray_current_m_s=STRAY_M_S, stray_current_direction_deg=STRAY_DEG)
    for i, name in enumerate(STRAIGHT + TURNING):
        motion = name.split("_")[0]
        write_experiment(record_experiment(robot, _short(name, turn_to), motion, TABLE3[motion],
                                           settings, seed=i), folder)
    write_manifest(folder, manifest_text(
        "paper_robot.toml", {"straight": {"train": STRAIGHT, "test": []},
                             "turning": {"train": TURNING, "test": []}}, [],
        {m: TABLE3[m] for m in ("straight", "turning")}))
    ds = load_dataset(folder)
    fits, evs = {}, {}
    for motion in ("straight", "turning"):
        fits[motion], evs[motion] = fit_motion(ds, motion, FitSettings(budget=300,
                                                                       polish_iterations=6))
    return ds, fits, evs


@pytest.mark.slow
@pytest.mark.parametrize("tank_of", ["tank", "two_axes_tank"])
def test_both_motions_hold_one_tank_current_recovered_within_a_mm_s_and_15_degrees(
    tank_of, request
):
    _, fits, evs = request.getfixturevalue(tank_of)
    # the motions swim towards about 5 and 25 deg (at the edge of AXIS_SPREAD_DEG apart), or 5
    # and 55 deg: each motion's along-axis current its own, the tank's what both see across
    axes = cross_track_axes([swim_axis(evs[m]) for m in ("straight", "turning")])
    if tank_of == "two_axes_tank":
        assert all(a is not None for a in axes)
    held, held_evs, current = share_tank_current(fits, evs)
    assert current is not None and current.experiments == 4
    speed = float(np.hypot(*current.current_m_s))
    direction = float(np.degrees(np.arctan2(current.current_m_s[1], current.current_m_s[0])))
    assert abs(speed - STRAY_M_S) < 0.001
    assert abs((direction - STRAY_DEG + 180) % 360 - 180) < 15
    # every fit's current lies in the tank current's interval, which has a width
    assert np.all(current.half_width_m_s > 0) and np.all(current.half_width_m_s < 0.03)
    for motion in ("straight", "turning"):
        got = np.array(held[motion].model.current_m_s)
        assert np.all(np.abs(got - current.current_m_s) <= current.half_width_m_s + 1e-12)
        assert held_evs[motion].space is held[motion].space
        # the held fit is scored on the same experiments as the motion's own
        assert held[motion].fitness == pytest.approx(
            float(held_evs[motion].fitness(held[motion].values[None])[0]))
        assert held[motion].simulations > fits[motion].simulations
        # never worse than the motion's own fit with its current brought into the held bounds
        space = held_evs[motion].space
        own = space.from_unit(np.clip(space.to_unit(np.asarray(fits[motion].values)[None]),
                                      0.0, 1.0))
        assert held[motion].fitness <= float(held_evs[motion].fitness(own)[0]) + 1e-12


def test_one_motion_alone_keeps_its_own_current(tank):
    _, fits, evs = tank
    only = {"straight": fits["straight"]}
    out, out_evs, current = share_tank_current(only, {"straight": evs["straight"]})
    assert current is None and out["straight"] is fits["straight"]
    # a fit that failed (scored a penalty) cannot tell the water either
    failed = {**fits, "turning": replace(fits["turning"], fitness=6.2e5)}
    out, _, current = share_tank_current(failed, evs)
    assert current is None and out["straight"] is fits["straight"]


@pytest.mark.slow
def test_the_report_writes_the_tank_current_and_validation_swims_each_fit_in_it(tank, tmp_path):
    import json

    from eelhost.estimation.coefficients_file import read_coefficients
    from eelhost.estimation.report import run_report

    ds = tank[0]
    report = run_report(ds, tmp_path, settings=FitSettings(budget=150, polish_iterations=3),
                        bootstrap_replicates=0, compare_models=False)
    data = json.loads((tmp_path / "coefficients.json").read_text())
    held = np.array([data["tank_current"]["current_x_m_s"], data["tank_current"]["current_y_m_s"]])
    half = np.array(data["tank_current"]["half_width_m_s"])
    assert data["tank_current"]["experiments"] == 4
    models = read_coefficients(str(tmp_path / "coefficients.json"), ds.robot)
    for motion in ("straight", "turning"):
        got = np.array(models[motion].current_m_s)  # what validate swims in
        assert np.all(np.abs(got - held) <= half + 1e-12)
    assert "One current for the tank" in report.read_text()


class _LinearResiduals:
    """An evaluator whose residuals are linear in one parameter and the current, plus ``noise``.

    ``experiments`` recordings of ``samples`` residuals each (the layout of
    ``Evaluator.residuals``: each experiment's residuals one block).
    """

    def __init__(self, rng, experiments, samples, noise):
        from types import SimpleNamespace

        camera = SimpleNamespace(pixel_m=0.0)
        self.prepared = [SimpleNamespace(experiment=SimpleNamespace(
            recording_camera=lambda: camera))] * experiments
        self.columns = rng.normal(size=(experiments * samples, 3))  # (own, v_x, v_y)
        self.noise = noise(rng, self.columns, experiments, samples)
        self.space = SimpleNamespace(bounds=np.array([[-1.0, 1.0], [-0.03, 0.03], [-0.03, 0.03]]))

    def residuals(self, x):
        return np.atleast_2d(x) @ self.columns.T + self.noise


def _interval(noise_of):
    from eelhost.estimation.tank_current import _spread

    rng = np.random.default_rng(5)
    e, n = 8, 12
    ev = _LinearResiduals(rng, e, n, noise_of)
    half = _spread(ev, np.zeros(3)).half_width()
    # the independent-residual interval, written apart: the full Jacobian in the unit cube and
    # the inverse of J^T J, the residual variance RSS / (M - K)
    ranges = ev.space.bounds[:, 1] - ev.space.bounds[:, 0]
    jac = ev.columns * ranges
    r = ev.noise
    sigma2 = r @ r / (len(r) - 3)
    independent = 1.959964 * np.sqrt(sigma2 * np.diag(np.linalg.inv(jac.T @ jac)))[1:] * ranges[1:]
    return half, independent


def test_the_current_interval_is_the_independent_one_unless_each_experiments_residuals_move_together():
    # residuals independent from sample to sample: the linearised interval
    half, independent = _interval(lambda rng, columns, e, n: 1e-3 * rng.normal(size=e * n))
    np.testing.assert_allclose(half, np.maximum(independent, half), rtol=1e-6)
    assert np.all(half < 2 * independent)
    # each experiment's residuals one shift along the current's own columns (a clock offset, a
    # misfit): the same size of residuals, but only as many pieces of evidence as experiments,
    # and the cluster-robust interval is wider than the independent one
    def shifted(rng, columns, e, n):
        return np.repeat(1e-3 * rng.choice([-1.0, 1.0], size=e), n) * columns[:, 1]

    half, independent = _interval(shifted)
    assert np.all(half >= independent) and half.max() > 1.5 * independent.max()


def test_a_motion_swimming_one_axis_is_told_apart_from_motions_that_do_not():
    along_x = [np.array([1.0, 0.02]), np.array([1.0, -0.01])]
    axis = swim_axis(SimpleNamespace(prepared=[_swum(d) for d in along_x]))
    assert axis is not None and abs(axis[1]) < 0.02 and axis[0] > 0.99
    # circles and paths: displacements to every side
    assert swim_axis(SimpleNamespace(prepared=[_swum(d) for d in ([1, 0], [0, 1])])) is None
    x, at_30 = np.array([1.0, 0.0]), np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)])
    # across their axes the two motions see the whole plane: each keeps its axis
    assert [a is b for a, b in zip(cross_track_axes([x, at_30]), [x, at_30], strict=True)] == [
        True, True]
    assert cross_track_axes([x, None])[0] is x
    # every motion along one axis: nothing would see the current along it, so none is decoupled
    assert cross_track_axes([x, np.array([0.995, 0.0998])]) == [None, None]


def _swum(displacement):
    """A prepared experiment stand-in whose recording moves by ``displacement``."""
    end = np.asarray(displacement, dtype=float)
    return SimpleNamespace(experiment=SimpleNamespace(position_m=np.array([[0.0, 0.0], end])))


class _LinearMotion:
    """A motion whose residuals are linear in its own parameter and the current.

    ``residuals(x) = x @ columns.T - columns @ truth + misfit + noise`` for x = (own, v_x, v_y):
    ``truth`` the water's (own, current), ``misfit`` what the model cannot hold, laid along the
    current's columns (``misfit_m_s``: the current that would absorb it), the worst case for a
    nuisance.
    """

    def __init__(self, rng, truth, misfit_m_s, experiments=5, samples=12, noise_m=2e-4):
        camera = SimpleNamespace(pixel_m=0.0)
        self.prepared = [SimpleNamespace(experiment=SimpleNamespace(
            recording_camera=lambda: camera))] * experiments
        self.columns = rng.normal(size=(experiments * samples, 3))
        self.offset = (-self.columns @ np.asarray(truth)
                       - self.columns[:, 1:] @ np.asarray(misfit_m_s)
                       + noise_m * rng.normal(size=experiments * samples))
        self.space = SimpleNamespace(bounds=np.array([[-1.0, 1.0], [-0.03, 0.03], [-0.03, 0.03]]))

    def residuals(self, x):
        return np.atleast_2d(x) @ self.columns.T + self.offset

    def own_fit(self):
        return np.linalg.lstsq(self.columns, -self.offset, rcond=None)[0]


def _tank_interval(current_m_s, misfits_m_s, seed=3, axes=(None, None)):
    """The tank's current, half-width and widening from two linear motions (their LS fits)."""
    from eelhost.estimation.tank_current import estimate

    rng = np.random.default_rng(seed)
    evs = [_LinearMotion(rng, [0.3, *current_m_s], m) for m in misfits_m_s]
    _, current, covariance, scale, _ = estimate(evs, [np.zeros(3), np.zeros(3)], list(axes))
    return current, 1.959964 * np.sqrt(np.diag(covariance)), scale, covariance


def test_a_still_water_tank_whose_model_misfits_reports_an_interval_that_includes_still_water():
    from eelhost.estimation.tank_current import TankCurrent

    # each motion's misfit looks like its own current (4 and 2 mm/s, different ways): the
    # joint fit's current is their mean, 1.1 mm/s, and the residuals alone give it +-0.1 mm/s
    misfits = [(-0.004, 0.001), (0.002, -0.002)]
    current, half, scale, covariance = _tank_interval((0.0, 0.0), misfits)
    assert np.hypot(*current) > 0.001
    assert scale > 5  # the motions disagree far beyond their intervals
    assert np.all(np.abs(current) <= half)
    tank = TankCurrent(current, half, {}, 10, 1.0, scale, covariance)
    assert not tank.resolved and tank.to_json()["resolved"] is False
    assert tank.text().startswith("no current resolved")


def test_a_real_current_with_a_model_that_holds_the_water_is_resolved_and_not_widened_much():
    from eelhost.estimation.tank_current import TankCurrent

    truth = np.array([-0.0025, 0.00433])
    current, half, scale, covariance = _tank_interval(truth, [(0.0, 0.0), (0.0, 0.0)])
    assert scale < 2
    assert np.all(np.abs(current - truth) <= half) and np.all(half < 0.001)
    tank = TankCurrent(current, half, {}, 10, 1.0, scale, covariance)
    assert tank.resolved and not tank.text().startswith("no current")


def test_the_current_interval_widens_with_the_motions_misfit():
    misfit = np.array([(-0.0004, 0.0001), (0.0002, -0.0002)])
    halves = [_tank_interval((-0.0025, 0.00433), k * misfit)[1] for k in (0.0, 1.0, 2.0)]
    assert np.all(halves[1] > 2 * halves[0]) and np.all(halves[2] > 1.5 * halves[1])
    # the real current stays inside (the misfits' mean moves the fit, the interval holds it)
    current, half, _, _ = _tank_interval((-0.0025, 0.00433), misfit)
    assert np.all(np.abs(current - (-0.0025, 0.00433)) <= half)


def test_the_birge_ratio_is_the_motions_chi_square_over_its_degrees_of_freedom():
    from eelhost.estimation.tank_current import misfit_scale

    tank = np.array([0.001, 0.002])
    cov = np.diag([1e-6, 4e-6])
    # written apart: two motions, 2 * 2 - 2 = 2 degrees of freedom
    a, b = np.array([0.004, 0.002]), np.array([0.001, -0.004])
    q = ((a - tank) ** 2 / np.diag(cov)).sum() + ((b - tank) ** 2 / np.diag(cov)).sum()
    assert misfit_scale(tank, [(a, cov), (b, cov)]) == pytest.approx(np.sqrt(q / 2))
    assert misfit_scale(tank, [(tank, cov), (tank + 1e-4, cov)]) == 1.0
    assert misfit_scale(tank, [(a, cov)]) == 1.0  # one motion: nothing to compare


def test_the_tank_current_is_taken_to_the_residuals_least_squares_estimate():
    from eelhost.estimation.tank_current import _least_squares

    rng = np.random.default_rng(8)
    ev = _LinearMotion(rng, [0.3, -0.0025, 0.00433], (0.001, 0.0))
    # from a point another criterion chose (the minimax fit's), off the least-squares one
    got = _least_squares(ev, np.array([0.1, 0.004, 0.0]))
    np.testing.assert_allclose(got, ev.own_fit(), atol=1e-7)
    # a least-squares point beyond a bound: the best point within the bounds, the parameter at
    # its bound and the current fitted with it (written apart: the bounded linear problem with
    # that parameter fixed at the bound)
    far = _LinearMotion(rng, [1.5, -0.0025, 0.00433], (0.0, 0.0))
    got = _least_squares(far, np.array([0.9, 0.0, 0.0]))
    rest = np.linalg.lstsq(far.columns[:, 1:], -far.offset - far.columns[:, 0], rcond=None)[0]
    np.testing.assert_allclose(got, [1.0, *rest], atol=1e-7)
    # the least-squares point itself stays
    np.testing.assert_allclose(_least_squares(ev, ev.own_fit()),
                               ev.own_fit(), atol=1e-9)


def test_the_views_are_combined_by_their_information_and_a_one_axis_view_only_across_its_axis():
    from eelhost.estimation.tank_current import RESOLVED_CHI2, CurrentView, combine_views

    a, b = np.array([0.001, 0.004]), np.array([-0.002, 0.005])
    sa, sb = np.array([[4e-6, 1e-6], [1e-6, 1e-6]]), np.diag([1e-6, 9e-6])
    current, cov = combine_views([CurrentView(a, sa), CurrentView(b, sb)])
    # written apart: the inverse-covariance-weighted mean
    wa, wb = np.linalg.inv(sa), np.linalg.inv(sb)
    np.testing.assert_allclose(cov, np.linalg.inv(wa + wb), rtol=1e-9)
    np.testing.assert_allclose(current, np.linalg.solve(wa + wb, wa @ a + wb @ b), rtol=1e-9)
    # two one-axis motions (along x and along 30 deg): each tells only its cross-track
    # component, n_m . c = n_m . c_m, two equations for two unknowns; whatever each says along
    # its axis moves nothing
    x_axis, at_30 = np.array([1.0, 0.0]), np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)])
    truth = np.array([-0.0025, 0.00433])
    along_x, along_30 = truth + 0.006 * x_axis, truth - 0.004 * at_30  # far off along the axes
    current, cov = combine_views([CurrentView(along_x, sa, x_axis),
                                  CurrentView(along_30, sb, at_30)])
    np.testing.assert_allclose(current, truth, atol=1e-12)
    across = np.array([[0.0, 1.0], [-at_30[1], at_30[0]]])
    variances = np.array([n @ s @ n for n, s in zip(across, (sa, sb), strict=True)])
    written_apart = np.linalg.inv(across.T @ np.diag(1 / variances) @ across)
    np.testing.assert_allclose(cov, written_apart, rtol=1e-9)
    # a direction no view tells: the whole search bound wide, the views' mean there
    from eelhost.estimation.space import CURRENT_BOUND_M_S

    current, cov = combine_views([CurrentView(along_x, sa, x_axis)])
    assert current[1] == pytest.approx(along_x[1])
    assert current[0] == pytest.approx(along_x[0])
    assert np.sqrt(RESOLVED_CHI2 * cov[0, 0]) == pytest.approx(CURRENT_BOUND_M_S)
    # a view that tells nothing (its current unidentifiable) is left out
    current, _ = combine_views([CurrentView(a, sa), CurrentView(b, None)])
    np.testing.assert_allclose(current, a, atol=1e-15)


def test_a_one_axis_motions_along_track_error_does_not_pull_the_tanks_current():
    # two linear motions in a 5 mm/s current towards 120 deg; the first swims along x and its
    # residuals hold an along-track error that looks like 4 mm/s of current along x (a clock
    # offset, a speed its coefficients cannot make), the worst case: along its own columns
    truth = (-0.0025, 0.00433)
    misfits = [(0.004, 0.0), (0.0, 0.0)]
    pulled, _, _, _ = _tank_interval(truth, misfits)
    current, half, _, _ = _tank_interval(truth, misfits, axes=(np.array([1.0, 0.0]), None))
    assert np.hypot(*(pulled - truth)) > 0.001  # every component counted: pulled along x
    assert np.hypot(*(current - truth)) < 0.0003  # across x only: the truth
    assert np.all(np.abs(current - truth) <= half)


def test_still_water_is_told_by_the_confidence_ellipse_not_by_each_components_interval():
    from eelhost.estimation.tank_current import RESOLVED_CHI2, TankCurrent

    sd = 0.001
    cov = np.diag([sd**2, sd**2])
    half = np.full(2, 1.959964 * sd)
    # 2.1 standard deviations along x: outside v_x's 95 % interval, inside the 95 % ellipse
    # (chi-squared with 2 degrees of freedom, 5.99), as a still tank is one time in ten
    edge = TankCurrent(np.array([2.1 * sd, 0.0]), half, {}, 8, 1.0, 1.0, cov)
    assert RESOLVED_CHI2 == pytest.approx(5.991, abs=1e-3)
    assert not edge.resolved and edge.text().startswith("no current resolved")
    assert TankCurrent(np.array([2.1 * sd, 0.0]), half, {}, 8, 1.0).resolved  # intervals alone
    # 2.5 standard deviations: outside the ellipse too
    beyond = TankCurrent(np.array([2.5 * sd, 0.0]), half, {}, 8, 1.0, 1.0, cov)
    assert beyond.resolved and beyond.to_json()["covariance_m2_s2"] == cov.tolist()
    # both components at 1.9 standard deviations: each inside its interval, together beyond
    assert TankCurrent(np.array([1.9 * sd, 1.9 * sd]), half, {}, 8, 1.0, 1.0, cov).resolved


@pytest.mark.slow
def test_one_set_for_every_motion_gets_the_tanks_interval_and_verdict(tank):
    ds = tank[0]
    fit, ev = fit_motion(ds, "joint", FitSettings(budget=150, polish_iterations=4))
    held, held_evs, current = share_tank_current({"joint": fit}, {"joint": ev})
    assert current is not None and current.experiments == 4
    assert list(current.per_motion_m_s) == ["joint"] and current.misfit_scale == 1.0
    # one set for two motions whose water differs (table 3's straight and turning sets)
    # misfits, and its current with it (about 12 mm/s towards 164 deg): its interval says so
    # and holds the truth; the verdict is the ellipse's
    truth = STRAY_M_S * np.array([np.cos(np.radians(STRAY_DEG)), np.sin(np.radians(STRAY_DEG))])
    assert np.all(np.abs(current.current_m_s - truth) <= current.half_width_m_s)
    c, cov = current.current_m_s, current.covariance_m2_s2
    assert current.resolved == bool(c @ np.linalg.inv(cov) @ c > 5.991)
    got = np.array(held["joint"].model.current_m_s)
    assert np.all(np.abs(got - current.current_m_s) <= current.half_width_m_s + 1e-12)
    assert held_evs["joint"].space is held["joint"].space


def test_the_combined_interval_pools_every_experiment_of_every_motion_as_clusters():
    from scipy.stats import t as student_t

    from eelhost.estimation.tank_current import CurrentView, combine_views

    rng = np.random.default_rng(4)
    x_axis = np.array([1.0, 0.0])
    views, pulls = [], []
    for axis in (x_axis, None):
        pull = 1e-3 * rng.normal(size=(4, 2))  # each of 4 experiments' pull on the view
        robust = pull.T @ pull * 4 / 3 * (student_t.ppf(0.975, 3) / 1.959964) ** 2
        views.append(CurrentView(1e-3 * rng.normal(size=2), robust, axis,
                                 independent=np.diag([1e-9, 1e-9]), influence=pull))
        pulls.append(pull)
    _, weights_only = combine_views([replace(v, independent=None) for v in views])
    current, cov = combine_views(views)
    # written apart: the gains A_m of the combination, every experiment's pull through them,
    # summed over all 8 experiments with 8 / 7 and (t(7) / z)^2
    h = [np.outer([0.0, 1.0], [0.0, 1.0]) / views[0].covariance[1, 1],
         np.linalg.inv(views[1].covariance)]
    inverse = np.linalg.inv(h[0] + h[1])
    moved = np.vstack([p @ (inverse @ w).T for p, w in zip(pulls, h, strict=True)])
    expected = moved.T @ moved * 8 / 7 * (student_t.ppf(0.975, 7) / 1.959964) ** 2
    np.testing.assert_allclose(cov, expected, rtol=1e-9)
    np.testing.assert_allclose(weights_only, inverse, rtol=1e-9)
    np.testing.assert_allclose(current, inverse @ sum(w @ v.current_m_s
                                                      for w, v in zip(h, views, strict=True)),
                               rtol=1e-9)
    # eight clusters need a smaller t than four: the pooled interval is narrower than the
    # weights' own (each motion's with t(3))
    assert np.trace(cov) < np.trace(weights_only)


class _OneAxisMotion(_LinearMotion):
    """A linear motion swimming along ``axis``, its speed trading against the current along it.

    ``across_misfit_m_s``: what its model gets wrong drifts every experiment the same way across
    its track, along the cross-track current's own columns (a turning rate the model gets
    wrong when every gait turns the same way: nothing in its positions tells it from a current).
    """

    def __init__(self, rng, truth, axis, across_misfit_m_s, experiments=4, samples=12):
        axis = np.asarray(axis, dtype=float)
        across = np.array([-axis[1], axis[0]])
        super().__init__(rng, truth, tuple(across_misfit_m_s * across), experiments, samples)
        rebuilt = self.columns[:, 1:] @ axis + 0.05 * rng.normal(size=len(self.columns))
        self.offset -= (rebuilt - self.columns[:, 0]) * truth[0]  # the same truth, new column
        self.columns[:, 0] = rebuilt


def _one_axis_tank(truth, across_misfit_m_s):
    """The tank's current from a straight motion along x and a turning one along 30 deg."""
    from eelhost.estimation.tank_current import TankCurrent, estimate

    rng = np.random.default_rng(11)
    axes = [np.array([1.0, 0.0]), np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)])]
    evs = [_OneAxisMotion(rng, [0.3, *truth], axes[0], 0.0),
           _OneAxisMotion(rng, [0.3, *truth], axes[1], across_misfit_m_s)]
    _, current, covariance, scale, seeing = estimate(evs, [ev.own_fit() for ev in evs], axes)
    half = 2.4474 * np.sqrt(np.diag(covariance))
    seen_by = tuple(m for m, sees in zip(("straight", "turning"), seeing, strict=True) if sees)
    return TankCurrent(current, half, {}, 8, 1.0, scale, covariance, seen_by)


def test_a_current_only_one_motions_view_sees_is_not_resolved():
    # still water; the turning gaits' model drifts them 1 mm/s across their track, all the same
    # way. The straight motion says still water across x, the turning one 1 mm/s across 30 deg:
    # their two lines cross at 2 mm/s along x, well outside the ellipse (what head_tail did),
    # but only one view sees any current: not resolved, and the fits may hold still water
    tank = _one_axis_tank((0.0, 0.0), 0.001)
    assert tank.outside_ellipse and np.hypot(*tank.current_m_s) > 0.0015
    assert tank.seen_by == ("turning",) and not tank.resolved
    assert tank.text().startswith("no current resolved") and "seen by turning's view alone" in (
        tank.text())
    assert tank.to_json()["resolved"] is False and tank.to_json()["seen_by"] == ["turning"]
    # a current both motions swim in is seen by both views and resolved, misfit or none
    truth = np.array([-0.0025, 0.00433])
    for misfit in (0.0, 0.001):
        there = _one_axis_tank(truth, misfit)
        assert there.seen_by == ("straight", "turning") and there.resolved
    assert np.hypot(*(_one_axis_tank(truth, 0.0).current_m_s - truth)) < 0.0003


def test_a_view_sees_a_current_where_still_water_is_outside_its_interval_in_what_it_tells():
    from eelhost.estimation.tank_current import CurrentView, sees_a_current

    x_axis = np.array([1.0, 0.0])
    cov = np.diag([4e-6, 1e-6])  # sd 2 mm/s along x, 1 mm/s across
    # one axis: only the cross-track component counts, against 1.96 of its sd
    assert not sees_a_current(CurrentView(np.array([0.009, 0.0019]), cov, x_axis))
    assert sees_a_current(CurrentView(np.array([0.0, 0.0021]), cov, x_axis))
    # whole: both components, the ellipse's 5.99
    assert sees_a_current(CurrentView(np.array([0.005, 0.0]), cov))
    assert not sees_a_current(CurrentView(np.array([0.004, 0.001]), cov))
    assert not sees_a_current(CurrentView(np.array([0.01, 0.01]), None))
