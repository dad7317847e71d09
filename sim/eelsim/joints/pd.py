"""The paper's joint model: a PD loop driving free joints (docs/model.md section 4).

u_j = k_p (alpha_j - phi_j) + k_d (alpha_dot_j - phi_dot_j), evaluated inside every RK4 stage as
the robot's fast joint loop does, optionally clipped to the servo's torque-speed line (the loop's
``servo_limits`` option). The torques drive the full N + 2 dynamics of docs/model.md section 2.

Explicit RK4 and stiff gains: a joint mode with effective inertia m_j has the rates of
m_j s^2 + k_d s + k_p = 0, about k_d / m_j for stiff damping; the bundled robot's smallest m_j
is about 7e-5 kg m^2, so at dt = 0.01 s RK4 is stable only for k_d up to about 0.02 N m s/rad
(:meth:`PDJoints.largest_stable_step_s` computes the limit from the robot's mass matrix). Beyond
it the run blows up and is flagged ill-conditioned, and the reason says so and points to a
smaller step or the servo model (:func:`stiffness_hint`), which is how stiff real joints are
modelled.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar, cast

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


class PDJointParameters(JointParameters):
    """``[joints]`` of the PD model (``model = "pd"``, the default).

    Attributes
    ----------
    kp_nm_per_rad, kd_nms_per_rad : float
        PD gains of the joint loop u = k_p (alpha - phi) + k_d (alpha_dot - phi_dot).
    """

    model_name: ClassVar[str] = "pd"

    kp_nm_per_rad: PositiveFloat
    kd_nms_per_rad: NonNegativeFloat


class PDJoints(JointModel):
    """The PD law on free joints (see the module docstring)."""

    name: ClassVar[str] = "pd"
    parameters: ClassVar[type[JointParameters]] = PDJointParameters
    kinematic: ClassVar[bool] = False
    # the gains soak up what the paper's robot did differently (docs/model.md section 8); k_d's
    # upper bound is about RK4's stability limit at dt = 0.01 s for the bundled robot
    fit_parameters: ClassVar[tuple[tuple[str, float, float], ...]] = (
        ("kp_nm_per_rad", 0.01, 1.0), ("kd_nms_per_rad", 0.0, 0.02))
    kernel_rows: ClassVar[tuple[str, ...]] = ("kp", "kd", "stall", "stall_slope")
    # the paper's gains are the robot's own (docs/estimation.md, "The protocol"): a fit keeps them
    fitted_by_estimator: ClassVar[bool] = False

    # fit_values and with_fit_values read and replace the record's fields named in
    # fit_parameters, so a model extending this one (pd_limited) fits other fields by naming them
    def fit_values(self, spec: JointParameters) -> FloatArray:
        """The fitted fields' values in ``fit_names`` order: (k_p, k_d) for this model."""
        p = self._own(spec)
        return np.array([getattr(p, name) for name in self.fit_names], dtype=float)

    def with_fit_values(self, spec: JointParameters, values: ArrayLike) -> JointParameters:
        """``spec`` as this model's record with the fitted fields replaced (validated)."""
        p = self._own(spec)
        numbers = (float(v) for v in np.asarray(values, dtype=float).reshape(len(self.fit_names)))
        return self.parameters.model_validate(
            {**p.model_dump(), **dict(zip(self.fit_names, numbers, strict=True))})

    def _own(self, spec: JointParameters) -> PDJointParameters:
        """``spec``, refused with a TypeError unless it is this model's record (or a subclass's)."""
        if not isinstance(spec, self.parameters):
            raise TypeError(f"the {self.name} joint model needs its own parameters, got "
                            f"{type(spec).__name__}")
        # every PD-family record derives from PDJointParameters (PDJoints.parameters and below)
        return cast(PDJointParameters, spec)

    def drive(
        self,
        spec: JointParameters,
        alpha_rad: FloatArray,
        alpha_dot_rad_s: FloatArray,
        phi_rad: FloatArray,
        phi_dot_rad_s: FloatArray,
    ) -> FloatArray:
        """Joint torques u = k_p (alpha - phi) + k_d (alpha_dot - phi_dot), N m."""
        from eelsim.control import joint_pd_torque

        p = self._own(spec)
        return joint_pd_torque(alpha_rad, alpha_dot_rad_s, phi_rad, phi_dot_rad_s,
                               p.kp_nm_per_rad, p.kd_nms_per_rad)

    def kernel_values(self, spec: JointParameters, servo_limits: bool) -> dict[str, float]:
        """Gains, and the torque-speed clip (stall = inf and slope 0 when it is off)."""
        p = self._own(spec)
        stall = p.servo_max_torque_nm if servo_limits else np.inf
        # stall * (1 / no_load): the expression the kernel's rows had (the same rounding)
        slope = p.servo_max_torque_nm * (1.0 / p.servo_max_speed_rad_s) if servo_limits else 0.0
        return {"kp": p.kp_nm_per_rad, "kd": p.kd_nms_per_rad, "stall": stall,
                "stall_slope": slope}

    def emit_joint(self, code: KernelCode, plain: bool) -> None:
        """The PD law, then (unless ``plain``) the clip to the torque-speed line."""
        line, w = code.line, code.w
        line(f"jout = {w('kp')} * (al - ph) + {w('kd')} * (ald - phd)")
        if not plain:
            # |u| <= stall (1 -+ phd / no_load) on either side: stall = inf and the slope 0 when
            # the clip is off, which leaves the torque unchanged exactly (so ``plain`` gives the
            # same numbers)
            line(f"jm_q = phd * {w('stall_slope')}")
            line(f"jm_stall = {w('stall')}")
            line("jout = min(max(jout, max(-jm_stall, -jm_stall - jm_q)), "
                 "min(jm_stall, jm_stall - jm_q))")

    def largest_stable_step_s(self, spec: JointParameters, model: SwimmerModel) -> float:
        """From the joint modes at the straight pose: M s^2 + k_d S s + k_p S, S = D^T D.

        The generalised eigenvalues mu of (S, M) give each mode s^2 + k_d mu s + k_p mu = 0.
        """
        # (eelsim.dynamics imports eelsim.robot, which imports this module: not at the top)
        from eelsim.dynamics import mass_matrix, straight_state

        p = self._own(spec)
        n = model.n_links
        big_m = mass_matrix(model, straight_state(model))
        d = np.diff(np.eye(n), axis=0)  # phi = d theta
        stiffness = np.zeros_like(big_m)
        stiffness[:n, :n] = d.T @ d
        chol_inv = np.linalg.inv(np.linalg.cholesky(big_m))
        mu = np.linalg.eigvalsh(chol_inv @ stiffness @ chol_inv.T)
        rates: list[complex] = []
        for m in mu[mu > 1e-12 * mu.max()]:
            rates.extend(np.roots([1.0, p.kd_nms_per_rad * m, p.kp_nm_per_rad * m]))
        return largest_stable_step(rates)


    def check_step(self, spec: JointParameters, model: SwimmerModel, dt_s: float) -> None:
        """Accept every step: a blow-up is flagged ill-conditioned, with :func:`stiffness_hint`."""


