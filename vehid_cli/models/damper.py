"""Damper force laws (Fleps-Dezasse 2013; Spencer et al. 1997), their parameter layouts and defaults; the
bench adapter that runs them through the compiled kernel is ``sim/bench.py``.

Every model is a numba force law of the kernel's shape ``law(d, dd, z, params, f_out, zd_out)`` driven
on a virtual test bench: the kernel's input channels are the bench's

    d = [x, v, u_delayed, rising]

displacement x [m] (extension positive), velocity v [m/s] (rebound positive: Fleps-Dezasse's convention),
and, for models with a control input, the command u [0..1] with each change delayed by the candidate's
delay for its direction and stroke, and the direction of the latest change (prepared per candidate by the
bench: the delay is an exact time shift). ``f_out[0]`` is the damper
force [N], positive in rebound; the other outputs are zero.

Common to every model (the "front end", parameters first in each row):

* gas spring ``F_gas = k1 (x - x0)``: preload and stiffness of the gas charge (Fleps-Dezasse section 2);
* backlash: a dead zone of width ``gap`` at each reversal (the play operator, applied exactly to the
  prescribed motion by the bench): the damper proper sees x_b and v_b instead of x and v;
* control-input dynamics: a delay and a first-order lag, both chosen by the direction of the command's
  change (rising/falling) and by the stroke (compression/rebound, the lag blended by Eq. 4-5).

The models proper: ``viscous`` (c0 v), ``bingham`` (c0 v + fc tanh(v / v_eps)), ``gas_spring`` (none),
``bouc_wen`` (Spencer's extended model, Eq. 1-3 with n = 2), ``generalized_bouc_wen`` (its seven
parameters as tables over u with compression and rebound sets blended by Eq. 4-5) and ``force_map``
(a table over velocity and delayed control input, Eq. 6).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

from ..core.jit import cached_njit

# ------------------------------------------------------------------------------------------ front end

FRONT = ("k1", "x0", "gap", "T_comp_rise", "T_comp_fall", "T_reb_rise", "T_reb_fall", "v_switch")
N_FRONT = len(FRONT)
DELAYS = ("tau_comp_rise", "tau_comp_fall", "tau_reb_rise", "tau_reb_fall")  # applied by the bench
CONTROL_STATE = 1  # models with a control input carry u_f (the lagged input) as their last state
P0 = N_FRONT + len(DELAYS)  # where a model's own parameters start in a row
BW_SET = ("c0", "k0", "c1", "alpha", "beta", "gamma", "delta")  # Bouc-Wen parameters that depend on u and side
# SI units of every parameter a row can hold ('-': dimensionless, a count or the control input's own scale); the
# tables' expanded names (c0_comp_2, v_node_1, F_2_3) take their base name's (DamperModel.unit).
UNITS = {
    "k1": "N/m", "x0": "m", "gap": "m", "v_switch": "m/s",
    **{n: "s" for n in FRONT[3:7] + DELAYS},
    "c0": "N s/m", "fc": "N", "v_eps": "m/s", "k0": "N/m", "c1": "N s/m", "alpha": "N/m", "beta": "1/m²",
    "gamma": "1/m²", "delta": "-", "m": "-", "nv": "-", "nu": "-", "u_node": "-", "v_node": "m/s", "F": "N",
}  # fmt: skip


@numba.njit(error_model="numpy", inline="always")
def _switch(v, eps):  # pragma: no cover - compiled
    """Eq. 5: 0 in compression, 1 in rebound, smooth over |v| ~ eps: s = 0.5 tanh(v / eps) + 0.5, computed as the
    logistic 1 / (1 + exp(-2 v / eps)) (the same function; an exp costs a third of a tanh, and the control models
    evaluate it at every RK4 stage of every candidate)."""
    return _logistic(v / eps)


@numba.njit(error_model="numpy", inline="always")
def _logistic(x):  # pragma: no cover - compiled
    """0.5 tanh(x) + 0.5 = 1 / (1 + exp(-2 x)) (within 2.3e-16)."""
    return 1.0 / (1.0 + math.exp(-2.0 * x))


@cached_njit()
def play(x, v, gap):  # pragma: no cover - compiled
    """Backlash on prescribed motion: the piston (x_b, v_b) follows x through a play of width gap, resting
    after each reversal until the gap is taken up (the play operator, exact; x_b starts centred)."""
    n = x.shape[0]
    xb, vb = np.empty(n), np.empty(n)
    xb[0], vb[0] = x[0], v[0]
    half = 0.5 * gap
    for k in range(1, n):
        xb[k] = min(max(xb[k - 1], x[k] - half), x[k] + half)
        vb[k] = v[k] if xb[k] != xb[k - 1] else 0.0
    return xb, vb


@numba.njit(error_model="numpy", inline="always")
def _control(d, z, p, zd, v, i):  # pragma: no cover - compiled
    """Control-input dynamics: the delayed command d[2] (each change of u takes effect after the delay of its
    direction and of the stroke it happens in; prepared by the bench) through a first-order lag whose time
    constant is chosen by the direction of the latest change (d[3]: 1 rising, 0 falling) and blended between
    compression and rebound by Eq. 4-5. Writes the rate of z[i] = u_f and returns the input the damper sees."""
    s = _switch(v, p[7])
    r = d[3]
    T = r * ((1 - s) * p[3] + s * p[5]) + (1 - r) * ((1 - s) * p[4] + s * p[6])
    if T > 0.0:
        zd[i] = (d[2] - z[i]) / T
        return z[i]
    zd[i] = 0.0
    return d[2]


@numba.njit(error_model="numpy", inline="always")
def _finish(x, p, f_out, force):  # pragma: no cover - compiled
    f_out[0] = force + p[0] * (x - p[1])
    for i in range(1, f_out.shape[0]):
        f_out[i] = 0.0


# ------------------------------------------------------------------------------------------ force laws


@cached_njit(error_model="numpy")
def viscous_law(d, dd, z, p, f_out, zd):  # pragma: no cover - compiled
    """F = c0 v + gas. params: front, c0."""
    _finish(d[0], p, f_out, p[P0] * d[1])


@cached_njit(error_model="numpy")
def gas_spring_law(d, dd, z, p, f_out, zd):  # pragma: no cover - compiled
    """F = k1 (x - x0) only."""
    _finish(d[0], p, f_out, 0.0)


@cached_njit(error_model="numpy")
def bingham_law(d, dd, z, p, f_out, zd):  # pragma: no cover - compiled
    """F = c0 v + fc tanh(v / v_eps) + gas (viscous plus smoothed Coulomb friction). params: front, c0, fc, v_eps."""
    vb = d[1]
    c0, fc, veps = p[P0], p[P0 + 1], p[P0 + 2]
    _finish(d[0], p, f_out, c0 * vb + fc * math.tanh(vb / veps))


@numba.njit(error_model="numpy", inline="always")
def _bouc_wen(xb, vb, y, zz, c0, k0, c1, alpha, beta, gamma, delta):  # pragma: no cover - compiled
    """Spencer's extended Bouc-Wen with n = 2 (Fleps-Dezasse Eq. 1-3): (force without gas, ydot, zdot)."""
    ydot = (alpha * zz + c0 * vb + k0 * (xb - y)) / (c0 + c1)
    w = vb - ydot
    zdot = -gamma * abs(w) * zz * abs(zz) - beta * w * zz * zz + delta * w
    return c0 * w + k0 * (xb - y) + alpha * zz, ydot, zdot


