"""Laying out a batch: per-run inputs as arrays, the kernel's parameter rows, random draws.

:class:`BatchSpec` holds everything the kernel needs, one row per run: the per-run constants in
the generated code's row order (geometry, fluid law rows, gait, gains, current), the initial
states, waypoints, control update schedules and heading noise (drawn here, from each run's seed,
exactly as the reference draws them), and the camera's frame table. :func:`block_order` decides
which runs share a block; :func:`plain_runs` which runs may take the sweep without current and
servo line.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelsim.batch import codegen
from eelsim.batch.loading import DEFAULT_LANES
from eelsim.closed_loop import LoopOptions, blow_up_hint
from eelsim.fluid import FluidCoefficients, FluidLaw, get_fluid_law
from eelsim.joints import JointModel, get_joint_model
from eelsim.model import SwimmerModel, geometry_matrix
from eelsim.robot import Robot
from eelsim.scenario import Scenario

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class BatchSpec:
    """Everything the kernel needs, as arrays with one row per run (R runs, N links).

    Build it with :meth:`build`; :meth:`with_coefficients` swaps the hydrodynamic coefficients
    cheaply (what estimation does generation after generation).

    Attributes
    ----------
    n_links : int
        N, shared by the batch.
    params : ndarray, shape (R, P)
        Per-run constants in the kernel's row order (geometry, fluid coefficients, gait, gains,
        current; see ``eelsim.batch.codegen.make_layout``).
    initial_state : ndarray, shape (R, 2 N + 4)
        Straight robot at rest at the scenario's start pose.
    total_steps : ndarray of int, shape (R,)
        floor(T_max / dt).
    goal_steps : ndarray of int, shape (R,)
        With ``options.stop_at_goal``, the first step at which reaching the goal ends the run
        (``Scenario.goal_steps``).
    waypoints_m : ndarray, shape (R, W, 2)
        Waypoints, padded (repeating the last one) to the longest list.
    n_waypoints : ndarray of int, shape (R,)
    acceptance_radius_m, k_theta : ndarray, shape (R,)
    delay_steps : ndarray of int, shape (R,)
    update_steps : ndarray of int, shape (R, U)
        Control update schedule of each run (from its seed), padded with -1.
    update_count : ndarray of int, shape (R,)
    heading_noise_rad : ndarray, shape (R, F) or (R, 0)
        Heading noise of each camera frame (from the seed), empty without noise.
    frame_step, frame_fraction, frame_time_s : ndarray, shape (F,)
        Camera frames: the step k whose interval (t_k, t_k + dt] holds the frame, the fraction of
        the step, and the frame's time (frame 0 is seen at t = 0 before the first step).
    options : LoopOptions
        The shared loop options.
    half_length_m, half_axis_vertical_m, half_axis_horizontal_m, yaw_inertia_kg_m2 : ndarray
        Per-run, per-link geometry and inertia, kept to recompute the fluid coefficients.
    density_kg_m3 : ndarray, shape (R,)
    coefficients : ndarray, shape (R, k)
        The fluid law's coefficients of each run (Morison: (C_f, C_d, C_a, C_m)).
    duration_s : ndarray, shape (R,)
        T_max of each run (for messages).
    joint_limit_rad : ndarray, shape (R,)
    fluid_law_name : str
        The fluid law of every run (its rows are part of ``params``).
    joint_model_name : str
        The joint model of every run (its rows are part of ``params``).
    blow_up_hints : tuple of str
        What the reason of a run that blows up adds, per distinct robot
        (:func:`eelsim.closed_loop.blow_up_hint`); ``robot_index`` gives each run's.
    robot_index : ndarray of int, shape (R,)
    guidance_state : ndarray, shape (R, 4), optional
        Each run's guidance state at its start (docs/model.md section 4): where its first leg
        starts (NaN: at the first filtered pose) and the ILOS integral vector; ``None``: NaN and
        zero for every run. A run restarted from another's state gets that run's here.
    """

    n_links: int
    params: FloatArray
    initial_state: FloatArray
    total_steps: IntArray
    goal_steps: IntArray
    waypoints_m: FloatArray
    n_waypoints: IntArray
    acceptance_radius_m: FloatArray
    k_theta: FloatArray
    delay_steps: IntArray
    update_steps: IntArray
    update_count: IntArray
    heading_noise_rad: FloatArray
    frame_step: IntArray
    frame_fraction: FloatArray
    frame_time_s: FloatArray
    options: LoopOptions
    half_length_m: FloatArray
    half_axis_vertical_m: FloatArray
    half_axis_horizontal_m: FloatArray
    yaw_inertia_kg_m2: FloatArray
    density_kg_m3: FloatArray
    coefficients: FloatArray
    duration_s: FloatArray
    joint_limit_rad: FloatArray
    fluid_law_name: str = "morison"
    joint_model_name: str = "pd"
    blow_up_hints: tuple[str, ...] = ("",)
    robot_index: IntArray | None = None
    guidance_state: FloatArray | None = None

    def guidance_start(self) -> FloatArray:
        """:attr:`guidance_state`, filled in: shape (R, 4), float."""
        if self.guidance_state is None:
            out = np.zeros((self.n_runs, 4))
            out[:, :2] = np.nan
            return out
        return np.ascontiguousarray(np.asarray(self.guidance_state, dtype=float)
                                    .reshape(self.n_runs, 4))

    @property
    def fluid_law(self) -> FluidLaw:
        """The fluid law of the batch."""
        return get_fluid_law(self.fluid_law_name)

    @property
    def joint_model(self) -> JointModel:
        """The joint model of the batch."""
        return get_joint_model(self.joint_model_name)

    def blow_up_hint(self, run: int) -> str:
        """What run ``run``'s reason adds when it blew up (see ``blow_up_hints``)."""
        index = 0 if self.robot_index is None else int(self.robot_index[run])
        return self.blow_up_hints[index]

    @property
    def n_runs(self) -> int:
        """Number of runs R."""
        return int(self.initial_state.shape[0])

    @classmethod
    def build(
        cls,
        robots: Robot | Sequence[Robot],
        scenarios: Scenario | Sequence[Scenario],
        coefficients: ArrayLike | FluidCoefficients | Sequence[FluidCoefficients] | None = None,
        options: LoopOptions | None = None,
        seeds: int | ArrayLike = 0,
        models: SwimmerModel | Sequence[SwimmerModel] | None = None,
    ) -> BatchSpec:
        """Lay out a batch of runs.

        Parameters
        ----------
        robots : Robot or sequence of Robot
            One robot for all runs, or one per run (same number of links).
        scenarios : Scenario or sequence of Scenario
            One scenario for all runs, or one per run.
        coefficients : array_like (R, k) or (k,), FluidCoefficients or a sequence of them, optional
            The fluid law's coefficients per run (Morison: (C_f, C_d, C_a, C_m)); default: each
            robot's own. Every run must use the same fluid law.
        options : LoopOptions, optional
            Shared by all runs.
        seeds : int or array_like of int
            Seed of each run's jitter and heading noise (as ``simulate_closed_loop``'s ``seed``).
        models : SwimmerModel or sequence of SwimmerModel, optional
            The robots' models where the caller has built them (one per robot, in the order of
            ``robots``), so that a batch does not rebuild them: the joint model's step check
            and the blow-up hint read a robot's model with its own coefficients, so one with
            other coefficients or other links is not used and the robot's own is built.

        Returns
        -------
        BatchSpec

        Raises
        ------
        ValueError
            When per-run sequences have different lengths, robots differ in N, fluid law or
            joint model, the coefficients do not fit the law, or the joint model refuses the
            physics step (as ``simulate_closed_loop``).
        """
        opts = options or LoopOptions()
        robot_list = [robots] if isinstance(robots, Robot) else list(robots)
        model_list = ([] if models is None else [models] if isinstance(models, SwimmerModel)
                      else list(models))
        if model_list and len(model_list) != len(robot_list):
            raise ValueError(f"{len(model_list)} models for {len(robot_list)} robots")
        given = {id(rb): m for rb, m in zip(robot_list, model_list, strict=False)}
        scen_list = [scenarios] if isinstance(scenarios, Scenario) else list(scenarios)
        if not robot_list or not scen_list:
            raise ValueError("a batch needs at least one robot and one scenario")
        law = robot_list[0].fluid_law
        if any(rb.fluid_law is not law for rb in robot_list):
            raise ValueError("all robots of a batch must use the same fluid law")
        joints = robot_list[0].joint_model
        if any(rb.joint_model is not joints for rb in robot_list):
            raise ValueError("all robots of a batch must use the same joint model")
        coeff_arr = None if coefficients is None else _coefficient_array(coefficients, law)
        seed_arr = np.atleast_1d(np.asarray(seeds, dtype=np.int64))
        sizes = {len(robot_list), len(scen_list), seed_arr.shape[0]}
        if coeff_arr is not None:
            sizes.add(coeff_arr.shape[0])
        sizes.discard(1)
        if len(sizes) > 1:
            raise ValueError(f"per-run inputs have different lengths: {sorted(sizes)}")
        n_runs = sizes.pop() if sizes else 1
        n = robot_list[0].n_links
        if any(rb.n_links != n for rb in robot_list):
            raise ValueError("all robots of a batch must have the same number of links")

        # per-run inputs are often a few objects repeated (estimation: every candidate on the
        # same experiments): their arrays are computed once per distinct object
        robot_list, robot_idx = _distinct(robot_list, n_runs)
        scen_list, scen_idx = _distinct(scen_list, n_runs)
        seed_of = np.broadcast_to(seed_arr, (n_runs,))
        timing, camera = opts.timing, opts.camera
        dt = timing.dt_s

        # -- robots: per-link geometry, gains (computed once per distinct robot), and what the
        # joint model says of the step (the servo model refuses an unstable one)
        rob = [_robot_arrays(rb, opts) for rb in robot_list]
        own_models = [_own_model(rb, given.get(id(rb)), arrays)
                      for rb, arrays in zip(robot_list, rob, strict=True)]
        for rb, own in zip(robot_list, own_models, strict=True):
            joints.check_step(rb.joints, own, dt)
        hints = tuple(blow_up_hint(rb, own, dt)
                      for rb, own in zip(robot_list, own_models, strict=True))
        per_robot = {k: np.stack([r[k] for r in rob]) for k in rob[0]}
        rsel = {k: v[robot_idx] for k, v in per_robot.items()}
        if coeff_arr is None:
            coeff_arr = np.stack([rb.hydrodynamics.as_array() for rb in robot_list])[robot_idx]
        coeff_arr = np.broadcast_to(coeff_arr, (n_runs, coeff_arr.shape[1])).astype(float)

        # -- scenarios
        sc = [_scenario_arrays(s, n, dt) for s in scen_list]
        n_wp_max = max(len(s.waypoints_m) for s in scen_list)
        wp = np.stack([_pad_waypoints(s.waypoints_m, n_wp_max) for s in scen_list])[scen_idx]
        ssel = {k: np.stack([d[k] for d in sc])[scen_idx] for k in sc[0]}
        total = ssel["total_steps"].astype(np.int64)

        # -- camera frames, shared by all runs (the same dt and fps), for the longest run
        frame_step, frame_fraction, frame_time = _frame_table(int(total.max()), dt, camera.fps)

        # -- random draws, per distinct (seed, total) as the reference makes them
        updates, counts, noise = _random_draws(seed_of, total, timing, camera, frame_time.size)

        layout = codegen.make_layout(n, DEFAULT_LANES, law, joints)
        params = np.zeros((n_runs, layout.work_rows - layout.work["geometry"]))
        spec = cls(
            n_links=n,
            params=params,
            initial_state=ssel["initial_state"],
            total_steps=total,
            goal_steps=ssel["goal_steps"].astype(np.int64),
            waypoints_m=wp,
            n_waypoints=ssel["n_waypoints"].astype(np.int64),
            acceptance_radius_m=ssel["radius"],
            k_theta=ssel["k_theta"],
            delay_steps=np.full(n_runs, timing.delay_steps, dtype=np.int64),
            update_steps=updates,
            update_count=counts,
            heading_noise_rad=noise,
            frame_step=frame_step,
            frame_fraction=frame_fraction,
            frame_time_s=frame_time,
            options=opts,
            half_length_m=rsel["half"],
            half_axis_vertical_m=rsel["a"],
            half_axis_horizontal_m=rsel["b"],
            yaw_inertia_kg_m2=rsel["inertia"],
            density_kg_m3=rsel["rho"],
            coefficients=coeff_arr,
            duration_s=ssel["duration"],
            joint_limit_rad=rsel["limit"],
            fluid_law_name=law.name,
            joint_model_name=joints.name,
            blow_up_hints=hints,
            robot_index=robot_idx,
        )
        _fill_params(params, layout, rsel, ssel, n, dt)
        _fill_fluid(params, layout, spec, coeff_arr)
        return spec

    def with_coefficients(self, coefficients: ArrayLike) -> BatchSpec:
        """The same batch with other hydrodynamic coefficients (one row or one per run).

        Parameters
        ----------
        coefficients : array_like, shape (R, k) or (k,)
            The fluid law's coefficients (Morison: (C_f, C_d, C_a, C_m)).

        Returns
        -------
        BatchSpec
        """
        law = self.fluid_law
        given = _coefficient_array(coefficients, law)
        c = np.broadcast_to(given, (self.n_runs, given.shape[1])).copy()
        params = self.params.copy()
        out = replace(self, params=params, coefficients=c)
        _fill_fluid(params, _layout(self), out, c)
        return out


