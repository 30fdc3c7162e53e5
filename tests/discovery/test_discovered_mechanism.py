"""The `discovered` mechanism inside the plant: each term does exactly what its id says, in the
trajectory simulator (replay), the batch simulator and the step simulator (node), and
survives a model file round trip."""
import math

import numpy as np
import pytest

from clutch_model.errors import ParamsError
from clutch_model.plant import kernels as K
from clutch_model.plant.friction import friction_grid
from clutch_model.plant.mechanisms import make_mechanism
from clutch_model.plant.params import ClutchModel, load_model, save_model
from clutch_model.plant.simulate import Plant, simulate, simulate_batch


def _inputs(slip=4.0):
    t = np.arange(0.0, 4.0, 0.005)
    force = np.interp(t, [0, 0.5, 0.56, 2.0, 2.05, 3.0, 3.06, 4.0], [300, 300, 7000, 7000, 3000, 3000, 9000, 9000])
    return t, force, np.full(t.size, slip), np.full(t.size, 55.0)


def _with(model, terms, coefs):
    return model.with_mechanisms([make_mechanism("discovered", terms=list(terms), coefficients=list(coefs))])


def _base_mu(sim):
    m = load_model()
    return friction_grid(m.friction_coefficients, m.friction_exponent, np.abs(np.full(sim.t.size, 4.0)), sim.pressure_mpa, sim.pack_temperature_c)


@pytest.fixture(scope="module")
def rc1():
    return load_model()


def test_pressure_temperature_multiplier_is_exact(rc1):
    c = 3e-3
    sim = simulate(_with(rc1, ["mu:pressure*pack_temperature"], [c]), *_inputs())
    expected = _base_mu(sim) * (1.0 + c * sim.pressure_mpa * (sim.pack_temperature_c - 60.0))
    np.testing.assert_allclose(sim.friction_coefficient, expected, rtol=1e-12, atol=1e-15)
    # and the pack heats with the changed torque: the state is simulated, not patched
    base = simulate(rc1, *_inputs())
    assert abs(sim.pack_temperature_c[-1] - base.pack_temperature_c[-1]) > 0.05


def test_slip_power_and_energy_multipliers_use_the_plant_state(rc1):
    c_p, c_e = -0.03, -0.5
    sim = simulate(_with(rc1, ["mu:slip_power", "mu:energy"], [c_p, c_e]), *_inputs())
    power_prev = np.concatenate([[0.0], sim.power_w[:-1]]) * 1e-3
    expected = _base_mu(sim) * (1.0 + c_p * power_prev + c_e * sim.energy_j * 1e-6)
    np.testing.assert_allclose(sim.friction_coefficient[1:], expected[1:], rtol=1e-9)


def test_once_per_revolution_ripple_follows_the_slip_angle(rc1):
    a_sin, a_cos, w = 0.05, -0.02, 4.0
    sim = simulate(_with(rc1, ["mu:sin_slip_angle", "mu:cos_slip_angle"], [a_sin, a_cos]), *_inputs(w))
    angle = w * sim.t            # constant slip from the run start
    expected = _base_mu(sim) * (1.0 + a_sin * np.sin(angle) + a_cos * np.cos(angle))
    np.testing.assert_allclose(sim.friction_coefficient, expected, rtol=1e-9)


def test_low_passed_additive_torque_is_a_first_order_response(rc1):
    c, tau = 12.0, 0.5
    sim = simulate(_with(rc1, ["torque:slip_sign@0.5s"], [c]), *_inputs())
    # the drag output carries the additive term (RC-1 has no drag): c (1 - exp(-t / tau))
    np.testing.assert_allclose(sim.drag_torque_nm, c * -np.expm1(-sim.t / tau), rtol=1e-12, atol=1e-12)


def test_replay_batch_and_step_simulators_agree(rc1):
    model = _with(rc1, ["mu:slip_power@0.3s", "mu:force_rate", "torque:slip"], [-0.02, 1e-4, 0.8])
    t, f, w, s = _inputs()
    sim = simulate(model, t, f, w, s)
    batch = simulate_batch([rc1, model], t, f, w, s)
    np.testing.assert_allclose(batch.torque_nm[1], sim.torque_nm, rtol=0, atol=1e-9)
    assert np.max(np.abs(batch.torque_nm[0] - sim.torque_nm)) > 1.0
    plant = Plant(model)
    plant.reset(f[0], s[0])
    out = []
    for k in range(t.size):
        if k:
            plant.advance(t[k] - t[k - 1])
        out.append(float(plant.sample(f[k], w[k], s[k])[K.O_TORQUE]))
    np.testing.assert_allclose(out, sim.torque_nm, rtol=0, atol=1e-9)


def test_model_file_round_trip(tmp_path, rc1):
    model = _with(rc1, ["mu:pressure*pack_temperature", "torque:slip*slip_abs"], [2e-3, -0.05])
    path = save_model(model, tmp_path / "extended_model.yaml")
    text = path.read_text()
    assert "id: discovered" in text and "mu:pressure*pack_temperature" in text
    again = load_model(path)
    assert again.mechanism("discovered").parameter_values == pytest.approx(
        {"mu:pressure*pack_temperature": 2e-3, "torque:slip*slip_abs": -0.05})
    np.testing.assert_array_equal(again.vector(), model.vector())


@pytest.mark.parametrize("entry,message", [
    ({"terms": ["mu:viscosity"], "coefficients": [1.0]}, "unknown signal 'viscosity'"),
    ({"terms": ["friction:slip_power"], "coefficients": [1.0]}, "bad term"),
    ({"terms": ["mu:slip_power"], "coefficients": [1.0, 2.0]}, "differ in length"),
    ({"terms": ["mu:slip_power"], "coefficients": [math.nan]}, "finite"),
    ({"terms": ["mu:slip_power"]}, "needs lists"),
])
def test_bad_entries_are_refused_with_a_reason(rc1, entry, message):
    raw = rc1.to_dict()
    raw["mechanisms"] = [{"id": "discovered", **entry}]
    with pytest.raises(ParamsError, match=message):
        ClutchModel.from_dict(raw, source="m.yaml")


def test_clutch_sim_replay_applies_the_discovered_terms(tmp_path, rc1):
    """`clutch-sim replay --params extended_model.yaml` simulates the discovered terms: its
    torque is the plant simulation of the extended model, and differs from RC-1's."""
    import csv

    from clutch_model.formats.bag_writer import write_run_bag
    from clutch_sim.cli import main as cli

    t, f, w, s = _inputs()
    sig = {"applied_force": (t, f), "slip_speed": (t, w), "sump_temperature": (t[::20], s[::20]),
           "measured_torque": (t, np.zeros(t.size))}
    write_run_bag(tmp_path / "run_a", sig, storage="mcap")
    model = _with(rc1, ["mu:pressure*pack_temperature", "mu:sin_slip_angle"], [3e-3, 0.05])
    params = save_model(model, tmp_path / "extended_model.yaml")
    outs = {}
    for name, p in (("extended", params), ("rc1", None)):
        out = tmp_path / f"{name}.csv"
        args = ["replay", "--bag", str(tmp_path / "run_a"), "--out", str(out)] + (["--params", str(p)] if p else [])
        assert cli(args) == 0
        with open(out) as fh:
            outs[name] = np.array([float(r["torque_sim"]) for r in csv.DictReader(fh)])
    expected = simulate(model, t, f, w, s).torque_nm
    np.testing.assert_allclose(outs["extended"], expected, rtol=1e-5, atol=1e-6)
    assert np.max(np.abs(outs["extended"] - outs["rc1"])) > 10.0