@cached_njit(error_model="numpy")
def bouc_wen_law(d, dd, z, p, f_out, zd):  # pragma: no cover - compiled
    """Spencer's extended Bouc-Wen; states z[0] = y (internal displacement), z[1] = z (hysteretic).
    params: front, c0, k0, c1, alpha, beta, gamma, delta."""
    xb, vb = d[0], d[1]
    q = P0
    force, ydot, zdot = _bouc_wen(xb, vb, z[0], z[1], p[q], p[q + 1], p[q + 2], p[q + 3], p[q + 4], p[q + 5], p[q + 6])
    zd[0] = ydot
    zd[1] = zdot
    _finish(d[0], p, f_out, force)


@numba.njit(error_model="numpy", inline="always")
def _table_1d(nodes, values, m, u):  # pragma: no cover - compiled
    """Linear interpolation in a table of m nodes (held constant outside). The fraction of the interval is the offset
    times the interval's reciprocal (what the batch laws keep from call to call instead of dividing)."""
    if m == 1 or u <= nodes[0]:
        return values[0]
    if u >= nodes[m - 1]:
        return values[m - 1]
    j = 0
    while nodes[j + 1] < u:
        j += 1
    t = (u - nodes[j]) * (1.0 / (nodes[j + 1] - nodes[j]))
    return (1 - t) * values[j] + t * values[j + 1]


