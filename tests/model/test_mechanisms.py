"""Exact identities of each catalog mechanism and of their composition (checked against
independent statements of what the mechanism does, not against the kernels' code)."""
import math

import numpy as np
import pytest

from clutch_model import load_model, make_mechanism, simulate
from clutch_model.errors import ParamsError
from clutch_model.plant import friction
from clutch_model.plant.mechanisms import CATALOG, PATHS, CampaignScale, lowpass_signal
from clutch_model.prediction import PlantInputs, predict_campaign

MODEL = load_model()
DT = 1.0 / 256.0            # binary-exact grid: delays on a grid multiple shift exactly


def inputs(n_runs=2, duration=3.0, seed=0):
    """Force steps (below and above a preload), slowly varying slip, a warm sump; n_runs runs
    on one concatenated grid."""
    rng = np.random.default_rng(seed)
    n = int(duration / DT)
    t_run = np.arange(n) * DT
    ts, fs, ws, ss, rs = [], [], [], [], []
    for j in range(n_runs):
        f = np.where(t_run < 0.5, 200.0, np.where(t_run < 1.5, 6000.0 + 500 * j, np.where(t_run < 2.2, 300.0, 3000.0)))
        f = f + rng.normal(0, 10, n)
        w = 3.0 + 0.5 * np.sin(2 * np.pi * t_run / 3.0) + j
        ts.append(t_run + 20.0 * j)
        fs.append(f)
        ws.append(w)
        ss.append(np.full(n, 55.0 + 10 * j))
        r = np.zeros(n, bool)
        r[0] = True
        rs.append(r)
    return PlantInputs(t=np.concatenate(ts), force=np.concatenate(fs), slip=np.concatenate(ws),
                       sump=np.concatenate(ss), run_start=np.concatenate(rs))


IN = inputs()


def sim(model, force=None, energy0_j=0.0):
    return simulate(model, IN.t, IN.force if force is None else force, IN.slip, IN.sump,
                    run_start=IN.run_start, energy0_j=energy0_j)


def with_(*mechs):
    return MODEL.with_mechanisms([make_mechanism(i, **v) for i, v in mechs])


# --- what each mechanism says about itself ------------------------------------------------------
@pytest.mark.parametrize("mid", list(CATALOG))
def test_mechanism_describes_itself(mid):
    cls = CATALOG[mid]
    assert cls.id == mid and cls.path in PATHS and cls.physics
    for par in cls.parameters:
        lo, hi = par.bounds
        assert lo < hi and par.unit
    scale = CampaignScale(max_force_n=8000.0, max_slip_rad_s=10.0, energy_total_j=2e5, torque_scale_nm=800.0)
    specs = cls.search_space(scale)
    assert [s.name for s in specs] == list(cls.parameter_names())
    for s in specs:
        assert s.lo < s.hi and np.all((s.grid >= s.lo) & (s.grid <= s.hi))
    vis = cls.virtual_car.visible
    if vis is not None:
        assert vis[0] <= cls.virtual_car.default <= vis[1]
        make_mechanism(mid, **{cls.magnitude_parameter(): vis[1]})   # within its physical bounds
    # plant mechanisms write a kernel slot, measurement ones do not
    assert (cls.kernel_slot is None) == (cls.path == "measurement")
    with pytest.raises(ParamsError):
        make_mechanism(mid, **{cls.magnitude_parameter(): cls.parameters[0].bounds[1] * 2 + 1})


def test_model_file_round_trip_with_several_mechanisms():
    m = with_(("torque_sensor_lag", {"tau_s": 0.03}), ("spring_preload", {"preload_n": 400.0}),
              ("torque_offset", {"offset_nm": 5.0}))
    again = type(MODEL).from_dict(m.to_dict())
    assert [x.to_dict() for x in again.mechanisms] == [x.to_dict() for x in m.mechanisms]
    assert np.array_equal(again.vector(), m.vector())


# --- plant mechanisms ----------------------------------------------------------------------------
def test_preload_is_the_baseline_at_force_minus_preload():
    fp = 700.0
    ext = sim(with_(("spring_preload", {"preload_n": fp})))
    base = sim(MODEL, force=np.maximum(IN.force - fp, 0.0))
    assert np.array_equal(ext.torque_nm, base.torque_nm)
    assert np.array_equal(ext.pack_temperature_c, base.pack_temperature_c)
    assert np.array_equal(ext.pack_force_n, base.pack_force_n)


