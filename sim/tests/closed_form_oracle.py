"""The paper's closed form (docs/model.md section 3), written separately as a test oracle.

Only valid for identical links. Deliberately written in the paper's matrix notation, sharing no
code with eelsim.dynamics except the coefficient values.
"""

import numpy as np


def closed_form_accelerations(n, l, m, ct, cn, mu, lam1, lam2, lam3, state, u, vc):
    theta = state[:n]
    pd = state[n + 2 + n :]
    td = state[n + 2 : 2 * n + 2]
    A = np.zeros((n - 1, n))
    D = np.zeros((n - 1, n))
    for j in range(n - 1):
        A[j, j] = A[j, j + 1] = 1.0
        D[j, j], D[j, j + 1] = 1.0, -1.0
    e = np.ones(n)
    DDinv = np.linalg.inv(D @ D.T)
    K = A.T @ DDinv @ D
    V = A.T @ DDinv @ A
    S, C = np.diag(np.sin(theta)), np.diag(np.cos(theta))
    I = np.eye(n)
    J = m * l**2 / 3.0
    ee = np.outer(e, e)
    Mp_inv = np.array(
        [
            [n * m + mu * e @ S @ S @ e, -mu * e @ S @ C @ e],
            [-mu * e @ S @ C @ e, n * m + mu * e @ C @ C @ e],
        ]
    )
    Mp = np.linalg.inv(Mp_inv)
    m11, m12, m21, m22 = Mp[0, 0], Mp[0, 1], Mp[1, 0], Mp[1, 1]
    A1 = S @ K @ S @ S + C @ K @ S @ C
    A2 = S @ K @ S @ C + C @ K @ C @ C
    K1 = (
        A1 + mu * A1 @ ee @ (m12 * S @ C - m11 * S @ S) - mu * A2 @ ee @ (m22 * S @ C - m21 * S @ S)
    )
    K2 = (
        A2 - mu * A1 @ ee @ (m11 * S @ C - m12 * C @ C) + mu * A2 @ ee @ (m21 * S @ C - m22 * C @ C)
    )
    M_theta = (
        J * I
        + m * l**2 * S @ V @ S
        + m * l**2 * C @ V @ C
        + lam1 * I
        + l**2 * mu * K1 @ K.T @ S
        + l**2 * mu * K2 @ K.T @ C
    )
    W_theta = (
        m * l**2 * S @ V @ C
        - m * l**2 * C @ V @ S
        + l**2 * mu * K1 @ K.T @ C
        - l**2 * mu * K2 @ K.T @ S
    )
    Vx, Vy = vc[0] * I, vc[1] * I
    V_theta = lam2 * I - l * mu * K2 @ Vx - l * mu * K1 @ Vy
    K_Dx = l * mu * m11 * A1 @ ee - l * mu * m21 * A2 @ ee - l * S @ K
    K_Dy = l * mu * m12 * A1 @ ee - l * mu * m22 * A2 @ ee + l * C @ K
    # Link velocities and drag (paper eqs. 9-11): X_dot = l K^T S td + e px_dot, etc.
    Xd = l * K.T @ S @ td + e * pd[0]
    Yd = -l * K.T @ C @ td + e * pd[1]
    rx, ry = Xd - vc[0], Yd - vc[1]
    c, s = np.cos(theta), np.sin(theta)
    vt = c * rx + s * ry
    vn = -s * rx + c * ry
    fDx = -ct * (vt + np.abs(vt) * vt) * c + cn * (vn + np.abs(vn) * vn) * s
    fDy = -ct * (vt + np.abs(vt) * vt) * s - cn * (vn + np.abs(vn) * vn) * c
    u_paper = -np.asarray(u)
    rhs = (
        D.T @ u_paper
        - W_theta @ td**2
        - V_theta @ td
        - lam3 * np.abs(td) * td
        - K_Dx @ fDx
        - K_Dy @ fDy
    )
    tdd = np.linalg.solve(M_theta, rhs)
    # Centre of mass (paper eq. 6 as restated in docs/model.md section 3).
    fcur_n = -mu * td * (c * vc[0] + s * vc[1])
    fcx, fcy = -fcur_n * s, fcur_n * c
    ax = l * K.T @ (C @ td**2 + S @ tdd)
    ay = l * K.T @ (S @ td**2 - C @ tdd)
    an = -s * ax + c * ay  # n_i . (link acceleration minus p_ddot)
    fx = fDx.sum() + fcx.sum() - (mu * an * -s).sum()
    fy = fDy.sum() + fcy.sum() - (mu * an * c).sum()
    pdd = Mp @ np.array([fx, fy])
    return tdd, pdd