@cached_njit(error_model="numpy")
def generalized_bouc_wen_law(d, dd, z, p, f_out, zd):  # pragma: no cover - compiled
    """Bouc-Wen whose 7 parameters are tables over u, one set for compression and one for rebound, blended
    by Eq. 4-5. params: front, m, u_nodes (m), comp set (7 x m, parameter-major), rebound set (7 x m)."""
    xb, vb = d[0], d[1]
    u = _control(d, z, p, zd, vb, 2)
    q = P0
    m = int(p[q])
    nodes = p[q + 1 : q + 1 + m]
    comp = q + 1 + m
    reb = comp + 7 * m
    s = _switch(vb, p[7])

    def blended(i):  # parameter i of the Bouc-Wen set at the current u, compression and rebound blended
        c = _table_1d(nodes, p[comp + i * m : comp + (i + 1) * m], m, u)
        r = _table_1d(nodes, p[reb + i * m : reb + (i + 1) * m], m, u)
        return s * r + (1 - s) * c

    force, ydot, zdot = _bouc_wen(
        xb, vb, z[0], z[1], blended(0), blended(1), blended(2), blended(3), blended(4), blended(5), blended(6)
    )
    zd[0] = ydot
    zd[1] = zdot
    _finish(d[0], p, f_out, force)


@cached_njit(error_model="numpy")
def force_map_law(d, dd, z, p, f_out, zd):  # pragma: no cover - compiled
    """Eq. 6: F = table(v, u) + gas, bilinear in velocity and delayed control input (held outside the grid).
    params: front, nv, nu, v_nodes (nv), u_nodes (nu), forces (nv x nu, velocity-major)."""
    vb = d[1]
    u = _control(d, z, p, zd, vb, 0)
    q = P0
    nv, nu = int(p[q]), int(p[q + 1])
    vn = p[q + 2 : q + 2 + nv]
    un = p[q + 2 + nv : q + 2 + nv + nu]
    F = p[q + 2 + nv + nu : q + 2 + nv + nu + nv * nu]
    # bilinear: the velocity interval (extrapolated linearly outside the grid), each of its two rows in u
    j = 0
    if vb >= vn[nv - 1]:
        j = nv - 2
    elif vb > vn[0]:
        while vn[j + 1] < vb:
            j += 1
    t = (vb - vn[j]) / (vn[j + 1] - vn[j])
    lo = _table_1d(un, F[j * nu : (j + 1) * nu], nu, u)
    hi = _table_1d(un, F[(j + 1) * nu : (j + 2) * nu], nu, u)
    force = (1 - t) * lo + t * hi
    _finish(d[0], p, f_out, force)


# ------------------------------------------------------------------------------------------ lane laws
# The same laws over a whole batch of candidates at once (``lanes``): ``law(d, z, par, f, zd, w, fresh, read)`` with
# the bench's channels d (n_u, P), the states z and their rates zd (n_z, P), the rows par (n_par, P, transposed), the
# force f (P,), the law's scratch w, whether d is new since the call before and whether the force is read (the output;
# at RK4's stages only zd is: a law may leave f as it is) (``sim.prescribed.lanes_loop``). The
# candidates are independent, so the compiled loop over them (innermost) runs several at a time (SIMD, overlapped
# latency chains) instead of one candidate's serial chain of RK4 stages; a table look-up runs as passes over the
# batch. Each is the scalar law above, operation for operation: the forces agree bit for bit
# (tests/test_damper_lanes.py); the scalar laws stay as the reference path.


