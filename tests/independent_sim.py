"""An independent 7-DOF full-car simulator for tests: a second implementation, imports nothing from vehid_cli.

Equations from Newton's laws per body (SPEC section 1 conventions), integrated by scipy's solve_ivp on the
continuous road, piecewise between the bump's kinks. Responses are measured from static equilibrium.

q = [x, phi, theta, x1, x2, x3, x4]: bounce [m] (up +), roll [rad], pitch [rad], wheel hops [m] (up +).
Corners: 1 front/b1, 2 front/b2, 3 rear/b2, 4 rear/b1. Body point z_i = x + s_i phi + p_i theta with
s = (b1, -b2, -b2, b1), p = (-a1, -a1, a2, a2). Strut i: deflection d_i = z_i - x_i (+ = rebound), velocity
v_i; strut force F_i (+ pulls the body down and the wheel up) = ks d + cs v + extra effects. Tyre force
T_i = kt (x_i - y_i) + ct (dx_i - dy_i) (+ pushes the wheel down). Anti-roll bar: energy kR/2 r^2 with
r = phi - (x1 - x2)/w, w = b1 + b2. Newton (the mass matrix is diagonal in these coordinates):

    m  xdd   = -sum F_i
    Ix phidd = -sum s_i F_i - kR r
    Iy thdd  = -sum p_i F_i
    m_i xidd = F_i - T_i + kR r (+1/w for wheel 1, -1/w for wheel 2)

Command line: ``python tests/independent_sim.py -o run.csv --set kf=54000 --effect hysteresis:alpha_f=3e4
--noise 0.05 --seed 1``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Mapping

import numpy as np
from scipy.integrate import solve_ivp

PAPER_CAR: dict[str, float] = dict(
    m=1300.0, mf=40.0, mr=65.0, Ix=500.0, Iy=2500.0, a1=1.3, a2=1.3, b1=0.75, b2=0.75,
    kf=45000.0, kr=80000.0, ktf=200000.0, ktr=200000.0, kR=50000.0, cf=2800.0, cr=3500.0,
)  # fmt: skip

# Every effect's parameters with defaults that make it clearly present (override any of them).
EFFECT_DEFAULTS: dict[str, dict[str, float]] = {
    "hysteresis": dict(alpha_f=3e4, alpha_r=3e4, beta=1e4, gamma=1e4, A=1.0),  # N/m, 1/m^2, 1/m^2, -
    "tyre_damping": dict(ct_f=300.0, ct_r=300.0),  # N s/m
    "coulomb_friction": dict(Fc_f=150.0, Fc_r=150.0, v_eps=0.01),  # N, N, m/s
    "asymmetric_damping": dict(dc_f=2000.0, dc_r=2500.0, v_eps=0.02),  # N s/m, N s/m, m/s
    "progressive_spring": dict(k3_f=1e7, k3_r=1e7),  # N/m^3
    "gas_spring": dict(F0_f=2000.0, F0_r=2000.0, L=0.1, kappa=1.4),  # N, N, m, -
    "damper_lag": dict(T_f=0.01, T_r=0.01),  # s
    "sqrt_damper": dict(c_sqrt_f=500.0, c_sqrt_r=600.0),  # N / (m/s)^0.5
    "bump_stop": dict(k_stop_f=2e5, k_stop_r=2e5, gap_f=0.02, gap_r=0.02, compression_only=0.0),  # N/m, m, flag
}
EFFECTS = tuple(EFFECT_DEFAULTS)
# Laws outside vehid's effect library (issue 25's held-back kinds), accepted like effects but not in EFFECTS.
OUTSIDE_LIBRARY: dict[str, dict[str, float]] = {
    "quadratic_damper": dict(c2_f=1500.0, c2_r=2000.0),  # N s^2/m^2: c2 |v| v
    "digressive_damper": dict(v_knee=0.1, share=0.4),  # m/s, -: above the knee the damping falls to share * c
    "stribeck_friction": dict(Fc=60.0, Fs=200.0, v_s=0.03, v_eps=0.005),  # N, N, m/s, m/s
    "progressive_tyre": dict(k3t_f=3e7, k3t_r=3e7),  # N/m^3: the tyre force gains k3t (x - y)^3
}
BUMP_LENGTH = 0.1  # m
DEFAULT_HEIGHTS = (0.05, 0.04, 0.04, 0.05)  # m, corners 1..4
FRONT = np.array([True, True, False, False])  # corners 1, 2 front; 3, 4 rear


def per_corner(front: float, rear: float) -> np.ndarray:
    """A (4, 1) column of per-corner values from front/rear axle values."""
    return np.where(FRONT, float(front), float(rear))[:, None]


def effect_params(effects: Mapping[str, Mapping[str, float] | None] | None) -> dict[str, dict[str, float]]:
    """Complete each named effect's parameters with the defaults; refuses unknown effects and parameters."""
    out: dict[str, dict[str, float]] = {}
    laws = {**EFFECT_DEFAULTS, **OUTSIDE_LIBRARY}
    for name, given in (effects or {}).items():
        if name not in laws:
            raise ValueError(f"unknown effect {name!r}; known: {', '.join(laws)}")
        p = dict(laws[name])
        for key, value in (given or {}).items():
            if key not in p:
                raise ValueError(f"unknown parameter {key!r} of effect {name!r}; known: {', '.join(p)}")
            p[key] = float(value)
        out[name] = p
    return out


