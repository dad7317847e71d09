"""The same swimmer in MuJoCo, for the speed comparison of ``eelbot bench`` (optional dependency).

Two MuJoCo versions of the robot of a :class:`~eelsim.robot.Robot` file:

- the fastest batched path: ``mujoco.rollout`` (MuJoCo's own thread pool), the built-in ellipsoid
  fluid model (``fluidshape="ellipsoid"``, water density, optional ``wind`` for a current), the
  joint PD as a position actuator (k_p) plus joint damping (k_d) so that the stiff damping is
  integrated implicitly (``implicitfast``); the gait enters as the actuator target
  alpha + (k_d / k_p) alpha_dot, which gives exactly u = k_p (alpha - phi) + k_d (alpha_dot - phi_dot);
- our Morison drag (docs/model.md section 2: linear + quadratic tangential and normal drag and the fluid yaw
  damping, no added mass) applied as ``xfrc_applied`` from Python between ``mj_step`` calls, with
  MuJoCo's fluid model switched off.

Geometry: N bodies in a chain, the tail carrying the planar base (slide x, slide y, hinge z), each
following link on a hinge about z at the joint; every link an ellipsoid of half-axes (l, b, a)
with the robot's mass and yaw inertia at its centre; no gravity (the robot swims in a plane).
These are speed measurements; the gait runs open loop (no heading controller), the same gait in
every run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from eelsim.fluid import FluidCoefficients
from eelsim.joints import pd_gains
from eelsim.model import SwimmerModel
from eelsim.robot import HydroCoefficients, Robot

try:  # optional: pip install eelbot[bench]
    import mujoco
    import mujoco.rollout as mj_rollout
except ImportError:  # pragma: no cover - depends on the environment
    mujoco = None
    mj_rollout = None


class MujocoMissing(RuntimeError):
    """The optional ``mujoco`` package is not installed."""


def require_mujoco() -> None:
    """Raise :class:`MujocoMissing` with the install hint when mujoco is absent."""
    if mujoco is None:
        raise MujocoMissing(
            "the MuJoCo comparison needs the optional 'mujoco' package: "
            "pip install 'eelbot[bench]' (or pip install mujoco)"
        )


def robot_mjcf(
    robot: Robot, dt_s: float = 0.01, fluid: bool = True, current_m_s: tuple[float, float] = (0, 0)
) -> str:
    """MJCF text of the robot.

    Parameters
    ----------
    robot : Robot
        Geometry, masses, gains (the hydrodynamic coefficients are not used by MuJoCo's model).
    dt_s : float
        Time step.
    fluid : bool
        Use MuJoCo's ellipsoid fluid model (water density); off for the ``xfrc_applied`` path.
    current_m_s : (float, float)
        Uniform current, as MuJoCo's ``wind``.

    Returns
    -------
    str

    Raises
    ------
    TypeError
        For a robot whose joints are not the PD model's (MuJoCo's position actuator is a PD law).
    """
    links = robot.links()
    j = robot.joints
    kp, kd = _pd_gains(robot)
    density = robot.water_density_kg_m3 if fluid else 0.0
    wind = f"{current_m_s[0]:.9g} {current_m_s[1]:.9g} 0"
    shape = ' fluidshape="ellipsoid"' if fluid else ""
    body_lines: list[str] = []
    closing: list[str] = []
    indent = "    "
    yaw_inertia = SwimmerModel.from_robot(robot).yaw_inertia_kg_m2  # the twin's (default m l^2/3)
    for i, lk in enumerate(links):
        inertia = float(yaw_inertia[i])
        # roll and pitch inertia are irrelevant in the plane but must satisfy the triangle
        # inequality: (small, J, J) does
        small = inertia * 1e-3
        if i == 0:
            body_lines.append(f'{indent}<body name="link1" pos="0 0 0">')
            body_lines.append(f'{indent}  <joint name="x" type="slide" axis="1 0 0"/>')
            body_lines.append(f'{indent}  <joint name="y" type="slide" axis="0 1 0"/>')
            body_lines.append(f'{indent}  <joint name="yaw" type="hinge" axis="0 0 1"/>')
        else:
            prev = links[i - 1].half_length_m
            body_lines.append(
                f'{indent}<body name="link{i + 1}" pos="{prev + lk.half_length_m:.9g} 0 0">'
            )
            body_lines.append(
                f'{indent}  <joint name="j{i}" type="hinge" axis="0 0 1" pos="{-lk.half_length_m:.9g} 0 0"'
                f' damping="{kd:.9g}" range="{-j.limit_rad:.6g} {j.limit_rad:.6g}"'
                ' limited="false"/>'
            )
        body_lines.append(
            f'{indent}  <inertial pos="0 0 0" mass="{lk.mass_kg:.9g}"'
            f' diaginertia="{small:.9g} {inertia:.9g} {inertia:.9g}"/>'
        )
        body_lines.append(
            f'{indent}  <geom type="ellipsoid" size="{lk.half_length_m:.9g} '
            f'{lk.half_axis_horizontal_m:.9g} {lk.half_axis_vertical_m:.9g}"'
            f' contype="0" conaffinity="0" mass="0"{shape}/>'
        )
        closing.append(f"{indent}</body>")
        indent += "  "
    actuators = "\n".join(
        f'    <position joint="j{i}" kp="{kp:.9g}"/>' for i in range(1, len(links))
    )
    return f"""<mujoco model="eelbot swimmer">
  <option timestep="{dt_s:.9g}" integrator="implicitfast" gravity="0 0 0"
          density="{density:.9g}" viscosity="0" wind="{wind}"/>
  <worldbody>
{chr(10).join(body_lines)}
{chr(10).join(reversed(closing))}
  </worldbody>
  <actuator>
{actuators}
  </actuator>