@numba.njit(error_model="numpy", inline="always")
def viscous_lanes(d, z, par, f, zd, w, fresh, read):  # pragma: no cover - compiled
    """``viscous_law`` over the batch."""
    for p in range(f.shape[0]):
        f[p] = par[P0, p] * d[1, p] + par[0, p] * (d[0, p] - par[1, p])


@numba.njit(error_model="numpy", inline="always")
def gas_spring_lanes(d, z, par, f, zd, w, fresh, read):  # pragma: no cover - compiled
    """``gas_spring_law`` over the batch."""
    for p in range(f.shape[0]):
        f[p] = 0.0 + par[0, p] * (d[0, p] - par[1, p])


@numba.njit(error_model="numpy", inline="always")
def bingham_lanes(d, z, par, f, zd, w, fresh, read):  # pragma: no cover - compiled
    """``bingham_law`` over the batch."""
    for p in range(f.shape[0]):
        vb = d[1, p]
        force = par[P0, p] * vb + par[P0 + 1, p] * math.tanh(vb / par[P0 + 2, p])
        f[p] = force + par[0, p] * (d[0, p] - par[1, p])


@numba.njit(error_model="numpy", inline="always")
def bouc_wen_lanes(d, z, par, f, zd, w, fresh, read):  # pragma: no cover - compiled
    """``bouc_wen_law`` over the batch: states z[0] = y, z[1] = z."""
    q = P0
    for p in range(f.shape[0]):
        xb, vb = d[0, p], d[1, p]
        force, ydot, zdot = _bouc_wen(
            xb, vb, z[0, p], z[1, p], par[q, p], par[q + 1, p], par[q + 2, p], par[q + 3, p], par[q + 4, p],
            par[q + 5, p], par[q + 6, p],
        )  # fmt: skip
        zd[0, p] = ydot
        zd[1, p] = zdot
        f[p] = force + par[0, p] * (xb - par[1, p])


# The control models' scratch (w): Eq. 5's switch and the ratio v / v_switch it was computed at (kept from call to
# call: RK4's stages 2 and 3, and its stage 4 and the output, see the same inputs), the input the damper sees (u),
# (the force map) the velocity's interval in the table's nodes and the fraction in it (the generalised model: the
# cell of u of its latest look-up, -1 when it had none), the u last looked up and what was found there (the
# generalised model: its fourteen tables' values; the force map: the cell of u), and the reciprocals of the u nodes'
# intervals (computed at the first call: a look-up multiplies by them instead of dividing).
W_S, W_X, W_U, W_JV, W_TV, W_AT, W_TAB = range(7)  # W_TAB..W_TAB + 13: the tables at u (compression, rebound)
W_INV = W_TAB + 14  # W_INV..W_INV + N_INV - 1: 1 / (node i+1 - node i) of the u nodes
N_INV = 12  # intervals whose reciprocals are kept; a table of more nodes divides at each look-up (the same numbers)
N_SCRATCH = W_INV + N_INV


@numba.njit(error_model="numpy", inline="always")
def _reciprocals(par, first, m, w):  # pragma: no cover - compiled
    """At the first call (its rows still NaN), w[W_INV + i] <- 1 / (node i + 1 - node i) of every candidate's m u nodes
    par[first : first + m]; returns whether they are kept (m - 1 <= N_INV)."""
    kept = m - 1 <= N_INV
    if kept and m > 1 and not w[W_INV, 0] == w[W_INV, 0]:
        for i in range(m - 1):
            for p in range(w.shape[1]):
                w[W_INV + i, p] = 1.0 / (par[first + i + 1, p] - par[first + i, p])
    return kept