def stiffness_hint(spec: JointParameters, stable_step_s: float, dt_s: float) -> str:
    """What to add to a blow-up's reason when the PD joints are too stiff for RK4 at ``dt_s``.

    Parameters
    ----------
    spec : JointParameters
        The PD model's parameters.
    stable_step_s : float
        :meth:`PDJoints.largest_stable_step_s` of the robot.
    dt_s : float
        The physics step.

    Returns
    -------
    str
        Empty when the step is inside the limit (the blow-up then has another cause).
    """
    if not dt_s > stable_step_s:
        return ""
    p = PD._own(spec)
    return (
        f"; the PD joints (k_p {p.kp_nm_per_rad:g} N m/rad, k_d {p.kd_nms_per_rad:g} N m s/rad) "
        f"are too stiff for explicit RK4 at dt = {dt_s:g} s (stable below about "
        f"{stable_step_s:.2g} s): use a smaller step or the servo joint model "
        f'([joints] model = "servo"), which models stiff joints (docs/model.md section 4)'
    )


def pd_gains(spec: JointParameters) -> tuple[float, float] | None:
    """The PD model's gains (k_p, k_d) in N m/rad and N m s/rad; None for another joint model.

    For what the firmware is sent (SetGains): with the servo model the servos close their own
    loop and the firmware's torques drive nothing.

    Parameters
    ----------
    spec : JointParameters

    Returns
    -------
    tuple of float, or None
    """
    if not isinstance(spec, PDJointParameters):
        return None
    return spec.kp_nm_per_rad, spec.kd_nms_per_rad


PD = register_joint_model(PDJoints(), "the paper's PD loop driving free joints with torques")
"""The PD model, registered as ``"pd"`` (the default)."""
