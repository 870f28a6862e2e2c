"""Every identifiable parameter declares its SI unit where it is declared (issue 23): the car's on its field's type,
each effect's on its parameters, a damper's beside its model's layout; `SystemConfig.unit` is the one lookup, and
a plug-in effect brings its units along."""

from __future__ import annotations

import pytest

from tests import toy_effect
from tests.conftest import BASE_CONFIG, ROOT
from vehid_cli.config import load_config
from vehid_cli.models.damper import MODELS
from vehid_cli.models.effects import LIBRARY, register, unregister

# SPEC section 1 (SI inside) and the config's descriptions: independent of the Unit markers
CAR = {
    "m": "kg", "mf": "kg", "mr": "kg", "Ix": "kg m²", "Iy": "kg m²", "a1": "m", "b1": "m", "kf": "N/m", "kr": "N/m",
    "ktf": "N/m", "ktr": "N/m", "kR": "N m/rad", "cf": "N s/m", "cr": "N s/m",
}  # fmt: skip


def test_the_cars_parameters_have_the_units_of_their_descriptions():
    cfg = load_config(BASE_CONFIG)
    assert cfg.units(CAR) == CAR
    for name, unit in CAR.items():  # the description a user reads in a did-you-mean says the same unit
        assert type(cfg.vehicle).model_fields[name].description.endswith(f"[{unit}]")
    assert cfg.unit("no_such_parameter") == ""


def test_every_effect_parameter_has_its_declared_unit_on_the_car_and_on_a_bench():
    cfg = load_config(BASE_CONFIG)
    damper = load_config(ROOT / "configs" / "dampers" / "synthetic_bingham.yaml")
    for effect in LIBRARY.values():
        for name in effect.names():
            unit = effect.param(name).unit
            assert unit and cfg.unit(f"{effect.name}.{name}") == unit
        for p in effect.params:  # a damper names them plainly
            assert damper.unit(f"{effect.name}.{p.name}") == p.unit


@pytest.mark.parametrize("model", list(MODELS))
def test_every_entry_of_a_damper_models_row_has_a_unit(model):
    shape = {"generalized_bouc_wen": (3,), "force_map": (4, 3)}.get(model, ())
    row = MODELS[model].layout(shape)
    units = {n: MODELS[model].unit(n) for n in row}
    assert all(units.values()), [n for n, u in units.items() if not u]
    expected = {"k1": "N/m", "x0": "m", "gap": "m", "tau_comp_rise": "s", "T_reb_fall": "s", "v_switch": "m/s"}
    assert {n: units[n] for n in expected} == expected
    if model == "force_map":
        assert units["F_2_3"] == "N" and units["v_node_4"] == "m/s" and units["u_node_1"] == "-"
    if model == "generalized_bouc_wen":
        assert units["c0_comp_2"] == "N s/m" and units["alpha_reb_3"] == "N/m" and units["delta_comp_1"] == "-"


def test_a_plug_in_effect_brings_its_units_along():
    before = tuple(LIBRARY)
    register(toy_effect.EFFECT)
    try:
        cfg = load_config(BASE_CONFIG)
        for name in toy_effect.EFFECT.names():
            declared = toy_effect.EFFECT.param(name).unit
            assert cfg.unit(f"{toy_effect.EFFECT.name}.{name}") == declared != ""
    finally:
        unregister(toy_effect.EFFECT.name)
    assert tuple(LIBRARY) == before


def test_a_correction_of_the_measurement_chain_has_its_faults_unit_in_the_channels_unit():
    """sensor:<channel>:<param>: a gain, sign or weight is dimensionless, a delay in s, an offset in the channel's
    own unit and a drift in it per second (the channel from the config's layout: acc in m/s², disp in m)."""
    from vehid_cli.models.faults import FAULTS

    cfg = load_config(BASE_CONFIG)
    assert cfg.unit("sensor:acc1:offset") == "m/s^2" and cfg.unit("sensor:disp3:offset") == "m"
    assert cfg.unit("sensor:disp2:drift") == "m/s" and cfg.unit("sensor:acc4:delay") == "s"
    assert cfg.unit("sensor:acc1:swap:acc2") == "-" and cfg.unit("sensor:acc1:gain") == "-"
    assert all(f.unit for f in FAULTS.values())  # every fault declares one
