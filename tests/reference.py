"""An independent, converged reference: scipy's adaptive DOP853 on the continuous road, tight tolerances."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from vehid_cli.models.fullcar import FullCarMatrices


def reference_response(
    mats: FullCarMatrices, road_fn, t: np.ndarray, rtol: float = 1e-11
) -> tuple[np.ndarray, np.ndarray]:
    """Body-point displacement and acceleration (n, 4) of one car, from rest at zero, on road_fn(t) -> (k, 4)."""
    A, Bs = mats.state_space()
    G = mats.G

    def rhs(time, s):
        return A @ s + Bs @ road_fn(np.array([time]))[0]

    sol = solve_ivp(rhs, (t[0], t[-1]), np.zeros(14), method="DOP853", t_eval=t, rtol=rtol, atol=1e-14, max_step=1e-3)
    assert sol.success, sol.message
    s = sol.y.T
    sd = s @ A.T + road_fn(t) @ Bs.T
    return s[:, :3] @ G.T, sd[:, 7:10] @ G.T


def rel_rms(x: np.ndarray, ref: np.ndarray) -> float:
    return float(np.sqrt(np.mean((x - ref) ** 2)) / np.sqrt(np.mean(ref**2)))
