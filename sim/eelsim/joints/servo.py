"""A hobby position servo as the joint law: prescribed-shape dynamics (docs/model.md section 4).

A stiff position servo does not feel the water below its stall torque: its joint angle follows
its own law, driven only by the reference. Per joint, with e = alpha - phi (alpha clamped):

    v_cmd    = clip(K deadband(e, db), -w_max, +w_max)      position loop and rate limit
    phi_ddot = (v_cmd - phi_dot) / tau_m                      motor (velocity) lag

deadband(e, db) = e - db above db, e + db below -db, 0 in between (a dead zone, continuous).
K (1/s) is the position-loop gain (1/K: the servo's first-order lag for slow signals), w_max the
no-load speed (``servo_max_speed_rad_s``, 8 rad/s), tau_m the motor's time constant. The body's
position and heading then follow from the water's forces through the 3 x 3 reduced system
(``eelsim.dynamics.prescribed_shape_derivative``), which also gives the torque each servo must
give; torques outside the servo's torque-speed line (stall 1.26 N m) are counted as saturation,
a warning on the run, not a failure (the model assumes the servo keeps up; a run with many
saturated steps asks more than the servo has).

Explicit RK4: the linearised law tau_m s^2 + s + K = 0 sets the step; :meth:`ServoJoints.check_step`
refuses a step outside RK4's stability region, naming the largest stable one. With K -> inf and
tau_m -> 0 the joints track exactly (phi = alpha): the limit the stiff PD loop converges to.

Defaults, a standard-size analog hobby servo (the paper's 1.26 N m, 8 rad/s class), unloaded:
K = 30 1/s (a 33 ms lag; full speed for errors above w_max / K = 0.27 rad) and tau_m = 8 ms
(K tau_m = 0.24, about critically damped: no overshoot of a small step; -3 dB bandwidth about
6 Hz, inside the 4-8 Hz typical of such servos); no deadband (a typical 4 us dead band of a
1000 us = 90 degree stroke is about +-0.003 rad: ``deadband_rad = 0.003``). Roots -50 and
-75 1/s: RK4 at 0.01 s is stable (dt |lambda| = 0.75, the limit 2.79).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from eelsim.joints import register_joint_model  # defined before this module is imported
from eelsim.joints.base import (
    FloatArray,
    JointModel,
    JointParameters,
    KernelCode,
    NonNegativeFloat,
    PositiveFloat,
    largest_stable_step,
)

if TYPE_CHECKING:
    from eelsim.model import SwimmerModel

CAMERA_PERIOD_S = 1.0 / 30.0
"""The overhead camera's frame period (30 fps, docs/model.md section 4), for the steps offered."""


class ServoJointParameters(JointParameters):
    """``[joints]`` of the servo model (``model = "servo"``); defaults: a typical hobby servo.

    Attributes
    ----------
    position_gain_1_s : float
        K, the position-loop gain (1/K: the lag for slow signals), 1/s.
    motor_time_constant_s : float
        tau_m, the motor's velocity lag, s.
    deadband_rad : float
        Half-width of the dead zone of the position error, rad (0: none).
    """

    model_name: ClassVar[str] = "servo"

    position_gain_1_s: PositiveFloat = 30.0
    motor_time_constant_s: PositiveFloat = 0.008
    deadband_rad: NonNegativeFloat = 0.0