def bouc_wen_rate(zeta, v, A: float, beta: float, gamma: float):
    """Bouc-Wen (n = 2) state rate dzeta/dt [m/s] = A v - beta v zeta^2 - gamma |v| zeta |zeta|."""
    return A * v - beta * v * zeta**2 - gamma * np.abs(v) * zeta * np.abs(zeta)


def extra_strut_force(d, v, eff: dict[str, dict[str, float]], zeta=None):
    """Extra strut force [N] (+ resists extension) of the memoryless effects plus hysteresis alpha zeta, at
    deflection d [m] and velocity v [m/s] of shape (4, k). Damper lag is handled by the caller."""
    f = np.zeros(np.broadcast(d, v).shape)
    if "hysteresis" in eff:
        p = eff["hysteresis"]
        f = f + per_corner(p["alpha_f"], p["alpha_r"]) * zeta
    if "coulomb_friction" in eff:
        p = eff["coulomb_friction"]
        f = f + per_corner(p["Fc_f"], p["Fc_r"]) * np.tanh(v / p["v_eps"])
    if "asymmetric_damping" in eff:
        p = eff["asymmetric_damping"]
        f = f + 0.5 * per_corner(p["dc_f"], p["dc_r"]) * np.tanh(v / p["v_eps"]) * v
    if "progressive_spring" in eff:
        p = eff["progressive_spring"]
        f = f + per_corner(p["k3_f"], p["k3_r"]) * d**3
    if "gas_spring" in eff:
        p = eff["gas_spring"]
        F0, L, kappa = per_corner(p["F0_f"], p["F0_r"]), p["L"], p["kappa"]
        with np.errstate(invalid="ignore", divide="ignore"):
            f = f + F0 * (1.0 - (1.0 + d / L) ** -kappa) - F0 * kappa * d / L
    if "sqrt_damper" in eff:
        p = eff["sqrt_damper"]
        f = f + per_corner(p["c_sqrt_f"], p["c_sqrt_r"]) * np.sign(v) * np.sqrt(np.abs(v))
    if "bump_stop" in eff:
        p = eff["bump_stop"]
        k, gap = per_corner(p["k_stop_f"], p["k_stop_r"]), per_corner(p["gap_f"], p["gap_r"])
        engaged = (d < -gap) if p["compression_only"] else (np.abs(d) > gap)
        f = f + np.where(engaged, k * (np.abs(d) - gap) * np.sign(d), 0.0)
    return f + outside_strut_force(d, v, eff)


def outside_strut_force(d, v, eff: dict[str, dict[str, float]], cs=None):
    """Strut force [N] of the laws outside the library at deflection d [m], velocity v [m/s], shapes (4, k); `cs`
    (4, 1) the linear damping [N s/m] a digressive damper loses above its knee (the paper car's by default)."""
    f = np.zeros(np.broadcast(d, v).shape)
    if "quadratic_damper" in eff:
        p = eff["quadratic_damper"]
        f = f + per_corner(p["c2_f"], p["c2_r"]) * np.abs(v) * v
    if "digressive_damper" in eff:  # a blow-off knee: c v below v_knee, slope share * c above it
        p = eff["digressive_damper"]
        c = per_corner(PAPER_CAR["cf"], PAPER_CAR["cr"]) if cs is None else cs
        f = f - (1.0 - p["share"]) * c * np.sign(v) * np.maximum(np.abs(v) - p["v_knee"], 0.0)
    if "stribeck_friction" in eff:  # static friction Fs falling to Coulomb Fc beyond v_s (Gaussian Stribeck curve)
        p = eff["stribeck_friction"]
        level = p["Fc"] + (p["Fs"] - p["Fc"]) * np.exp(-((v / p["v_s"]) ** 2))
        f = f + level * np.tanh(v / p["v_eps"])
    return f