@numba.njit(error_model="numpy", inline="always")
def _switches(d, par, w):  # pragma: no cover - compiled
    """w[W_S] = Eq. 5's switch of every candidate as ``_switch`` computes it, only where the ratio v / v_switch
    differs from the one it was last computed at for this candidate or for the one before (the candidates of a
    batch mostly share the motion and v_switch): same numbers, a fraction of the exp calls, the most expensive step
    of the control models."""
    for p in range(w.shape[1]):
        x = d[1, p] / par[7, p]
        if x == w[W_X, p]:
            continue
        if p > 0 and x == w[W_X, p - 1]:
            w[W_S, p] = w[W_S, p - 1]
        else:
            w[W_S, p] = _logistic(x)
        w[W_X, p] = x


@numba.njit(error_model="numpy", inline="always")
def _controls(d, z, par, zd, w, i):  # pragma: no cover - compiled
    """``_control`` of every candidate (the switch in w[W_S]): the rate of z[i] = u_f, the input it sees in w[W_U].
    Selects, not branches (the rate divided by T <= 0 is computed and dropped): the control models 2-4 % faster."""
    for p in range(w.shape[1]):
        s, r = w[W_S, p], d[3, p]
        T = r * ((1 - s) * par[3, p] + s * par[5, p]) + (1 - r) * ((1 - s) * par[4, p] + s * par[6, p])
        rate = (d[2, p] - z[i, p]) / T
        zd[i, p] = rate if T > 0.0 else 0.0
        w[W_U, p] = z[i, p] if T > 0.0 else d[2, p]


@numba.njit(error_model="numpy", inline="always")
def _cell(par, first, m, u, p, w, kept):  # pragma: no cover - compiled
    """Where candidate p's u falls in its m nodes par[first : first + m, p], found as ``_table_1d`` finds it but once
    for every table over the same nodes: (i, -1) for the value at node i itself (u at or outside the end nodes, or
    m = 1), else the interval j and the fraction t in [0, 1) of it (NaN for a NaN u): the offset from node j times the
    interval's reciprocal, kept in w (``_reciprocals``) or taken now, as ``_table_1d`` computes it."""
    if m == 1 or u <= par[first, p]:
        return 0, -1.0
    if u >= par[first + m - 1, p]:
        return m - 1, -1.0
    j = 0
    while par[first + j + 1, p] < u:
        j += 1
    a = par[first + j, p]
    return j, (u - a) * (w[W_INV + j, p] if kept else 1.0 / (par[first + j + 1, p] - a))


@numba.njit(error_model="numpy", inline="always")
def _velocity_cells(d, par, first, nv, w):  # pragma: no cover - compiled
    """The force map's interval of every candidate's velocity d[1] in its nv nodes par[first : first + nv] (the
    first or last one outside them: extrapolated) into w[W_JV], the fraction into w[W_TV], as ``force_map_law``
    finds them."""
    for p in range(w.shape[1]):
        vb = d[1, p]
        j = 0
        if vb >= par[first + nv - 1, p]:
            j = nv - 2
        elif vb > par[first, p]:
            while par[first + j + 1, p] < vb:
                j += 1
        w[W_JV, p] = j
        w[W_TV, p] = (vb - par[first + j, p]) / (par[first + j + 1, p] - par[first + j, p])


@numba.njit(error_model="numpy", inline="always")
def _at(par, first, j, t, p):  # pragma: no cover - compiled
    """``_table_1d``'s value of the table par[first : first + m, p] in the cell (j, t) that ``_cell`` found."""
    if t < 0.0:
        return par[first + j, p]
    return (1 - t) * par[first + j, p] + t * par[first + j + 1, p]


@numba.njit(error_model="numpy", inline="always")
def _blend_at(w, i, s, p):  # pragma: no cover - compiled
    """Parameter i of the Bouc-Wen set at u (its compression and rebound tables' values there in w), blended by s
    (Eq. 4-5) as ``generalized_bouc_wen_law`` blends them."""
    return s * w[W_TAB + 7 + i, p] + (1 - s) * w[W_TAB + i, p]


