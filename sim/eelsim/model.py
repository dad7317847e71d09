"""The swimmer's per-link parameters: fluid coefficients and planar geometry.

``SwimmerModel`` turns a :class:`~eelsim.robot.Robot` (and, optionally, other hydrodynamic
coefficients) into the arrays the dynamics use, one entry per link, so links may differ. The fluid
coefficients come from the robot's fluid law (:mod:`eelsim.fluid`; the paper's Morison law by
default, docs/model.md section 2).

Geometry: link centres are X = p_x + G cos(theta), Y = p_y + G sin(theta), where p is the centre of
mass (mass-weighted mean of the link centres; the plain mean when masses are equal) and G is an
N x N matrix fixed by the half-lengths and masses. For identical links G = -l K^T (docs/model.md
section 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from eelsim.fluid import FluidCoefficients, FluidLaw, LinkFluid, law_of
from eelsim.robot import Robot

FloatArray = NDArray[np.float64]


def link_coefficients(
    half_length_m: ArrayLike,
    half_axis_vertical_m: ArrayLike,
    half_axis_horizontal_m: ArrayLike,
    coefficients: FluidCoefficients,
    water_density_kg_m3: float = 1000.0,
) -> LinkFluid:
    """Per-link fluid coefficients of ``coefficients``' law (for Morison: c_t, c_n, mu_n, ...).

    Parameters
    ----------
    half_length_m, half_axis_vertical_m, half_axis_horizontal_m : float or ndarray
        l, a and b of each link.
    coefficients : FluidCoefficients
        The hydrodynamic parameters (e.g. ``HydroCoefficients``, the Morison law's).
    water_density_kg_m3 : float
        rho.

    Returns
    -------
    LinkFluid
        The law's per-link record (``MorisonLinkFluid`` for the Morison law).
    """
    return law_of(coefficients).link_coefficients(
        half_length_m, half_axis_vertical_m, half_axis_horizontal_m, coefficients.as_array(),
        water_density_kg_m3,
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
    fluid: LinkFluid
    geometry: FloatArray
    coefficients: FluidCoefficients
    water_density_kg_m3: float
    fluid_law: FluidLaw

    @classmethod
    def from_robot(
        cls, robot: Robot, coefficients: FluidCoefficients | None = None
    ) -> SwimmerModel:
        """Build the model of ``robot``, optionally with other hydrodynamic coefficients.

        Parameters
        ----------
        robot : Robot
            The robot description.
        coefficients : FluidCoefficients, optional
            Replaces ``robot.hydrodynamics`` (used by estimation to try candidates); their law
            is the model's.

        Returns
        -------
        SwimmerModel
        """
        links = robot.link_arrays()
        coeffs = coefficients if coefficients is not None else robot.hydrodynamics
        return cls(
            n_links=robot.n_links,
            half_length_m=links.half_length_m,
            mass_kg=links.mass_kg,
            yaw_inertia_kg_m2=links.yaw_inertia_kg_m2,
            half_axis_vertical_m=links.half_axis_vertical_m,
            half_axis_horizontal_m=links.half_axis_horizontal_m,
            fluid=link_coefficients(links.half_length_m, links.half_axis_vertical_m,
                                    links.half_axis_horizontal_m, coeffs,
                                    robot.water_density_kg_m3),
            geometry=geometry_matrix(links.half_length_m, links.mass_kg),
            coefficients=coeffs,
            water_density_kg_m3=robot.water_density_kg_m3,
            fluid_law=law_of(coeffs),
        )

    @property
    def state_size(self) -> int:
        """Length of the state vector (theta, p, theta_dot, p_dot): 2 N + 4."""
        return 2 * self.n_links + 4

    @property
    def body_length_m(self) -> float:
        """Total length of the robot, BL."""
        return float(2.0 * self.half_length_m.sum())
