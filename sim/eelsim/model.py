"""The swimmer's per-link parameters: hydrodynamic coefficients and planar geometry.

``SwimmerModel`` turns a :class:`~eelsim.robot.Robot` (and, optionally, another set of hydrodynamic
coefficients) into the arrays the dynamics use, one entry per link, so links may differ.

Coefficients (spec section 2), for a link of half-length l, half-axes a (vertical) and b, in water
of density rho:

    c_t = 0.5 rho pi C_f (a + b)/2 * 2l          c_n = 0.5 rho C_d 2a * 2l
    mu_n = rho pi C_a a^2 * 2l                   lambda_1 = rho pi C_m (a^2 - b^2)^2 l^3 / 12
    lambda_2 = rho pi C_f (a + b) l^3 / 6        lambda_3 = rho pi C_f (a + b) l^4 / 8

Geometry: link centres are X = p_x + G cos(theta), Y = p_y + G sin(theta), where p is the centre of
mass (mass-weighted mean of the link centres; the plain mean when masses are equal) and G is an
N x N matrix fixed by the half-lengths and masses. For identical links G = -l K^T (spec section 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from eelsim.robot import HydroCoefficients, Robot

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LinkCoefficients:
    """Fluid coefficients of the links (arrays of shape (N,) or scalars).

    Attributes
    ----------
    c_t, c_n : ndarray
        Tangential and normal drag coefficients, kg/s (linear) and kg/m (quadratic).
    mu_n : ndarray
        Added mass in the normal direction, kg.
    lambda_1 : ndarray
        Added yaw inertia, kg m^2.
    lambda_2, lambda_3 : ndarray
        Linear and quadratic fluid yaw damping.
    """

    c_t: FloatArray
    c_n: FloatArray
    mu_n: FloatArray
    lambda_1: FloatArray
    lambda_2: FloatArray
    lambda_3: FloatArray


def link_coefficients(
    half_length_m: FloatArray | float,
    half_axis_vertical_m: FloatArray | float,
    half_axis_horizontal_m: FloatArray | float,
    coefficients: HydroCoefficients,
    water_density_kg_m3: float = 1000.0,
) -> LinkCoefficients:
    """Compute the per-link fluid coefficients from e = (C_f, C_d, C_a, C_m) (spec section 2).

    Parameters
    ----------
    half_length_m, half_axis_vertical_m, half_axis_horizontal_m : float or ndarray
        l, a and b of each link.
    coefficients : HydroCoefficients
        The hydrodynamic parameters.
    water_density_kg_m3 : float
        rho.

    Returns
    -------
    LinkCoefficients
    """
    l_ = np.asarray(half_length_m, dtype=float)
    a = np.asarray(half_axis_vertical_m, dtype=float)
    b = np.asarray(half_axis_horizontal_m, dtype=float)
    rho = water_density_kg_m3
    e = coefficients
    return LinkCoefficients(
        c_t=0.5 * rho * np.pi * e.C_f * (a + b) / 2.0 * 2.0 * l_,
        c_n=0.5 * rho * e.C_d * 2.0 * a * 2.0 * l_,
        mu_n=rho * np.pi * e.C_a * a**2 * 2.0 * l_,
        lambda_1=rho * np.pi * e.C_m * (a**2 - b**2) ** 2 * l_**3 / 12.0,
        lambda_2=rho * np.pi * e.C_f * (a + b) * l_**3 / 6.0,
        lambda_3=rho * np.pi * e.C_f * (a + b) * l_**4 / 8.0,
    )


def geometry_matrix(half_length_m: FloatArray, mass_kg: FloatArray) -> FloatArray:
    """Matrix G with link centre x_i = p_x + sum_k G[i, k] cos(theta_k) (and y with sin).

    Link i+1 is ahead of link i: x_{i+1} - x_i = l_i cos(theta_i) + l_{i+1} cos(theta_{i+1}), and
    p is the mass-weighted mean of the link centres.

    Parameters
    ----------
    half_length_m, mass_kg : ndarray, shape (N,)

    Returns
    -------
    ndarray, shape (N, N)
    """
    half = np.asarray(half_length_m, dtype=float)
    n = half.size
    # B[i, k]: position of link centre i relative to link centre 1, per cos(theta_k).
    idx = np.arange(n)
    rows, cols = idx[:, None], idx[None, :]
    b = half[None, :] * ((cols <= rows - 1).astype(float) + ((cols >= 1) & (cols <= rows)))
    w = np.asarray(mass_kg, dtype=float)
    w = w / w.sum()
    return b - np.outer(np.ones(n), w @ b)


@dataclass(frozen=True)
class SwimmerModel:
    """Everything the dynamics need, per link (tail = index 0, head = index N-1).

    Build it with :meth:`from_robot`. All arrays have shape (N,) except ``geometry`` (N, N).
    """

    n_links: int
    half_length_m: FloatArray
    mass_kg: FloatArray
    yaw_inertia_kg_m2: FloatArray
    half_axis_vertical_m: FloatArray
    half_axis_horizontal_m: FloatArray
    fluid: LinkCoefficients
    geometry: FloatArray
    coefficients: HydroCoefficients
    water_density_kg_m3: float

    @classmethod
    def from_robot(
        cls, robot: Robot, coefficients: HydroCoefficients | None = None
    ) -> SwimmerModel:
        """Build the model of ``robot``, optionally with other hydrodynamic coefficients.

        Parameters
        ----------
        robot : Robot
            The robot description.
        coefficients : HydroCoefficients, optional
            Replaces ``robot.hydrodynamics`` (used by estimation to try candidates).

        Returns
        -------
        SwimmerModel
        """
        links = robot.links()
        half = np.array([lk.half_length_m for lk in links])
        mass = np.array([lk.mass_kg for lk in links])
        inertia = np.array(
            [
                lk.yaw_inertia_kg_m2
                if lk.yaw_inertia_kg_m2 is not None
                else lk.mass_kg * lk.half_length_m**2 / 3.0
                for lk in links
            ]
        )
        a = np.array([lk.half_axis_vertical_m for lk in links])
        b = np.array([lk.half_axis_horizontal_m for lk in links])
        coeffs = coefficients if coefficients is not None else robot.hydrodynamics
        return cls(
            n_links=robot.n_links,
            half_length_m=half,
            mass_kg=mass,
            yaw_inertia_kg_m2=inertia,
            half_axis_vertical_m=a,
            half_axis_horizontal_m=b,
            fluid=link_coefficients(half, a, b, coeffs, robot.water_density_kg_m3),
            geometry=geometry_matrix(half, mass),
            coefficients=coeffs,
            water_density_kg_m3=robot.water_density_kg_m3,
        )

    @property
    def state_size(self) -> int:
        """Length of the state vector (theta, p, theta_dot, p_dot): 2 N + 4."""
        return 2 * self.n_links + 4

    @property
    def body_length_m(self) -> float:
        """Total length of the robot, BL."""
        return float(2.0 * self.half_length_m.sum())