@numba.njit(error_model="numpy", inline="always")
def _blend1(par, comp, reb, i, s, p):  # pragma: no cover - compiled
    """``_blend`` of one-node tables (m = 1: the parameters do not depend on u)."""
    return s * par[reb + i, p] + (1 - s) * par[comp + i, p]


@numba.njit(error_model="numpy", inline="always")
def _lerp_rows(par, first, m, t, w, p):  # pragma: no cover - compiled
    """Candidate p's fourteen Bouc-Wen tables (compression 0..6, rebound 7..13: rows first + i m of par, first the
    row of the node the cell starts at) at fraction t of the cell into w[W_TAB + i], as ``_table_1d`` computes them."""
    if t < 0.0:  # at an end node: its value
        for i in range(14):
            w[W_TAB + i, p] = par[first + i * m, p]
    else:
        for i in range(14):
            w[W_TAB + i, p] = (1 - t) * par[first + i * m, p] + t * par[first + i * m + 1, p]


@numba.njit(error_model="numpy", inline="always")
def _tables_at(par, w, nodes, m, P):  # pragma: no cover - compiled
    """The generalised model's fourteen tables at every candidate's u (w[W_U]; its m nodes at rows nodes ..
    nodes + m - 1, the tables after them) into w[W_TAB ..], as ``_table_1d`` finds them (``_cell``), only for the
    candidates whose u changed since their last look-up (a held command, a settled lag: the same u). A pass of its
    own (its branches and search would keep the Bouc-Wen pass scalar), in two steps: the cells (w[W_JV], w[W_TV];
    -1 in w[W_JV]: unchanged), then the values. When every candidate's u changed and all fell in the same cell (the
    usual batch: the nodes held fixed by the config, the lags alike), the values are taken table by table over the
    whole batch (contiguous rows: SIMD) instead of candidate by candidate: the same numbers."""
    comp = nodes + m  # the compression tables' first row
    kept = _reciprocals(par, nodes, m, w)
    changed, shared, j0, end0 = 0, True, -1, False
    for p in range(P):
        u = w[W_U, p]
        if u == w[W_AT, p]:
            w[W_JV, p] = -1.0
            continue
        j, t = _cell(par, nodes, m, u, p, w, kept)
        if changed == 0:
            j0, end0 = j, t < 0.0
        shared &= j == j0 and (t < 0.0) == end0
        changed += 1
        w[W_JV, p], w[W_TV, p], w[W_AT, p] = j, t, u
    if changed == P and shared:
        first = comp + j0
        for i in range(14):
            row = first + i * m
            if end0:
                for p in range(P):
                    w[W_TAB + i, p] = par[row, p]
            else:
                for p in range(P):
                    t = w[W_TV, p]
                    w[W_TAB + i, p] = (1 - t) * par[row, p] + t * par[row + 1, p]
    elif changed > 0:
        for p in range(P):
            if w[W_JV, p] >= 0.0:
                _lerp_rows(par, comp + int(w[W_JV, p]), m, w[W_TV, p], w, p)