def _coefficient_array(coefficients: Any, law: FluidLaw) -> FloatArray:
    """The coefficients as an array of shape (R, k) (R = 1 for one set), checked against the law."""
    k = len(law.coefficient_names)
    if isinstance(coefficients, FluidCoefficients):
        coefficients = [coefficients]
    if isinstance(coefficients, Sequence) and coefficients and isinstance(
        coefficients[0], FluidCoefficients
    ):
        wrong = {type(c).law_name for c in coefficients} - {law.name}
        if wrong:
            raise ValueError(f"coefficients of fluid law {sorted(wrong)[0]!r} given for a batch "
                             f"of the {law.name!r} law")
        return np.stack([c.as_array() for c in coefficients])
    arr = np.asarray(coefficients, dtype=float)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != k:
        raise ValueError(
            f"coefficients must have shape (R, {k}) or ({k},) "
            f"({', '.join(law.coefficient_names)}), got {arr.shape}"
        )
    return arr


def _own_model(robot: Robot, model: SwimmerModel | None,
               arrays: dict[str, FloatArray]) -> SwimmerModel:
    """``robot``'s model with its own coefficients: ``model`` when it is one, else built.

    ``model`` is checked against the robot's coefficients and its link arrays (``arrays``, from
    :func:`_robot_arrays`), so a model of another robot is never used for it.
    """
    if (model is not None and model.n_links == robot.n_links
            and model.coefficients == robot.hydrodynamics
            and all(np.array_equal(mine, arrays[key]) for mine, key in (
                (model.half_length_m, "half"), (model.mass_kg, "mass"),
                (model.yaw_inertia_kg_m2, "inertia"),
                (model.half_axis_vertical_m, "a"), (model.half_axis_horizontal_m, "b")))
            and model.water_density_kg_m3 == float(arrays["rho"])):
        return model
    return SwimmerModel.from_robot(robot)