def test_friction_degradation_scales_mu_by_exp_minus_energy():
    es = 4e4
    e0 = 1.5e4
    s = sim(with_(("friction_degradation", {"energy_scale_j": es})), energy0_j=e0)
    b = np.flatnonzero(IN.run_start)[1]
    assert s.energy_j[0] == e0 and s.energy_j[-1] > e0 + 1e3
    assert s.energy_j[b] >= s.energy_j[b - 1] > e0                   # carried across the runs
    a, i = MODEL.friction_coefficients, MODEL.friction_exponent
    w = np.where(s.locked, 0.0, np.abs(IN.slip))
    mu0 = np.array([friction.mu(a, i, wk, pk, th) for wk, pk, th in zip(w, s.pressure_mpa, s.pack_temperature_c)])
    assert np.allclose(s.friction_coefficient, mu0 * np.exp(-s.energy_j / es), rtol=1e-12, atol=0)


def test_drag_adds_coeff_times_slip_times_viscosity_ratio():
    c = 7.0
    s = sim(with_(("drag_torque", {"coeff_nm_per_rad_s": c})))
    v = MODEL.data["viscosity"]
    mu60 = v["alpha0"] * 60.0 ** (-v["alpha1"])
    expect = np.where(s.locked, 0.0, c * IN.slip * s.viscosity_pa_s / mu60)
    assert np.allclose(s.drag_torque_nm, expect, rtol=1e-12, atol=0)
    assert np.allclose(s.torque_nm, s.asperity_torque_nm + s.hydrodynamic_torque_nm + s.drag_torque_nm,
                       rtol=1e-12, atol=1e-12)
    assert np.min(np.abs(s.drag_torque_nm)) > 0


# --- measurement mechanisms ----------------------------------------------------------------------
def test_offset_adds_exactly():
    p = predict_campaign(with_(("torque_offset", {"offset_nm": 17.5})), IN)
    assert np.array_equal(p.torque_nm, p.plant_torque_nm + 17.5)


def test_delay_shifts_exactly_on_a_grid_multiple():
    k = 9
    p = predict_campaign(with_(("transport_delay", {"delay_s": k * DT})), IN)
    for a in np.flatnonzero(IN.run_start):
        n = int(np.sum(IN.t[a:] < IN.t[a] + 3.0))
        run, plant = p.torque_nm[a:a + n], p.plant_torque_nm[a:a + n]
        assert np.array_equal(run[k:], plant[:-k])
        assert np.all(run[:k] == plant[0])           # before the run: its first value


def test_sensor_lag_step_response_is_analytic():
    tau = 0.05
    t = np.sort(np.concatenate([np.linspace(0, 1, 301), [0.2371, 0.61, 0.6101]]))
    u = np.where(t >= 0.3, 40.0, 10.0)
    y = lowpass_signal(t, u, np.r_[True, np.zeros(t.size - 1, bool)], tau, hold=True)
    expect = np.where(t < 0.3, 10.0, 40.0 - 30.0 * np.exp(-(t - 0.3) / tau))
    assert np.allclose(y, expect, rtol=0, atol=1e-12)


def test_sensor_lag_ramp_response_is_analytic_on_an_irregular_grid():
    tau, r, u0 = 0.08, 250.0, 30.0
    rng = np.random.default_rng(3)
    t = np.cumsum(np.r_[0.0, rng.uniform(0.001, 0.02, 200)])
    u = u0 + r * t
    y = lowpass_signal(t, u, np.r_[True, np.zeros(t.size - 1, bool)], tau)
    # tau y' = u - y, y(0) = u(0): y = u0 + r (t - tau (1 - exp(-t/tau)))
    expect = u0 + r * (t - tau * (1.0 - np.exp(-t / tau)))
    assert np.allclose(y, expect, rtol=1e-12, atol=1e-10)


def test_sensor_lag_restarts_at_each_bag_and_is_first_order_in_the_prediction():
    tau = 0.04
    p = predict_campaign(with_(("torque_sensor_lag", {"tau_s": tau})), IN)
    starts = np.flatnonzero(IN.run_start)
    assert np.array_equal(p.torque_nm[starts], p.plant_torque_nm[starts])
    # (n_sets, n) traces filter row by row like the 1-D trace, linearly
    both = lowpass_signal(IN.t, np.vstack([p.plant_torque_nm, 2 * p.plant_torque_nm]), IN.run_start, tau)
    assert np.allclose(both[0], p.torque_nm, rtol=1e-13, atol=1e-12)
    assert np.allclose(both[1], 2 * p.torque_nm, rtol=1e-13, atol=1e-12)