@numba.njit(error_model="numpy", inline="always")
def generalized_bouc_wen_lanes(d, z, par, f, zd, w, fresh, read):  # pragma: no cover - compiled
    """``generalized_bouc_wen_law`` over the batch (every row has the same table size m; scratch w of N_SCRATCH
    rows). One node (m = 1): no look-up; more: the cell of u in the nodes found once for the fourteen tables, and
    only when u changed, in a pass of its own before the Bouc-Wen pass (``_tables_at``; interleaved, the look-up's
    branches kept the whole loop scalar: 1.3x slower on the sawtooth with lag, benchmarks/bench_damper.py)."""
    q = P0
    m = int(par[q, 0])
    comp = q + 1 + m
    reb = comp + 7 * m
    if fresh:
        _switches(d, par, w)
    _controls(d, z, par, zd, w, 2)
    if m == 1:
        for p in range(f.shape[0]):
            xb, vb, s = d[0, p], d[1, p], w[W_S, p]
            force, ydot, zdot = _bouc_wen(
                xb, vb, z[0, p], z[1, p], _blend1(par, comp, reb, 0, s, p), _blend1(par, comp, reb, 1, s, p),
                _blend1(par, comp, reb, 2, s, p), _blend1(par, comp, reb, 3, s, p), _blend1(par, comp, reb, 4, s, p),
                _blend1(par, comp, reb, 5, s, p), _blend1(par, comp, reb, 6, s, p),
            )  # fmt: skip
            zd[0, p] = ydot
            zd[1, p] = zdot
            f[p] = force + par[0, p] * (xb - par[1, p])
        return
    _tables_at(par, w, q + 1, m, f.shape[0])
    for p in range(f.shape[0]):  # then Bouc-Wen over the batch: straight-line arithmetic, SIMD over the candidates
        xb, vb, s = d[0, p], d[1, p], w[W_S, p]
        force, ydot, zdot = _bouc_wen(
            xb, vb, z[0, p], z[1, p], _blend_at(w, 0, s, p), _blend_at(w, 1, s, p), _blend_at(w, 2, s, p),
            _blend_at(w, 3, s, p), _blend_at(w, 4, s, p), _blend_at(w, 5, s, p), _blend_at(w, 6, s, p),
        )  # fmt: skip
        zd[0, p] = ydot
        zd[1, p] = zdot
        f[p] = force + par[0, p] * (xb - par[1, p])


@numba.njit(error_model="numpy", inline="always")
def force_map_lanes(d, z, par, f, zd, w, fresh, read):  # pragma: no cover - compiled
    """``force_map_law`` over the batch (every row has the same nv x nu table; scratch w of N_SCRATCH rows). At RK4's
    stages (not `read`) only the lag's rate: the map is looked up once per step, for the output (1.56-1.76x,
    benchmarks/bench_damper_against.py): the velocity's interval, then the cell of u once for the interval's two
    rows (only when u changed: its fraction from the intervals' reciprocals, ``_reciprocals``, not a division)."""
    q = P0
    nv, nu = int(par[q, 0]), int(par[q + 1, 0])
    vn, un, F = q + 2, q + 2 + nv, q + 2 + nv + nu
    if fresh:  # what depends on the motion alone
        _switches(d, par, w)
    _controls(d, z, par, zd, w, 0)
    if not read:  # an RK4 stage: only the lag's rate is used, the force is not
        return
    _velocity_cells(d, par, vn, nv, w)
    kept = _reciprocals(par, un, nu, w)
    for p in range(f.shape[0]):
        if w[W_U, p] != w[W_AT, p]:  # the cell of a new u (a held command, a settled lag: the same)
            w[W_TAB, p], w[W_TAB + 1, p] = _cell(par, un, nu, w[W_U, p], p, w, kept)
            w[W_AT, p] = w[W_U, p]
        j, t, ju, tu = int(w[W_JV, p]), w[W_TV, p], int(w[W_TAB, p]), w[W_TAB + 1, p]
        lo = _at(par, F + j * nu, ju, tu, p)
        hi = _at(par, F + (j + 1) * nu, ju, tu, p)
        f[p] = (1 - t) * lo + t * hi + par[0, p] * (d[0, p] - par[1, p])


# ------------------------------------------------------------------------------------------ model catalogue