def _distinct(items: list, n_runs: int) -> tuple[list, IntArray]:
    """The distinct objects of ``items`` (by identity) and each run's index into them.

    A single item is shared by all ``n_runs`` runs.
    """
    if len(items) == 1:
        return items, np.zeros(n_runs, dtype=np.int64)
    slot: dict[int, int] = {}  # id -> position among the distinct objects
    distinct: list[Any] = []
    index = np.empty(len(items), dtype=np.int64)
    for i, item in enumerate(items):
        if id(item) not in slot:
            slot[id(item)] = len(distinct)
            distinct.append(item)
        index[i] = slot[id(item)]
    return distinct, index


def _layout(spec: BatchSpec) -> codegen.Layout:
    """The kernel's row layout for the batch (its N, fluid law and joint model)."""
    return codegen.make_layout(spec.n_links, DEFAULT_LANES, spec.fluid_law, spec.joint_model)


def _robot_arrays(robot: Robot, opts: LoopOptions) -> dict[str, FloatArray]:
    links = robot.link_arrays()
    j = robot.joints
    own = robot.joint_model.kernel_values(j, opts.servo_limits)
    return {
        "half": links.half_length_m,
        "mass": links.mass_kg,
        "inertia": links.yaw_inertia_kg_m2,
        "a": links.half_axis_vertical_m,
        "b": links.half_axis_horizontal_m,
        "rho": np.array(robot.water_density_kg_m3),
        "geometry": geometry_matrix(links.half_length_m, links.mass_kg),
        "limit": np.array(j.limit_rad),
        "clamp": np.array(j.command_limit_rad),
        # the torque-speed line that saturation is counted against (stall * (1 / no-load), the
        # expression of closed_loop.outside_torque_speed_line)
        "torque_limit": np.array(j.servo_max_torque_nm),
        "torque_slope": np.array(j.servo_max_torque_nm * (1.0 / j.servo_max_speed_rad_s)),
        **{f"joint_{name}": np.array(value) for name, value in own.items()},
    }


