"""PD joints on the servo's torque-speed line, with the line fitted (docs/model.md section 4).

The paper's PD loop (:mod:`eelsim.joints.pd`) whose torque the servo cannot always give: a DC
servo gives at most its stall torque tau_s at rest, and its driving torque falls linearly to zero
at its no-load speed w_0. Per joint, with u_PD = k_p (alpha - phi) + k_d (alpha_dot - phi_dot):

    u = clip(u_PD, -tau_s min(1, 1 + phi_dot / w_0), +tau_s min(1, 1 - phi_dot / w_0))

(``eelsim.closed_loop.servo_limited``). Braking torque is limited by the stall torque alone.
This is the PD model with the loop's ``servo_limits`` option always on, as a law of its own so
that an estimator can fit the line: the stall torque ``servo_max_torque_nm`` and the no-load
speed ``servo_max_speed_rad_s`` are this model's fitted parameters; the PD gains stay the robot
file's, as for the paper's model.

Identifiability: the line only matters where the PD loop asks more than it gives. Above about
the largest torque the gaits ask (0.04 N m for the paper's soft gains and gaits) the stall torque
changes nothing, and the no-load speed matters only through phi_dot / w_0 at the joint speeds
the gaits reach (up to about 3.5 rad/s); a fit on gaits that never reach the line returns both
wherever its start put them (the report's identifiability section says so).

Bounds (a modelling statement: the servos such a robot would carry): stall torque 0.005-0.08 N m
(sub-micro servos at 0.05-0.2 kg cm up to about twice what the paper's gains ask; above that the
model is the plain PD model and the comparison prefers the simpler one), no-load speed 3-20 rad/s
(hobby servos' 0.35-0.05 s per 60 degrees).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from eelsim.joints import register_joint_model  # defined before this module is imported
from eelsim.joints.base import FloatArray, JointParameters, KernelCode
from eelsim.joints.pd import PDJointParameters, PDJoints


class PDLimitedJointParameters(PDJointParameters):
    """``[joints]`` of the PD model on the servo's line (``model = "pd_limited"``).

    The PD model's fields; ``servo_max_torque_nm`` and ``servo_max_speed_rad_s`` (shared by every
    model) are the line the torques are clipped to, always.
    """

    model_name: ClassVar[str] = "pd_limited"


class PDLimitedJoints(PDJoints):
    """The PD law clipped to the torque-speed line, the line fitted (see the module docstring)."""

    name: ClassVar[str] = "pd_limited"
    parameters: ClassVar[type[JointParameters]] = PDLimitedJointParameters
    fit_parameters: ClassVar[tuple[tuple[str, float, float], ...]] = (
        ("servo_max_torque_nm", 0.005, 0.08), ("servo_max_speed_rad_s", 3.0, 20.0))
    # ten more candidates would cost the report's comparison about half again
    # (docs/estimation.md, "Model comparison"): every law when the robot file or the user asks;
    # by default it joins after the screen with the few laws the screen ranks best
    offered_by_default: ClassVar[bool] = False
    offered_after_screen: ClassVar[bool] = True
    # the PD gains stay the robot file's; the fit varies the line (its fit_parameters)
    fitted_by_estimator: ClassVar[bool] = True

    # fit_values and with_fit_values: the PD model's, over this model's fit_parameters
    def table_from(self, spec: JointParameters) -> JointParameters | None:
        """A PD table (its gains, limits and servo) as this model's; None for another model's."""
        if isinstance(spec, PDLimitedJointParameters):
            return spec
        if not isinstance(spec, PDJointParameters):
            return None
        return PDLimitedJointParameters.model_validate(spec.model_dump())

    def drive(
        self,
        spec: JointParameters,
        alpha_rad: FloatArray,
        alpha_dot_rad_s: FloatArray,
        phi_rad: FloatArray,
        phi_dot_rad_s: FloatArray,
    ) -> FloatArray:
        """The PD torques clipped to the torque-speed line, N m."""
        from eelsim.closed_loop import servo_limited

        p = self._own(spec)
        u = super().drive(spec, alpha_rad, alpha_dot_rad_s, phi_rad, phi_dot_rad_s)
        return servo_limited(u, np.asarray(phi_dot_rad_s, dtype=float), p.servo_max_torque_nm,
                             p.servo_max_speed_rad_s)

    def kernel_values(self, spec: JointParameters, servo_limits: bool) -> dict[str, float]:
        """The PD model's rows with its clip on whatever the loop's option says."""
        return super().kernel_values(spec, servo_limits=True)

    def emit_joint(self, code: KernelCode, plain: bool) -> None:
        """The PD model's code with the clip (the line is this model's law, never left out).

        Its rows' stall torque is finite, so ``batch.plain_runs`` never calls a block of it
        plain; the clip is written either way.
        """
        super().emit_joint(code, plain=False)


PD_LIMITED = PDLimitedJoints()
"""The PD model on the fitted torque-speed line, registered as ``"pd_limited"``."""
register_joint_model(PD_LIMITED, "the PD loop clipped to the servo's torque-speed line, the line "
                     "fitted")
