"""Sensor layouts (models/sensors.py) against the car's kinematics, computed here from the coordinates directly."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import PAPER_CAR, small_config
from vehid_cli.models.fullcar import assemble, geometry
from vehid_cli.models.road import road_function
from vehid_cli.models.sensors import Layout, Sensor, corner_layout
from vehid_cli.sim.linear import simulate

ROAD = road_function(small_config().road, 2.6, np.random.default_rng(0))


def _response(layout: Layout, integrator: str = "exact", car=PAPER_CAR):
    t = np.arange(1500) * 0.002
    return t, simulate(assemble(car), ROAD(t), 0.002, integrator, layout.points(car))


def test_the_paper_layout_reads_the_corner_points_of_eq_7_exactly():
    p = {k: np.array([v, 1.1 * v]) for k, v in PAPER_CAR.items()}
    np.testing.assert_array_equal(corner_layout().points(p), geometry(p["a1"], p["a2"], p["b1"], p["b2"]))
    assert corner_layout().channel_names == ("acc1", "acc2", "acc3", "acc4", "disp1", "disp2", "disp3", "disp4")


def test_channels_are_the_kinematics_of_their_points():
    """A body point at (x, y) from the CG moves x_b + y phi - x theta; a point given from corner 3 sits at
    (-a2 + dx, -b2 + dy); a deflection is the body point above the corner minus the wheel; a wheel sensor the hop."""
    layout = Layout((
        Sensor("roof", "body_acc", x=0.4, y=-0.3),
        Sensor("boot", "body_disp", x=0.2, y=0.1, origin="corner3"),
        Sensor("hub2", "wheel_acc", corner=2),
        Sensor("hop4", "wheel_disp", corner=4),
        Sensor("pot1", "deflection", corner=1),
        Sensor("dash", "body_acc", x=-0.3, origin="front_axle"),
    ))  # fmt: skip
    _, r = _response(layout)
    ch = layout.read(r)
    assert layout.names("acc") == ("roof", "hub2", "dash") and layout.names("disp") == ("boot", "hop4", "pot1")
    q, qdd = r.q, r.qdd
    a1, a2, b1, b2 = (PAPER_CAR[k] for k in ("a1", "a2", "b1", "b2"))
    np.testing.assert_allclose(ch["acc"][:, 0], qdd[:, 0] - 0.3 * qdd[:, 1] - 0.4 * qdd[:, 2], atol=1e-12)
    np.testing.assert_allclose(ch["disp"][:, 0], q[:, 0] + (-b2 + 0.1) * q[:, 1] - (-a2 + 0.2) * q[:, 2], atol=1e-15)
    np.testing.assert_array_equal(ch["acc"][:, 1], qdd[:, 4])
    np.testing.assert_array_equal(ch["disp"][:, 1], q[:, 6])
    np.testing.assert_allclose(ch["disp"][:, 2], q[:, 0] + b1 * q[:, 1] - a1 * q[:, 2] - q[:, 3], atol=1e-15)
    dash_y = (b1 - b2) / 2
    np.testing.assert_allclose(ch["acc"][:, 2], qdd[:, 0] + dash_y * qdd[:, 1] - (a1 - 0.3) * qdd[:, 2], atol=1e-12)


def test_a_sensor_given_from_a_corner_stays_put_when_the_cg_moves():
    layout = Layout((Sensor("tower", "body_disp", x=-0.1, y=-0.1, origin="corner1"),))
    a1 = np.array([1.2, 1.3, 1.4])
    rows = layout.points({"a1": a1, "a2": 2.6 - a1, "b1": 0.75, "b2": 0.75})
    np.testing.assert_allclose(rows[:, 0, 2], -(a1 - 0.1))  # x from the CG follows a1: the mount does not move
    np.testing.assert_allclose(rows[:, 0, 1], 0.65)


@pytest.mark.parametrize("integrator", ["exact-reference", "newmark"])
def test_the_fast_path_agrees_with_the_reference_integrators_at_any_points(integrator):
    layout = Layout((Sensor("a", "body_acc", x=0.7, y=0.2), Sensor("d", "body_disp", x=-1.0, y=-0.5)))
    _, fast = _response(layout)
    _, ref = _response(layout, integrator)
    tol = 1e-9 if integrator == "exact-reference" else 2e-2  # Newmark is second order at dt = 2 ms
    for name in ("acc", "disp"):
        scale = np.max(np.abs(getattr(ref, name)))
        np.testing.assert_allclose(getattr(fast, name), getattr(ref, name), atol=tol * scale)


def test_repeated_names_are_refused():
    with pytest.raises(ValueError, match="repeat"):
        Layout((Sensor("a", "body_acc"), Sensor("a", "wheel_acc", corner=1)))