# --- composition -----------------------------------------------------------------------------------
def test_measurement_mechanisms_compose_in_catalog_order_whatever_the_listing():
    k, off, tau = 5, 12.0, 0.03
    mechs = [("torque_sensor_lag", {"tau_s": tau}), ("transport_delay", {"delay_s": k * DT}),
             ("torque_offset", {"offset_nm": off})]
    p = predict_campaign(with_(*mechs), IN)
    q = predict_campaign(with_(*mechs[::-1]), IN)
    assert np.array_equal(p.torque_nm, q.torque_nm)
    # in sequence: offset, then delay, then the sensor's low-pass
    step = make_mechanism("torque_offset", offset_nm=off).apply_to_measurement(IN.t, p.plant_torque_nm, IN.run_start)
    step = make_mechanism("transport_delay", delay_s=k * DT).apply_to_measurement(IN.t, step, IN.run_start)
    step = lowpass_signal(IN.t, step, IN.run_start, tau)
    assert np.array_equal(p.torque_nm, step)


def test_plant_and_measurement_mechanisms_compose():
    """A plant mechanism and a measurement mechanism: the measurement acts on the plant
    torque of the model that has the plant mechanism."""
    fp, off = 500.0, -8.0
    p = predict_campaign(with_(("torque_offset", {"offset_nm": off}), ("spring_preload", {"preload_n": fp})), IN)
    base = sim(MODEL, force=np.maximum(IN.force - fp, 0.0))
    assert np.array_equal(p.torque_nm, base.torque_nm + off)


def _step_inputs(levels, t_steps, duration=2.0):
    n = int(duration / DT)
    t = np.arange(n) * DT
    f = np.full(n, float(levels[0]))
    for lv, ts in zip(levels[1:], t_steps):
        f[t >= ts] = lv
    rs = np.zeros(n, bool)
    rs[0] = True
    return t, f, rs


def test_force_chain_lag_then_hysteresis_then_preload():
    """Pack force of lag + hysteresis + preload against the chain stated independently:
    first-order lag of the measured steps, the play operator along it, minus the preload."""
    tau, r, fp = 0.1, 0.15, 800.0
    levels, t_steps = (300.0, 6000.0, 2500.0), (0.25, 1.0)
    t, f, rs = _step_inputs(levels, t_steps)
    model = with_(("spring_preload", {"preload_n": fp}), ("actuator_hysteresis", {"ratio": r}),
                  ("actuator_lag", {"tau_s": tau}))
    s = simulate(model, t, f, np.full(t.size, 3.0), np.full(t.size, 60.0), run_start=rs)
    # lag: exact response to the held steps (sample k's force acts from t_k on)
    fa = np.empty(t.size)
    fa[0] = levels[0]
    for k in range(1, t.size):
        target = f[k - 1]
        fa[k] = target + (fa[k - 1] - target) * math.exp(-DT / tau)
    # play operator along the lagged force, starting centred on the first sample
    fh = np.empty(t.size)
    fh[0] = fa[0]
    for k in range(1, t.size):
        fh[k] = min(max(fh[k - 1], fa[k] * (1 - r)), fa[k] * (1 + r))
    expect = np.maximum(fh - fp, 0.0)
    assert np.allclose(s.pack_force_n, expect, rtol=1e-10, atol=1e-9)
    # the order matters: preload before the lag would give a different pack force
    assert np.max(np.abs(s.pack_force_n - np.maximum(fa - fp, 0.0))) > 100.0
    assert s.pack_force_n[int(0.2 / DT)] == 0.0                   # below the preload: no pack force


def test_lag_alone_and_hysteresis_alone_follow_their_laws():
    tau = 0.07
    t, f, rs = _step_inputs((1000.0, 5000.0), (0.5,))
    s = simulate(with_(("actuator_lag", {"tau_s": tau})), t, f, np.full(t.size, 2.0), np.full(t.size, 50.0),
                 run_start=rs)
    k0 = int(0.5 / DT)
    tt = t[k0 + 1:] - t[k0]
    assert np.allclose(s.pack_force_n[k0 + 1:], 5000.0 - 4000.0 * np.exp(-tt / tau), rtol=1e-12)
    r = 0.1
    h = simulate(with_(("actuator_hysteresis", {"ratio": r})), t, f, np.full(t.size, 2.0),
                 np.full(t.size, 50.0), run_start=rs)
    assert np.all(h.pack_force_n[:k0] == 1000.0)
    assert np.allclose(h.pack_force_n[k0:], 5000.0 * (1 - r), rtol=1e-15)