def outside_tyre_force(deflection, eff: dict[str, dict[str, float]]):
    """Tyre force [N] (+ pushes the wheel down) beyond kt (x - y) of a law outside the library, deflection x - y [m]."""
    if "progressive_tyre" not in eff:
        return np.zeros_like(deflection)
    p = eff["progressive_tyre"]
    return per_corner(p["k3t_f"], p["k3t_r"]) * deflection**3


def bump_road(t, heights, speed: float, wheelbase: float, start_time: float, length: float = BUMP_LENGTH):
    """Road height y [m] and its rate dy [m/s], each (4, k), under the tyres at times t [s] (shape (k,))."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    delay = np.where(FRONT, 0.0, wheelbase / speed)[:, None]
    s = speed * (t[None, :] - start_time - delay) / length  # fraction of the ramp travelled
    h = np.asarray(heights, dtype=float)[:, None]
    inside = (s > 0.0) & (s < 1.0)
    y = h * np.where(s >= 1.0, 1.0, np.where(inside, 0.5 * (1.0 - np.cos(np.pi * s)), 0.0))
    dy = h * np.where(inside, 0.5 * np.pi * np.sin(np.pi * s) * speed / length, 0.0)
    return y, dy


class FullCar:
    """The equations of motion of one car with a set of effects; state [q (7), qd (7), zeta (4)?, Fd (4)?]."""

    def __init__(self, params: Mapping[str, float], effects=None, road=None):
        p = dict(PAPER_CAR)
        unknown = set(params) - set(p)
        if unknown:
            raise ValueError(f"unknown vehicle parameters {sorted(unknown)}; known: {', '.join(p)}")
        p.update({k: float(v) for k, v in params.items()})
        self.p = p
        self.eff = effect_params(effects)
        self.road = road if road is not None else (lambda t: (np.zeros((4, np.size(t))),) * 2)
        self.s = np.array([p["b1"], -p["b2"], -p["b2"], p["b1"]])[:, None]  # dz_i / dphi
        self.pp = np.array([-p["a1"], -p["a1"], p["a2"], p["a2"]])[:, None]  # dz_i / dtheta
        self.w = p["b1"] + p["b2"]
        self.ks = per_corner(p["kf"], p["kr"])
        self.cs = per_corner(p["cf"], p["cr"])
        self.kt = per_corner(p["ktf"], p["ktr"])
        self.mw = per_corner(p["mf"], p["mr"])
        ct = self.eff.get("tyre_damping")
        self.ct = per_corner(ct["ct_f"], ct["ct_r"]) if ct else np.zeros((4, 1))
        lag = self.eff.get("damper_lag")
        self.T = per_corner(lag["T_f"], lag["T_r"]) if lag else np.zeros((4, 1))
        self.n_zeta = 4 if "hysteresis" in self.eff else 0
        self.n_lag = 4 if lag else 0
        self.n_state = 14 + self.n_zeta + self.n_lag

    def body_points(self, q):
        """Body-point heights z_i (4, k) [m] from q (7, k)."""
        return q[0:1] + self.s * q[1:2] + self.pp * q[2:3]

    def evaluate(self, t, y):
        """Everything at times t (k,) and states y (n_state, k): state rate, d, v, extra force, road."""
        y = np.asarray(y, dtype=float).reshape(self.n_state, -1)
        q, qd = y[0:7], y[7:14]
        zeta = y[14 : 14 + self.n_zeta] if self.n_zeta else None
        Fd = y[14 + self.n_zeta :] if self.n_lag else None
        yr, dyr = self.road(t)
        xw, vw = q[3:7], qd[3:7]
        d = self.body_points(q) - xw
        v = self.body_points(qd) - vw
        extra = extra_strut_force(d, v, self.eff, zeta)
        lagged = self.T > 0
        damper = self.cs * v
        if Fd is not None:
            damper = np.where(lagged, Fd, damper)
        extra = extra + damper - self.cs * v  # everything beyond ks d + cs v
        F = self.ks * d + self.cs * v + extra
        Ft = self.kt * (xw - yr) + self.ct * (vw - dyr) + outside_tyre_force(xw - yr, self.eff)
        r = q[1] - (q[3] - q[4]) / self.w  # anti-roll bar twist
        P = self.p
        acc = np.empty_like(q)
        acc[0] = -F.sum(axis=0) / P["m"]
        acc[1] = (-(self.s * F).sum(axis=0) - P["kR"] * r) / P["Ix"]
        acc[2] = -(self.pp * F).sum(axis=0) / P["Iy"]
        wheel = F - Ft
        wheel[0] += P["kR"] * r / self.w
        wheel[1] -= P["kR"] * r / self.w
        acc[3:7] = wheel / self.mw
        rates = [qd, acc]
        if zeta is not None:
            h = self.eff["hysteresis"]
            rates.append(bouc_wen_rate(zeta, v, h["A"], h["beta"], h["gamma"]))
        if Fd is not None:
            rates.append(np.where(lagged, (self.cs * v - Fd) / np.where(lagged, self.T, 1.0), 0.0))
        return dict(rate=np.concatenate(rates), d=d, v=v, extra=extra, road=yr, road_vel=dyr, tyre=Ft)

    def rhs(self, t, y):
        """State rate for solve_ivp (y of shape (n_state,) or (n_state, k))."""
        out = self.evaluate(np.atleast_1d(t), y)["rate"]
        return out.reshape(np.shape(y))

    def energy(self, q, qd, road_y):
        """Total mechanical energy [J] (kinetic + springs + tyres + anti-roll bar), q, qd (7, k), road (4, k)."""
        P = self.p
        kin = 0.5 * (P["m"] * qd[0] ** 2 + P["Ix"] * qd[1] ** 2 + P["Iy"] * qd[2] ** 2)
        kin = kin + 0.5 * (self.mw * qd[3:7] ** 2).sum(axis=0)
        d = self.body_points(q) - q[3:7]
        pot = 0.5 * (self.ks * d**2).sum(axis=0) + 0.5 * (self.kt * (q[3:7] - road_y) ** 2).sum(axis=0)
        pot = pot + 0.5 * P["kR"] * (q[1] - (q[3] - q[4]) / self.w) ** 2
        return kin + pot


def time_grid(duration: float, dt: float) -> np.ndarray:
    """floor(duration / dt) samples 0, dt, ... [s] (3 s at 1 ms: 3000 samples)."""
    return np.arange(int(np.floor(duration / dt + 1e-9))) * dt


def simulate(
    params: Mapping[str, float] | None = None,
    effects: Mapping[str, Mapping[str, float] | None] | None = None,
    *,
    heights=DEFAULT_HEIGHTS,
    speed_kmh: float = 20.0,
    duration: float = 3.0,
    dt: float = 1e-3,
    start_time: float = 0.1,
    bump_length: float = BUMP_LENGTH,
    method: str = "LSODA",
    rtol: float = 1e-8,
    atol: float = 1e-11,
    max_step: float = 2e-3,
) -> dict:
    """Bump run from rest at equilibrium. params: vehicle values (missing ones from PAPER_CAR); effects:
    {name: {param: value}} (missing ones from EFFECT_DEFAULTS). Returns t (n,) [s], road (n, 4) [m], road_vel,
    acc (n, 4) [m/s^2] and disp (n, 4) [m] at body points z1..z4, d, v (n, 4) strut deflection [m] / velocity
    [m/s], extra (n, 4) strut force beyond ks d + cs v [N], tyre (n, 4) tyre force [N], q, qd (n, 7), state."""
    speed = speed_kmh / 3.6
    p = dict(PAPER_CAR)
    p.update(params or {})
    wheelbase = p["a1"] + p["a2"]

    def road(t):
        return bump_road(t, heights, speed, wheelbase, start_time, bump_length)

    car = FullCar(params or {}, effects, road)
    ramp = bump_length / speed
    kinks = [start_time, start_time + ramp, start_time + wheelbase / speed, start_time + wheelbase / speed + ramp]
    return run(car, time_grid(duration, dt), kinks, method=method, rtol=rtol, atol=atol, max_step=max_step)


def run(
    car: FullCar,
    t: np.ndarray,
    kinks=(),
    method: str = "LSODA",
    rtol: float = 1e-8,
    atol: float = 1e-11,
    max_step: float = 2e-3,
) -> dict:
    """Integrate `car` from rest on the grid t [s], restarting at the road's kinks [s]; the dict of simulate."""
    edges = [t[0]] + sorted(k for k in set(kinks) if t[0] < k < t[-1]) + [t[-1]]
    y0 = np.zeros(car.n_state)
    Y = np.empty((car.n_state, t.size))
    for i, (ta, tb) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
        last = i == len(edges) - 2
        mask = (t >= ta) & ((t <= tb) if last else (t < tb))
        t_eval = t[mask] if last else np.append(t[mask], tb)
        sol = solve_ivp(car.rhs, (ta, tb), y0, method=method, t_eval=t_eval, rtol=rtol, atol=atol, max_step=max_step)
        if not sol.success:
            raise RuntimeError(f"integration failed at t = {ta:g}..{tb:g} s: {sol.message}")
        Y[:, mask] = sol.y[:, : mask.sum()]
        y0 = sol.y[:, -1]
    ev = car.evaluate(t, Y)
    rate = ev["rate"]
    q, qd = Y[:7], Y[7:14]
    return dict(
        t=t,
        road=ev["road"].T,
        road_vel=ev["road_vel"].T,
        acc=car.body_points(rate[7:14]).T,
        disp=car.body_points(q).T,
        d=ev["d"].T,
        v=ev["v"].T,
        extra=ev["extra"].T,
        tyre=ev["tyre"].T,
        q=q.T,
        qd=qd.T,
        state=Y.T,
        energy=car.energy(q, qd, ev["road"]),
    )