class ServoJoints(JointModel):
    """The hobby-servo law on kinematic joints (see the module docstring)."""

    name: ClassVar[str] = "servo"
    parameters: ClassVar[type[JointParameters]] = ServoJointParameters
    kinematic: ClassVar[bool] = True
    # lag_s = 1/K: digital servos about 10 ms, slow analog ones up to 0.1 s; tau_m: small motors
    # behind their gear trains, 2-50 ms. Its lower bound is 5 ms, not 2: below about 4 ms some
    # lags of the box put the law outside RK4's stability at the twin's 10 ms step (the fits ran
    # into it: a fold refitted there failed as ill-conditioned), and at 5 ms every lag of the box
    # is stable up to a 13 ms step; a faster motor is instantaneous at that step (the lag rules).
    fit_parameters: ClassVar[tuple[tuple[str, float, float], ...]] = (
        ("lag_s", 0.005, 0.2), ("motor_time_constant_s", 0.005, 0.05))
    kernel_rows: ClassVar[tuple[str, ...]] = (
        "servo_gain", "servo_rate", "servo_inv_tau", "servo_deadband")

    def fit_values(self, spec: JointParameters) -> FloatArray:
        """(lag_s = 1/K, tau_m)."""
        p = _servo(spec)
        return np.array([1.0 / p.position_gain_1_s, p.motor_time_constant_s])

    def with_fit_values(self, spec: JointParameters, values: ArrayLike) -> JointParameters:
        """``spec`` with (lag_s, tau_m) replaced (validated: positive)."""
        lag, tau = (float(v) for v in np.asarray(values, dtype=float).reshape(2))
        if not lag > 0.0:
            raise ValueError(f"lag_s must be positive, got {lag}")
        return ServoJointParameters.model_validate(
            {**_servo(spec).model_dump(), "position_gain_1_s": 1.0 / lag,
             "motor_time_constant_s": tau})

    def drive(
        self,
        spec: JointParameters,
        alpha_rad: FloatArray,
        alpha_dot_rad_s: FloatArray,
        phi_rad: FloatArray,
        phi_dot_rad_s: FloatArray,
    ) -> FloatArray:
        """Joint accelerations phi_ddot, rad/s^2 (the reference's rate is not used)."""
        p = _servo(spec)
        e = np.asarray(alpha_rad, dtype=float) - np.asarray(phi_rad, dtype=float)
        db = p.deadband_rad
        e = np.maximum(e - db, 0.0) + np.minimum(e + db, 0.0)
        rate = p.servo_max_speed_rad_s
        v = np.minimum(np.maximum(p.position_gain_1_s * e, -rate), rate)
        return (v - np.asarray(phi_dot_rad_s, dtype=float)) * (1.0 / p.motor_time_constant_s)

    def kernel_values(self, spec: JointParameters, servo_limits: bool) -> dict[str, float]:
        """K, w_max, 1/tau_m and the dead zone (the torque-speed clip is not this model's)."""
        p = _servo(spec)
        return {"servo_gain": p.position_gain_1_s, "servo_rate": p.servo_max_speed_rad_s,
                "servo_inv_tau": 1.0 / p.motor_time_constant_s,
                "servo_deadband": p.deadband_rad}

    def emit_joint(self, code: KernelCode, plain: bool) -> None:
        """The same law, in the same order of operations."""
        line, w = code.line, code.w
        line("jm_e = al - ph")
        line(f"jm_db = {w('servo_deadband')}")
        line("jm_e = max(jm_e - jm_db, 0.0) + min(jm_e + jm_db, 0.0)")
        line(f"jm_rate = {w('servo_rate')}")
        line(f"jm_v = min(max({w('servo_gain')} * jm_e, -jm_rate), jm_rate)")
        line(f"jout = (jm_v - phd) * {w('servo_inv_tau')}")

    def largest_stable_step_s(self, spec: JointParameters, model: SwimmerModel) -> float:
        """From the roots of tau_m s^2 + s + K (the law inside its dead zone's and rate's limits)."""
        p = _servo(spec)
        return largest_stable_step(np.roots([p.motor_time_constant_s, 1.0, p.position_gain_1_s]))

    def check_step(self, spec: JointParameters, model: SwimmerModel, dt_s: float) -> None:
        """Refuse ``dt_s`` outside RK4's stability on the servo law, naming the largest stable step.

        Raises
        ------
        ValueError
            Naming the parameters, the largest stable step and a step to use: the largest
            1/(30 m) s below it, which divides the camera's frame period (and so any control
            period of whole frames, e.g. 0.3 s = 9 frames).
        """
        p = _servo(spec)
        stable = self.largest_stable_step_s(spec, model)
        if dt_s <= stable:
            return
        frames = int(np.ceil(CAMERA_PERIOD_S / stable))
        raise ValueError(
            f"[joints] position_gain_1_s = {p.position_gain_1_s:g} 1/s, motor_time_constant_s = "
            f"{p.motor_time_constant_s:g} s: explicit RK4 at dt = {dt_s:g} s is unstable on the "
            f"servo law; the largest stable step is {stable:.3g} s. Use dt = 1/{30 * frames} s "
            f"({CAMERA_PERIOD_S / frames:.6g} s: {frames} steps per camera frame, a whole number "
            f"per control period of whole frames), or a slower servo (larger "
            f"motor_time_constant_s)"
        )


def _servo(spec: JointParameters) -> ServoJointParameters:
    if not isinstance(spec, ServoJointParameters):
        raise TypeError(f"the servo joint model needs its own parameters, got "
                        f"{type(spec).__name__}")
    return spec


SERVO = register_joint_model(ServoJoints(), "a hobby position servo: position-loop gain, rate limit, motor lag, dead zone")
"""The hobby-servo model, registered as ``"servo"``."""