</mujoco>
"""


def gait_targets(robot: Robot, n_steps: int, dt_s: float, amplitude_rad: float = 0.87,
                 omega_rad_s: float = 3.9, beta_rad: float = 1.04) -> np.ndarray:
    """Actuator targets alpha + (k_d / k_p) alpha_dot of the open-loop gait, shape (steps, N-1)."""
    n = robot.n_links
    t = np.arange(n_steps)[:, None] * dt_s
    jj = np.arange(1, n)
    amp = amplitude_rad * (n - jj) / (n + 1.0)
    phase = omega_rad_s * t + (jj - 1) * beta_rad
    alpha = np.clip(amp * np.sin(phase), -robot.joints.command_limit_rad,
                    robot.joints.command_limit_rad)
    alpha_dot = amp * omega_rad_s * np.cos(phase)
    kp, kd = _pd_gains(robot)
    return alpha + kd / kp * alpha_dot


def _pd_gains(robot: Robot) -> tuple[float, float]:
    gains = pd_gains(robot.joints)
    if gains is None:
        raise TypeError(f"MuJoCo's joints here are the PD model's; this robot's joint model is "
                        f"{robot.joint_model.name!r}")
    return gains


@dataclass(frozen=True)
class MujocoTiming:
    """A MuJoCo speed measurement.

    Attributes
    ----------
    runs, steps : int
        Batch size and steps per run.
    wall_s : float
        Wall time.
    threads : int
        Threads used.
    walls_s : tuple of float
        Every repetition's wall time (``wall_s`` is the best), when repeated.
    """

    runs: int
    steps: int
    wall_s: float
    threads: int
    walls_s: tuple[float, ...] = ()

    @property
    def steps_per_s(self) -> float:
        """Physics steps per wall second, over all runs."""
        return self.runs * self.steps / self.wall_s


class Rollouts:
    """``runs`` copies of the robot in ``mujoco.rollout``, ready to be timed again and again.

    The model, the data, the initial states, the gait and the output buffer are made once;
    :meth:`time_once` times one rollout of all runs. MuJoCo's thread pool exists only inside
    :meth:`time_once`, so that no thread of it runs while another engine is timed.

    Parameters
    ----------
    robot : Robot
    runs, steps : int
    threads : int
        Threads of MuJoCo's pool.
    dt_s : float
    """

    def __init__(self, robot: Robot, runs: int, steps: int, threads: int,
                 dt_s: float = 0.01) -> None:
        require_mujoco()
        self.runs, self.steps, self.threads = runs, steps, threads
        self._model = mujoco.MjModel.from_xml_string(robot_mjcf(robot, dt_s, fluid=True))
        self._datas = [mujoco.MjData(self._model) for _ in range(threads)]
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state0 = np.zeros(mujoco.mj_stateSize(self._model, spec))
        mujoco.mj_getState(self._model, self._datas[0], state0, spec)
        self._initial = np.tile(state0, (runs, 1))
        self._control = gait_targets(robot, steps, dt_s)[None, :, :]
        self._out = np.empty((runs, steps, state0.size))

    def time_once(self) -> float:
        """Wall seconds of one rollout of every run.

        Raises
        ------
        RuntimeError
            When the rollout diverged.
        """
        with mj_rollout.Rollout(nthread=self.threads) as pool:
            start = time.perf_counter()
            pool.rollout(self._model, self._datas, self._initial, self._control,
                         nstep=self.steps, state=self._out)
            wall = time.perf_counter() - start
        if not np.all(np.isfinite(self._out[:, -1])):
            raise RuntimeError("the MuJoCo rollout diverged")
        return wall


def rollout_speed(robot: Robot, runs: int, steps: int, threads: int, dt_s: float = 0.01,
                  repeats: int = 2) -> MujocoTiming:
    """Time ``mujoco.rollout`` on ``runs`` copies of the robot for ``steps`` steps (best of repeats).

    Parameters
    ----------
    robot : Robot
    runs, steps : int
    threads : int
        Threads of MuJoCo's pool.
    dt_s : float
    repeats : int

    Returns
    -------
    MujocoTiming
    """
    rollouts = Rollouts(robot, runs, steps, threads, dt_s)
    walls = [rollouts.time_once() for _ in range(repeats)]
    return MujocoTiming(runs, steps, min(walls), threads, tuple(walls))


def morison_xfrc_speed(robot: Robot, coefficients: FluidCoefficients, runs: int, steps: int,
                       dt_s: float = 0.01) -> MujocoTiming:
    """Time MuJoCo with our Morison drag applied through ``xfrc_applied`` (one thread, Python loop).

    Parameters
    ----------
    robot : Robot
    coefficients : FluidCoefficients
        The paper's Morison coefficients (C_f, C_d, C_a, C_m): the drag and yaw damping
        (added mass is not modelled). Another fluid law is refused.
    runs, steps : int
        Runs are simulated one after the other.
    dt_s : float

    Returns
    -------
    MujocoTiming
    """
    require_mujoco()
    from eelsim.model import SwimmerModel

    if not isinstance(coefficients, HydroCoefficients):
        raise TypeError(f"MuJoCo's drag here is the Morison law's, not {type(coefficients).__name__}'s")
    model = mujoco.MjModel.from_xml_string(robot_mjcf(robot, dt_s, fluid=False))
    data = mujoco.MjData(model)
    swimmer = SwimmerModel.from_robot(robot, coefficients)
    f = swimmer.fluid
    bodies = np.arange(1, robot.n_links + 1)
    targets = gait_targets(robot, steps, dt_s)
    start = time.perf_counter()
    for _ in range(runs):
        mujoco.mj_resetData(model, data)
        for k in range(steps):
            data.ctrl[:] = targets[k]
            _apply_morison(data, bodies, f)
            mujoco.mj_step(model, data)
    wall = time.perf_counter() - start
    if not np.all(np.isfinite(data.qpos)):
        raise RuntimeError("the MuJoCo run with Morison drag diverged")
    return MujocoTiming(runs, steps, wall, 1)


def _apply_morison(data, bodies: np.ndarray, f) -> None:
    """xfrc_applied = Morison drag at each link centre and the fluid yaw damping torque."""
    xmat = data.xmat[bodies]
    tx, ty = xmat[:, 0], xmat[:, 3]  # body x axis (along the link) in world coordinates
    cvel = data.cvel[bodies]  # (angular, linear) about the subtree centre of mass of the root
    omega_z = cvel[:, 2]
    offset = data.xipos[bodies] - data.subtree_com[1]
    vx = cvel[:, 3] - omega_z * offset[:, 1]
    vy = cvel[:, 4] + omega_z * offset[:, 0]
    vt = tx * vx + ty * vy
    vn = -ty * vx + tx * vy
    ft = -f.c_t * (vt + np.abs(vt) * vt)
    fn = -f.c_n * (vn + np.abs(vn) * vn)
    data.xfrc_applied[bodies, 0] = ft * tx - fn * ty
    data.xfrc_applied[bodies, 1] = ft * ty + fn * tx
    data.xfrc_applied[bodies, 5] = -f.lambda_2 * omega_z - f.lambda_3 * np.abs(omega_z) * omega_z