def add_noise(sim: Mapping, noise_level: float, seed) -> tuple[np.ndarray, np.ndarray]:
    """acc, disp (n, 4) with Eq. 15 noise: per channel sigma = Np std(clean channel), one Generator(seed)."""
    clean = np.hstack([sim["acc"], sim["disp"]])
    rng = np.random.default_rng(seed)
    noisy = clean + noise_level * clean.std(axis=0)[None, :] * rng.standard_normal(clean.shape)
    return noisy[:, :4], noisy[:, 4:]


def write_run(path, sim: Mapping, noise_level: float = 0.0, seed=None, comments=()) -> None:
    """Write the SPEC vehicle measurement CSV (t, road1..4, acc1..4, disp1..4); road columns noise-free."""
    acc, disp = add_noise(sim, noise_level, seed)
    table = np.column_stack([sim["t"], sim["road"], acc, disp])
    header = ["t"] + [f"{name}{i}" for name in ("road", "acc", "disp") for i in range(1, 5)]
    with open(path, "w", encoding="utf-8") as fh:
        for line in comments:
            fh.write(f"# {line}\n")
        fh.write(",".join(header) + "\n")
        for row in table:
            fh.write(",".join(f"{x:.12g}" for x in row) + "\n")


def _key_values(text: str) -> dict[str, float]:
    out = {}
    for item in filter(None, text.split(",")):
        key, sep, value = item.partition("=")
        if not sep:
            raise argparse.ArgumentTypeError(f"expected key=value, got {item!r}")
        out[key.strip()] = float(value)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Independent full-car bump simulator (test data by hand).")
    ap.add_argument("-o", "--output", required=True, help="CSV file to write")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="vehicle parameter")
    ap.add_argument("--effect", action="append", default=[], metavar="NAME[:k=v,...]", help="add an effect")
    ap.add_argument("--heights", default=",".join(map(str, DEFAULT_HEIGHTS)), help="bump heights, corners 1..4 [m]")
    ap.add_argument("--speed-kmh", type=float, default=20.0)
    ap.add_argument("--duration", type=float, default=3.0)
    ap.add_argument("--dt", type=float, default=1e-3)
    ap.add_argument("--start-time", type=float, default=0.1)
    ap.add_argument("--noise", type=float, default=0.0, help="Np of Eq. 15 (0.05 = 5 %%)")
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--describe", action="store_true", help="write the parameters and effects as # comments")
    args = ap.parse_args(argv)
    params = {}
    for item in args.set:
        params.update(_key_values(item))
    effects = {}
    for item in args.effect:
        name, _, rest = item.partition(":")
        effects[name.strip()] = _key_values(rest)
    heights = [float(h) for h in args.heights.split(",")]
    if len(heights) != 4:
        ap.error("--heights needs four values")
    sim = simulate(
        params, effects, heights=heights, speed_kmh=args.speed_kmh, duration=args.duration, dt=args.dt,
        start_time=args.start_time,
    )  # fmt: skip
    comments = []
    if args.describe:
        comments = [f"vehicle {params}", f"effects {effect_params(effects)}", f"noise {args.noise} seed {args.seed}"]
    write_run(args.output, sim, args.noise, args.seed, comments)
    return 0


if __name__ == "__main__":
    sys.exit(main())
