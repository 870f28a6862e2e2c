"""The effect library on a linear rig's struts: the rig simulated with effects through the compiled kernel (RK4), and
the effects' car forms as the rig's diagnosis candidates.

A rig names its struts as the car's corners (`LumpedSystem.struts`: the suspension between a body point and a wheel
at corner slots 0..3, the front ones 0, 1 and the rear 2, 3, so that an effect's per-axle parameters ``_f`` and
``_r`` act on the rig's front and rear struts; a quarter car has one strut, the front one). The tyre's damping of
the linear model (the quarter car's ct) leaves the linear damping and becomes the kernel's tyre strut (the
``tyre_damping`` effect, whose velocity is the wheel's over the road's: the hold's slope, as on the exact path).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from ..diagnose.attribution import Candidate, effect_candidate
from ..models.effects import LIBRARY, CarScale, effect_rows
from ..sim.kernel import integrate
from ..sim.nonlinear import upsample

SLOTS = 4  # the car's corner slots the effect laws index
SUBSTEPS = 4  # RK4 steps per sample: a friction's sharp reversal within the noise at a lab rig's few hundred Hz


def rig_effect_values(values: Mapping[str, NDArray], tyre_ct: NDArray | None) -> dict[str, dict[str, NDArray]]:
    """Effect name -> {per-axle parameter: (P,)} from the dotted unknowns ``effect.param``, with the rig's linear
    tyre damping (tyre_ct (P, 4) per corner slot) as the tyre_damping effect."""
    out: dict[str, dict[str, NDArray]] = {}
    for key, v in values.items():
        effect, _, name = key.partition(".")
        out.setdefault(effect, {})[name] = v
    if tyre_ct is not None:
        tyre = out.setdefault("tyre_damping", {})
        tyre.setdefault("ct_f", tyre_ct[:, 0])
        tyre.setdefault("ct_r", tyre_ct[:, 2])
    return out


def kernel_outputs(system, p: dict[str, NDArray], effects: Mapping[str, NDArray], run: int) -> tuple[NDArray, ...]:
    """Displacement and acceleration channels (P, n, kd), (P, n, ka) of the rig with the effects `effects` (dotted
    ``effect.param`` -> (P,)) on run `run`, by RK4 on the kernel."""
    M, C, K, B0, _ = system.matrices(p)
    Sq, Sa = system.sensor_rows(p)
    D, T, ET, ct = system.struts(p)  # suspension rows (P, 4, d), tyre rows (P, 4, d), tyre inputs (4, nu), ct (P, 4)
    P = M.shape[0]
    if ct is not None:  # the linear tyre damping leaves C for the tyre struts
        C = C - np.einsum("ps,psi,psj->pij", ct, T, T)
    damping = system.strut_damping(p)  # (P, 2): the front and rear linear damping (backlash and lag act on it)
    es = effect_rows(rig_effect_values(effects, ct), damping[:, 0], damping[:, 1], (P,))
    E = np.zeros((SLOTS, B0.shape[-1]))
    if es.tyres:
        D = np.concatenate([D, T], axis=1)
        E = np.concatenate([E, ET], axis=0)
    rig = system.rigs[run]
    k = SUBSTEPS
    res = integrate("rk4", M, C, K, B0, upsample(rig.u, k), rig.dt / k, es.law, es.rows, es.n_z, D=D, E=E)
    disp = res.q[:, ::k] @ np.swapaxes(Sq, -1, -2)
    acc = res.qdd[:, ::k] @ np.swapaxes(Sa, -1, -2)
    return disp, acc


def rig_candidates(system) -> dict[str, Candidate]:
    """Each registered effect's car form on the rig's struts: the damping ranges from the rig's own, the per-axle
    unknowns of axles the rig lacks dropped, companions renamed to the rig's parameters."""
    damping = system.strut_damping(system.parameters(system.box.nominal[None, :]))[0]
    axles = system.axles  # e.g. ("f",) for a quarter car
    scale = CarScale(float(damping[0]), float(damping[1]), min(r.dt for r in system.rigs) / SUBSTEPS)
    out = {}
    for name, e in LIBRARY.items():
        if e.car_candidate is None or name in system.excluded_effects:
            continue
        c = effect_candidate(name, e.car_candidate(scale))

        def keep(n: str) -> bool:
            tail = n.rsplit("_", 1)
            return not (len(tail) == 2 and tail[1] in ("f", "r") and tail[1] not in axles)

        companions = tuple(system.companion_names.get(n, n) for n in c.companions)
        companions = tuple(n for n in companions if n in system.config.parameter_values())
        out[name] = dataclasses.replace(
            c, unknowns=tuple(n for n in c.unknowns if keep(n)),
            limits={k: v for k, v in c.limits.items() if keep(k)}, start={k: v for k, v in c.start.items() if keep(k)},
            strength=tuple(n for n in c.strength if keep(n)), null={k: v for k, v in c.null.items() if keep(k)},
            starts=tuple({k: v for k, v in s.items() if keep(k)} for s in c.starts), companions=companions,
        )  # fmt: skip
    return out
