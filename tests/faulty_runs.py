"""Logger runs of a car that is not the config's, made by the independent simulator (tests/independent_sim.py: Newton
per body through scipy's LSODA, no vehid code), with one fault of the measurement chain injected as a real chain
would make it (issue 21): a sensor upside down, a unit slip, two connectors swapped, a delayed channel, a saturating
sensor, held samples, a drifting bias. Written as MDF4 or CSV in g and mm under the logger's own names, with gravity
and zero offsets, 200 Hz potentiometers."""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np

from tests import independent_sim as ind

G = 9.80665
TRUTH = {"m": 1380.0, "Ix": 520.0, "Iy": 2400.0, "a1": 1.34, "b1": 0.73}  # 3-8 % off the config's
UNKNOWNS = tuple(TRUTH)
LAYOUT = (
    "[{name: a, kind: body_acc, origin: corner1, x: -0.15, y: -0.10},"
    " {name: b, kind: body_acc, origin: corner3, x: 0.15, y: 0.10},"
    " {name: c, kind: body_acc, origin: front_axle, x: -0.3, y: 0},"
    " {name: e, kind: body_acc, origin: corner2, x: -0.2, y: 0.1},"
    " {name: h1, kind: wheel_acc, corner: 1}, {name: h3, kind: wheel_acc, corner: 3},"
    " {name: d1, kind: deflection, corner: 1}, {name: d3, kind: deflection, corner: 3}]"
)
NAMES = {"a": "ACC_A", "b": "ACC_B", "c": "ACC_C", "e": "ACC_E", "h1": "HUB1", "h3": "HUB3", "d1": "POT1", "d3": "POT3"}
NAMES.update({f"road{i}": f"ACT{i}" for i in range(1, 5)})
UNITS = {k: ("g" if k[0] in "abceh" else "mm") for k in NAMES}
SIGMA = {"acc": 0.05, "disp": 1e-4}
FAULTS = ("clean", "sign", "gain", "swap", "delay", "clip", "dropout", "drift")
TRIGGER = 0.03  # [s] the road's clock ahead of the responses' in the "trigger" run


def config_sets(offsets: str = "identify") -> list[str]:
    """--set lines that make the four-post rig config read these runs."""
    return [
        f"layout={LAYOUT}", "data.channels=" + json.dumps(NAMES), "data.units=" + json.dumps(UNITS),
        f"noise.sigma.acc={SIGMA['acc']}", f"noise.sigma.disp={SIGMA['disp']}", "simulation.duration=3",
        f"identify.unknowns=[{','.join(UNKNOWNS)}]", "identify.start=config", f"data.offsets={offsets}",
    ]  # fmt: skip


@lru_cache(maxsize=2)
def _motion(seed: int = 77):
    """The independent car over unequal bumps: its coordinates, accelerations and road on a 1 kHz grid."""
    p = {**ind.PAPER_CAR, **TRUTH, "a2": 2.6 - TRUTH["a1"], "b2": 1.5 - TRUTH["b1"]}
    heights, speed, start, length = (0.05, 0.03, 0.03, 0.05), 20 / 3.6, 0.1, ind.BUMP_LENGTH
    car = ind.FullCar(p, None, lambda t: ind.bump_road(t, heights, speed, 2.6, start, length))
    ramp = length / speed
    kinks = [start, start + ramp, start + 2.6 / speed, start + 2.6 / speed + ramp]
    sim = ind.run(car, ind.time_grid(3.0, 1e-3), kinks)
    qdd = car.evaluate(sim["t"], sim["state"].T)["rate"][7:14].T
    return p, sim, qdd


