"""What the Galilean-consistent fluid laws share: the added-mass force of the relative motion.

A link's fluid impulse, with added mass mu_n in its normal direction only, is
P = mu_n (n . w) n, w = v - v_c its centre's velocity relative to the water. The force of the
water is -dP/dt and, for a steady uniform current (dw/dt = a, dn/dt = -theta_dot t),

    -dP/dt = -mu_n (n . a) n + mu_n theta_dot (w_t n + w_n t)

with w_t = t . w and w_n = n . w; the moment of the impulse about the centre, the Munk moment, is
-(w x P) = -mu_n w_t w_n. The first term is the mass matrix's mu_n n n^T (docs/model.md section
2); the rest, the *reactive* terms, are written here. Every term depends only on the motion
relative to the water, so swimming in a steady uniform current is swimming in still water carried
along by it (Galilean consistency; the paper's Morison law is not: its current term
-mu_n theta_dot (t . v_c) n is the current's part of mu_n theta_dot w_t n without the body's own
part mu_n theta_dot (t . v) n). Without drag these forces do no net work: the kinetic energy of
the bodies and the added mass, relative to the water, changes only by the joints' work.

A law of this family (:class:`RelativeMotionLaw`) writes only its drag and yaw damping
(:meth:`RelativeMotionLaw.drag`, :meth:`RelativeMotionLaw.emit_drag`) and inherits these terms
in both forms (docs/model.md section 2, "Galilean-consistent laws").
"""

from __future__ import annotations

import abc

from eelsim.fluid.base import FloatArray, FluidLaw, KernelCode, LinkFluid, LinkForces, LinkMotion


class RelativeMotionLaw(FluidLaw):
    """A fluid law whose forces depend only on the motion relative to the water (see module)."""

    @abc.abstractmethod
    def drag(
        self, fluid: LinkFluid, vt: FloatArray, vn: FloatArray, omega: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The law's drag along t and n and its yaw damping torque, on each link (numpy).

        Parameters
        ----------
        fluid : LinkFluid
            The law's per-link coefficients.
        vt, vn : ndarray
            Tangential and normal components of the centre's velocity relative to the water.
        omega : ndarray
            Link rates theta_dot.

        Returns
        -------
        (f_t, f_n, torque) : ndarrays
            Force along t and n, N, and torque, N m, of the water on each link.
        """

    @abc.abstractmethod
    def emit_drag(self, code: KernelCode, link: int) -> tuple[str, str, str]:
        """The batched form of :meth:`drag`: lines for one link, and three expressions.

        The lines may read ``fl_vt``, ``fl_vn`` (set before) and ``om``, and assign only ``fl_...``
        temporaries; the expressions give minus the tangential force, minus the normal force and
        minus the torque.

        Parameters
        ----------
        code : KernelCode
        link : int

        Returns
        -------
        (str, str, str)
        """

    def forces(self, fluid: LinkFluid, motion: LinkMotion, current_m_s: FloatArray) -> LinkForces:
        """The law's drag and damping plus the reactive added-mass terms (module docstring)."""
        s, c, om = motion.sin, motion.cos, motion.omega
        vt = c * motion.rel_vx + s * motion.rel_vy
        vn = -s * motion.rel_vx + c * motion.rel_vy
        ft, fn, torque = self.drag(fluid, vt, vn, om)
        rt, rn = fluid.mu_n * om * vn, fluid.mu_n * om * vt
        return LinkForces(
            fx=(ft + rt) * c - (fn + rn) * s,
            fy=(ft + rt) * s + (fn + rn) * c,
            torque=torque - fluid.mu_n * vt * vn,
            parts={"drag": (ft * c - fn * s, ft * s + fn * c), "reactive": (rt * c - rn * s,
                                                                            rt * s + rn * c)},
        )

    def emit_link_forces(self, code: KernelCode, link: int, still_water: bool) -> None:
        """The same in the link's frame (the velocity is relative: no separate current term)."""
        line, w = code.line, code.w
        line("fl_vt = c * lvx + s * lvy")
        line("fl_vn = c * lvy - s * lvx")
        minus_t, minus_n, minus_torque = self.emit_drag(code, link)
        line(f"fl_mu = {w('mu', link)}")
        line(f"fl_ftn = {minus_t} - fl_mu * om * fl_vn")
        line(f"fnn = {minus_n} - fl_mu * om * fl_vt")
        line("fxn = fl_ftn * c - fnn * s")
        line("fyn = fl_ftn * s + fnn * c")
        line(f"tqn = {minus_torque} + fl_mu * fl_vt * fl_vn")