def _scenario_arrays(s: Scenario, n: int, dt: float) -> dict[str, FloatArray]:
    heading = np.radians(s.start_heading_deg)
    x0 = np.concatenate(
        [np.full(n, float(heading)), np.asarray(s.start_position_m, float), np.zeros(n + 2)]
    )
    j = np.arange(1, n, dtype=float)
    return {
        "initial_state": x0,
        "total_steps": np.array(s.total_steps(dt)),
        "goal_steps": np.array(s.goal_steps(dt)),
        "n_waypoints": np.array(len(s.waypoints_m)),
        "radius": np.array(s.acceptance_radius_m),
        "k_theta": np.array(s.k_theta),
        "duration": np.array(s.duration_s),
        # control.joint_amplitudes and gait_reference's phase offsets (j - 1) beta
        "amp": s.amplitude_rad * (n - j) / (n + 1.0),
        "cos_beta": np.cos(np.arange(n - 1) * s.beta_rad),
        "sin_beta": np.sin(np.arange(n - 1) * s.beta_rad),
        "omega": np.array(s.omega_rad_s),
        "vcx": np.array(s.current_m_s[0]),
        "vcy": np.array(s.current_m_s[1]),
    }


def _pad_waypoints(waypoints: list[tuple[float, float]], size: int) -> FloatArray:
    wp = np.asarray(waypoints, dtype=float)
    return np.concatenate([wp, np.repeat(wp[-1:], size - len(wp), axis=0)])