@dataclass(frozen=True)
class DamperModel:
    """A damper model: its force law (per candidate, the reference path, and over a batch: ``lanes``), its
    parameter names (after the front end) and internal states."""

    name: str
    law: object  # numba dispatcher: law(d, dd, z, params, f_out, zd_out), one candidate
    lanes: object  # numba dispatcher: lanes(d, z, par, f, zd, w, fresh, read), the same law over a batch (inlined)
    parameters: tuple[str, ...]
    n_states: int  # internal states: Bouc-Wen's y and z first, then u_f when the model has a control input
    uses_control: bool
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)  # physical limits

    @property
    def scratch(self) -> int:
        """Rows of scratch its batch law keeps from call to call (the control models' caches)."""
        return N_SCRATCH if self.uses_control else 0

    def layout(self, table_shape: tuple[int, ...] = ()) -> tuple[str, ...]:
        """All parameter names of a row: the front end, then the model's own (tables expanded)."""
        return FRONT + DELAYS + self.expand(table_shape)

    @staticmethod
    def unit(name: str) -> str:
        """The SI unit of a parameter of a row (UNITS; a table entry's is its base name's), '' when unknown."""
        if name in UNITS:
            return UNITS[name]
        base = name.rstrip("0123456789_")  # c0_comp_2 -> c0_comp, u_node_3 -> u_node, F_2_3 -> F
        for side in ("_comp", "_reb"):
            base = base.removesuffix(side)
        return UNITS.get(base, "")

    def expand(self, table_shape: tuple[int, ...]) -> tuple[str, ...]:
        if self.name == "generalized_bouc_wen":
            (m,) = table_shape or (1,)
            names = ["m"] + [f"u_node_{j + 1}" for j in range(m)]
            for side in ("comp", "reb"):
                names += [f"{p}_{side}" + (f"_{j + 1}" if m > 1 else "") for p in BW_SET for j in range(m)]
            return tuple(names)
        if self.name == "force_map":
            nv, nu = table_shape
            names = ["nv", "nu"] + [f"v_node_{i + 1}" for i in range(nv)] + [f"u_node_{j + 1}" for j in range(nu)]
            return tuple(names + [f"F_{i + 1}_{j + 1}" for i in range(nv) for j in range(nu)])
        return self.parameters


MODELS = {
    m.name: m
    for m in (
        DamperModel("gas_spring", gas_spring_law, gas_spring_lanes, (), 0, False),
        DamperModel("viscous", viscous_law, viscous_lanes, ("c0",), 0, False, {"c0": (0.0, np.inf)}),
        DamperModel(
            "bingham",
            bingham_law,
            bingham_lanes,
            ("c0", "fc", "v_eps"),
            0,
            False,
            {"c0": (0.0, np.inf), "fc": (0.0, np.inf), "v_eps": (1e-6, np.inf)},
        ),
        DamperModel(
            "bouc_wen",
            bouc_wen_law,
            bouc_wen_lanes,
            BW_SET,
            2,
            False,
            {"c0": (0.0, np.inf), "k0": (0.0, np.inf), "c1": (1e-9, np.inf), "delta": (0.0, np.inf)},
        ),
        DamperModel(
            "generalized_bouc_wen", generalized_bouc_wen_law, generalized_bouc_wen_lanes, (), 2 + CONTROL_STATE, True
        ),
        DamperModel("force_map", force_map_law, force_map_lanes, (), CONTROL_STATE, True),
    )  # fmt: skip
}


def default_values(model: str, table_shape: tuple[int, ...] = ()) -> dict[str, float]:
    """Neutral starting values: no gas, no backlash, no lag or delay, mid-range damper parameters."""
    values = {n: 0.0 for n in FRONT + DELAYS}
    values["v_switch"] = 0.01
    typical = dict(c0=1000.0, fc=100.0, v_eps=0.01, k0=100.0, c1=10000.0, alpha=500.0, beta=1e5, gamma=1e5, delta=300.0)
    for name in MODELS[model].layout(table_shape)[len(values) :]:
        base = name.split("_")[0] if name.split("_")[0] in typical else name
        values[name] = typical.get(base, 0.0)
    if model == "generalized_bouc_wen":
        (m,) = table_shape or (1,)
        values["m"] = m
        for j in range(m):
            values[f"u_node_{j + 1}"] = j / max(m - 1, 1)
    if model == "force_map":  # the table size, evenly spread nodes, a flat (zero) map
        nv, nu = table_shape
        values.update(nv=nv, nu=nu)
        values.update({f"v_node_{i + 1}": v for i, v in enumerate(np.linspace(-0.5, 0.5, nv))})
        values.update({f"u_node_{j + 1}": u for j, u in enumerate(np.linspace(0.0, 1.0, nu))})
    return values