def channels(seed: int = 77) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every channel as the logger records it (name in the file -> (t [s], value in g or mm)), no fault."""
    p, sim, qdd = _motion()
    q, t = sim["q"], sim["t"]
    rng = np.random.default_rng(seed)

    def body(qq, x, y):  # vertical motion of the body point (x forward, y toward side 1) from the CG
        return qq[:, 0] + y * qq[:, 1] - x * qq[:, 2]

    points = {"ACC_A": (p["a1"] - 0.15, p["b1"] - 0.10), "ACC_B": (-p["a2"] + 0.15, -p["b2"] + 0.10),
              "ACC_C": (p["a1"] - 0.3, (p["b1"] - p["b2"]) / 2), "ACC_E": (p["a1"] - 0.2, -p["b2"] + 0.1)}  # fmt: skip
    out = {}
    for name, (x, y) in points.items():
        out[name] = (t, (body(qdd, x, y) + SIGMA["acc"] * rng.standard_normal(t.size)) / G + 1.0)
    for c in (1, 3):
        out[f"HUB{c}"] = (t, (qdd[:, 2 + c] + SIGMA["acc"] * rng.standard_normal(t.size)) / G + 1.0)
        cx, cy = {1: (p["a1"], p["b1"]), 3: (-p["a2"], -p["b2"])}[c]
        defl = body(q, cx, cy) - q[:, 2 + c] + SIGMA["disp"] * rng.standard_normal(t.size)
        out[f"POT{c}"] = (t[::5], 1e3 * defl[::5] + 3.0)  # 200 Hz, mm, a zero offset of 3 mm
    for i in range(4):
        out[f"ACT{i + 1}"] = (t, 1e3 * sim["road"][:, i])
    return out


def inject(chans: dict, fault: str) -> tuple[dict, str, str]:
    """The channels with `fault` injected; the layout channel it is on and the fault name a diagnosis should give
    (``swap:<other>`` for a swap)."""
    out = dict(chans)
    t, y = out["ACC_A"]
    if fault == "clean":
        return out, "", ""
    if fault == "sign":  # accelerometer a mounted upside down: -1 g at rest
        out["ACC_A"] = (t, -y)
        return out, "a", "sign"
    if fault == "gain":  # pot d1 recorded in cm while the config says mm
        td, yd = out["POT1"]
        out["POT1"] = (td, yd / 10.0)
        return out, "d1", "gain"
    if fault == "swap":  # the connectors of a and b swapped
        out["ACC_A"], out["ACC_B"] = (t, out["ACC_B"][1]), (t, y)
        return out, "a", "swap:b"
    if fault == "delay":  # wheel accelerometer h1 on a clock 25 ms late (its first 25 ms: the car at rest, noise)
        th, yh = out["HUB1"]
        out["HUB1"] = (th, np.r_[yh[25:50], yh[:-25]])
        return out, "h1", "delay"
    if fault == "clip":  # accelerometer c saturating at +-0.25 g around gravity
        tc, yc = out["ACC_C"]
        out["ACC_C"] = (tc, np.clip(yc, 1.0 - 0.25, 1.0 + 0.25))
        return out, "c", "clip"
    if fault == "dropout":  # pot d3's logger holds its last value for 6 samples every 40
        td, yd = out["POT3"]
        yd = yd.copy()
        for start in range(10, yd.size - 6, 40):
            yd[start : start + 6] = yd[start - 1]
        out["POT3"] = (td, yd)
        return out, "d3", "dropout"
    if fault == "drift":  # pot d1's zero creeps 4 mm over the run
        td, yd = out["POT1"]
        out["POT1"] = (td, yd + 4.0 * td / td[-1])
        return out, "d1", "drift"
    if fault == "trigger":  # the rig's actuators logged on a clock 30 ms ahead: every response lags the road
        k = int(round(TRIGGER / 1e-3))
        for i in range(1, 5):
            ta, ya = out[f"ACT{i}"]
            out[f"ACT{i}"] = (ta, np.r_[ya[k:], np.full(k, ya[-1])])
        return out, "road", "trigger"
    raise ValueError(fault)


def write(path: Path, fault: str, seed: int = 77) -> tuple[Path, str, str]:
    """A run with `fault` written to `path` (.mf4 or .csv); the channel and fault name a diagnosis should give."""
    from vehid_cli.io.write import write_record

    chans, channel, name = inject(channels(seed), fault)
    if Path(path).suffix == ".csv":
        write_multirate_csv(Path(path), chans)
    else:
        write_record(path, chans)
    return Path(path), channel, name


def write_multirate_csv(path: Path, chans: dict) -> None:
    """A logger's CSV export: one time column at the fastest rate, a slower channel's cells empty between its
    samples, each column's unit in its header (`ACC_A [g]`)."""
    t = chans["ACC_A"][0]
    cols = ["t"]
    table = np.full((t.size, len(chans) + 1), "", dtype=object)
    table[:, 0] = [repr(float(v)) for v in t]
    for j, (name, (tk, yk)) in enumerate(chans.items(), start=1):
        cols.append(f"{name} [{'g' if name.startswith(('ACC', 'HUB')) else 'mm'}]")
        rows = np.searchsorted(t, tk - 1e-9)
        table[rows, j] = [repr(float(v)) for v in yk]
    path.write_text(",".join(cols) + "\n" + "".join(",".join(r) + "\n" for r in table))