def _frame_table(max_total: int, dt: float, fps: float) -> tuple[IntArray, FloatArray, FloatArray]:
    """Camera frames as closed_loop assigns them to physics steps.

    Frame f is seen in the first step k with f / fps <= k dt + dt + 1e-12, at the fraction
    (f / fps - k dt) / dt of the step (the same float expressions as the reference).
    """
    count = int(np.floor(max_total * dt * fps + 1e-9)) + 1
    times = np.arange(count) / fps
    t_step = np.arange(max_total) * dt
    step = np.searchsorted(t_step + dt + 1e-12, times, side="left").astype(np.int64)
    step[0] = -1  # frame 0 is seen at t = 0, before the loop
    keep = step < max_total
    step, times = step[keep], times[keep]
    frac = np.zeros_like(times)
    frac[1:] = (times[1:] - t_step[step[1:]]) / dt
    return step, frac, times


def _random_draws(seeds, total, timing, camera, n_frames):
    """Update schedules and heading noise per run, drawn like simulate_closed_loop.

    Drawn once per distinct (seed, length): a generation of the GA has hundreds of runs but a
    handful of lengths, and without jitter or heading noise the seed does not matter.
    """
    random = timing.jitter_steps > 0 or camera.heading_noise_rad > 0
    keys = np.stack([seeds if random else np.zeros_like(seeds), total], axis=1)
    distinct, inverse = np.unique(keys, axis=0, return_inverse=True)
    schedules, noises = [], []
    for seed, tot in distinct.tolist():
        rng = np.random.default_rng(seed)
        schedules.append(timing.update_steps(tot, rng))
        if camera.heading_noise_rad:
            noises.append(rng.normal(0.0, camera.heading_noise_rad, size=n_frames))
    width = max(s.size for s in schedules)
    updates = np.full((len(schedules), width), -1, dtype=np.int64)
    counts = np.zeros(len(schedules), dtype=np.int64)
    for i, s in enumerate(schedules):
        updates[i, : s.size] = s
        counts[i] = s.size
    noise = np.stack(noises) if noises else np.zeros((len(schedules), 0))
    inverse = inverse.reshape(-1)
    return updates[inverse], counts[inverse], noise[inverse]


def _rows(params: FloatArray, layout: codegen.Layout, name: str, size: int) -> FloatArray:
    start = layout.work[name] - layout.work["geometry"]
    return params[:, start : start + size]


def plain_runs(spec: BatchSpec) -> NDArray[np.bool_]:
    """Which runs have no servo line and no current.

    A block whose runs all have neither takes the kernel's backward sweep without those terms
    (``eelsim.batch.codegen``): same numbers, about 12 % less work in that loop.

    Parameters
    ----------
    spec : BatchSpec

    Returns
    -------
    ndarray of bool, shape (R,)
    """
    layout = _layout(spec)
    params = spec.params
    plain = ((_rows(params, layout, "vcx", 1)[:, 0] == 0.0)
             & (_rows(params, layout, "vcy", 1)[:, 0] == 0.0))
    if "stall" in layout.joints.kernel_rows:  # the PD model's torque-speed clip
        plain &= (np.isinf(_rows(params, layout, "stall", 1)[:, 0])
                  & (_rows(params, layout, "stall_slope", 1)[:, 0] == 0.0))
    return plain


def _fill_params(params, layout, rsel, ssel, n, dt) -> None:
    g = rsel["geometry"]  # (R, N, N), G[j, i]
    mass = rsel["mass"]
    _rows(params, layout, "geometry", n * n)[:] = g.reshape(len(g), n * n)
    _rows(params, layout, "mass", n)[:] = mass
    _rows(params, layout, "mass_weight", n)[:] = mass / mass.sum(axis=1, keepdims=True)
    gmg = np.einsum("rj,rji,rjk->rik", mass, g, g)
    _rows(params, layout, "gmg", n * n)[:] = gmg.reshape(len(g), n * n)
    _rows(params, layout, "sm", n)[:] = np.einsum("rj,rji->ri", mass, g)
    _rows(params, layout, "mass_sum", 1)[:, 0] = mass.sum(axis=1)
    _rows(params, layout, "half_length", n)[:] = rsel["half"]
    _rows(params, layout, "four_h2", n)[:] = (2.0 * rsel["half"]) ** 2
    reach = codegen.screen_reach(rsel["half"])
    _rows(params, layout, "reach", reach.shape[1])[:] = reach
    for name in ("limit", "clamp", "torque_limit", "torque_slope"):
        _rows(params, layout, name, 1)[:, 0] = rsel[name]
    for name in layout.joints.kernel_rows:  # the joint model's own (JointModel.kernel_values)
        _rows(params, layout, name, 1)[:, 0] = rsel[f"joint_{name}"]
    for name in ("amp", "cos_beta", "sin_beta"):
        _rows(params, layout, name, n - 1)[:] = ssel[name]
    for name in ("omega", "vcx", "vcy"):
        _rows(params, layout, name, 1)[:, 0] = ssel[name]
    _rows(params, layout, "amp_omega", n - 1)[:] = ssel["amp"] * ssel["omega"][:, None]
    # the gait phase advanced by half a step (angle addition in stages 2 and 4)
    omega = ssel["omega"]
    _rows(params, layout, "cos_whalf", 1)[:, 0] = np.cos(omega * 0.5 * dt)
    _rows(params, layout, "sin_whalf", 1)[:, 0] = np.sin(omega * 0.5 * dt)


def _fill_fluid(params: FloatArray, layout: codegen.Layout, spec: BatchSpec,
                coeffs: FloatArray) -> None:
    """The fluid law's per-link coefficients of every run (one computation with the model's)."""
    n = spec.n_links
    l_ = spec.half_length_m
    fluid = layout.law.link_coefficients(
        l_, spec.half_axis_vertical_m, spec.half_axis_horizontal_m, coeffs[:, None, :],
        spec.density_kg_m3[:, None])
    _rows(params, layout, "mu", n)[:] = fluid.mu_n
    for name, values in fluid.kernel_values().items():
        _rows(params, layout, name, n)[:] = values
    # the diagonal term J_i + lambda_1,i of dynamics.mass_matrix
    inertia = spec.yaw_inertia_kg_m2 + fluid.lambda_1
    _rows(params, layout, "inertia", n)[:] = inertia
    # the articulated-body recursion's per-link constants (eelsim.batch.codegen)
    mu = _rows(params, layout, "mu", n)
    hm = l_ * (_rows(params, layout, "mass", n) + mu)
    _rows(params, layout, "hm", n)[:] = hm
    _rows(params, layout, "dd0", n)[:] = inertia + l_ * hm


def block_order(spec: BatchSpec, expected_steps: ArrayLike | None = None) -> IntArray:
    """The order in which runs fill the kernel's blocks: longest expected run first.

    A lane whose run has ended idles until the last run of its block ends, so runs of about
    the same length belong together: a batch mixing experiments of different spans (every
    estimation generation) otherwise runs each block as long as its longest run. Without a
    hint a run is expected to last until T_max (runs with the same T_max then by their minimum
    duration). np.lexsort is stable: a batch of equal runs keeps its order.

    Parameters
    ----------
    spec : BatchSpec
    expected_steps : array_like, shape (R,), optional
        Each run's expected number of steps (a caller's prediction, e.g. from similar runs).

    Returns
    -------
    ndarray of int, shape (R,)
        Run indices; block b takes entries b * lanes to (b + 1) * lanes - 1.
    """
    expected = spec.total_steps
    if expected_steps is not None:
        hint = np.asarray(expected_steps, dtype=float)
        if hint.shape != expected.shape:
            raise ValueError(
                f"expected_steps has shape {hint.shape}, the batch has {expected.shape[0]} runs"
            )
        expected = np.minimum(np.nan_to_num(hint, nan=np.inf), expected)
    return np.lexsort((-spec.goal_steps, -spec.total_steps, -expected)).astype(np.int64)


