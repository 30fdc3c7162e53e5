"""diagnose at scale: the anti-aliased decimation of fast logs (what it keeps, what it
removes, that campaigns at the rate the diagnosis was designed for are left untouched, that a
1 kHz campaign is still diagnosed right) and candidate fits on a real Dask cluster (a
`dask scheduler` and two `dask worker` processes, the ``cluster`` fixture of tests/conftest.py)
with the same report as the serial run."""
import json
import math
from dataclasses import replace

import numpy as np
import pytest

from clutch_model.diagnosis.decimation import (choose_diagnosis_rate, decimate_campaign, decimate_run,
                                               fastest_time_constant_s)
from clutch_model.formats.bag_reader import Campaign, Run
from clutch_model.plant.params import load_model
from clutch_model.plant.simulate import simulate
from clutch_model.virtual_car.campaign import CampaignSpec, synthesize_campaign, write_campaign
from clutch_sim.cli import main as cli


def _run(rate_hz, duration_s=20.0, torque=None, seed=0, name="r"):
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration_s * rate_hz)) / rate_hz
    force = 8000.0 + 6000.0 * np.sin(2 * np.pi * 0.3 * t)
    slip = 3.0 + np.sin(2 * np.pi * 0.17 * t)
    sump = np.full(t.size, 60.0)
    tq = torque(t) if torque is not None else rng.normal(0, 5.0, t.size)
    return Run(name=name, t=t, applied_force_n=force, slip_speed_rad_s=slip, sump_temperature_c=sump,
               torque_measured_nm=tq)


def test_rate_rule_leaves_the_design_rate_alone_and_decimates_fast_logs():
    assert fastest_time_constant_s() == pytest.approx(0.003)
    for rate in (100.0, 200.0, 250.0, 390.0):
        plan = choose_diagnosis_rate(Campaign([_run(rate)]))
        assert plan.factor == 1, rate
        assert decimate_campaign(Campaign([_run(rate)]), plan).t.size == int(20 * rate)
    plan = choose_diagnosis_rate(Campaign([_run(1000.0)]))
    # the plant's step (196 Hz) and a 3 ms lag's corner 1.5x inside the passband (199 Hz)
    assert plan.factor == 5 and plan.rate_hz == pytest.approx(200.0)
    assert plan.min_rate_hz == pytest.approx(2 * 1.5 / (2 * math.pi * 0.003) / 0.8)
    assert choose_diagnosis_rate(Campaign([_run(500.0)])).factor == 2
    # a requested rate: the largest integer factor that keeps at least that rate
    assert choose_diagnosis_rate(Campaign([_run(1000.0)]), rate_hz=300.0).factor == 3
    # runs of different lengths share one spectral grid
    assert choose_diagnosis_rate(Campaign([_run(1000.0), _run(1000.0, duration_s=0.3, name="s")])).factor == 5


def test_decimation_removes_what_would_alias_and_keeps_the_band():
    """A 30 Hz tone (inside the 200 Hz passband) survives in amplitude and phase; a 180 Hz
    tone (above the new 100 Hz Nyquist, it would alias to 20 Hz) is removed; white noise
    keeps the share of its variance that lies in the passband."""
    low = lambda t: 10.0 * np.sin(2 * np.pi * 30.0 * t)          # noqa: E731
    high = lambda t: 10.0 * np.sin(2 * np.pi * 180.0 * t)        # noqa: E731
    run = _run(1000.0, torque=lambda t: low(t) + high(t))
    d = decimate_run(run, 5)
    assert d.t.size == 4000 and np.array_equal(d.t, run.t[::5])
    inner = slice(50, -50)                                        # away from the padded ends
    err = d.torque_measured_nm[inner] - low(d.t[inner])
    assert np.sqrt(np.mean(err ** 2)) < 0.05 * 10.0 / np.sqrt(2)
    noise = decimate_run(_run(1000.0, duration_s=200.0, seed=3), 5).torque_measured_nm
    assert np.std(noise) == pytest.approx(5.0 * np.sqrt(1 / 5), rel=0.1)


def test_missing_torque_samples_stay_missing():
    run = _run(1000.0)
    tq = run.torque_measured_nm.copy()
    tq[5000:5003] = np.nan
    d = decimate_run(replace(run, torque_measured_nm=tq), 5)
    bad = np.flatnonzero(~np.isfinite(d.torque_measured_nm))
    assert bad.size and bad.min() * 5 <= 5000 and bad.max() * 5 >= 5002
    assert bad.size <= 2 * 10 + 2                                 # only the filter's reach
    assert np.isfinite(d.applied_force_n).all()


def test_decimated_plant_matches_the_native_one():
    """The plant simulated on the decimated inputs against the native simulation filtered the
    same way: the held force's half-step shift keeps the hold's mean delay, so the error is
    a fraction of a per mille of the torque's range."""
    model = load_model(None)
    run = _run(1000.0, duration_s=30.0)
    ref = simulate(model, run.t, run.applied_force_n, run.slip_speed_rad_s, run.sump_temperature_c).torque_nm
    d = decimate_run(replace(run, torque_measured_nm=ref), 5)
    sim = simulate(model, d.t, d.applied_force_n, d.slip_speed_rad_s, d.sump_temperature_c).torque_nm
    inner = slice(100, -100)
    err = np.sqrt(np.mean((sim - d.torque_measured_nm)[inner] ** 2))
    assert err < 1e-3 * np.ptp(ref)


def _virtual_campaign(tmp_path, **kw):
    spec = CampaignSpec(**kw)
    write_campaign(synthesize_campaign(spec), tmp_path / "campaign")
    return spec, sorted(str(p) for p in (tmp_path / "campaign" / "bags").iterdir())


# acceptance-style (70 s on the 2-core machine): the rate rule, the decimation filter and the
# decimated plant are checked by the tests above; `-m slow` runs it
@pytest.mark.slow
def test_a_1khz_car_log_is_decimated_and_diagnosed_right(tmp_path):
    """The car-log virtual test car (controller-like ramps, holds, releases; own clocks with
    jitter) with every topic at 1 kHz and a transport delay of 30 ms: diagnose decimates (the
    plant on the decimated rows within 0.1 noise sd of the native one) and still names the
    delay, with an interval holding the truth."""
    from clutch_model.virtual_car.car_logs import DEFAULT_CLOCKS, CarLogSpec, synthesize_car_logs, write_car_logs

    clocks = {ch: replace(c, rate_hz=1000.0, jitter_s=min(c.jitter_s, 2e-4))
              for ch, c in DEFAULT_CLOCKS.items() if ch in ("applied_force", "slip_speed", "measured_torque")}
    spec = CarLogSpec(seed=873, n_runs=6, run_duration_s=8.0, clocks=clocks, lockup=False,
                      mechanisms=[{"id": "transport_delay", "delay_s": 0.03}])
    paths = write_car_logs(synthesize_car_logs(spec), tmp_path / "campaign")
    out = tmp_path / "diag"
    assert cli(["diagnose", "--bench", str(paths["bench"]), "--bags", *map(str, paths["bags"]),
                "--out", str(out), "--mc-samples", "0", "--no-progress"]) == 0
    rep = json.loads((out / "report.json").read_text())
    rate = rep["diagnosis_rate"]
    assert rate["factor"] >= 2, rate
    for q, chk in rate["error_check_nm"].items():
        if int(q) == rate["factor"]:
            assert chk["decimation_error_rms"] <= 0.1 * chk["noise_sd"]
    assert [c["id"] for c in rep["causes"]] == ["transport_delay"], rep["cause"]["evidence"]
    lo, hi = rep["causes"][0]["parameters_ci95"]["delay_s"]
    assert lo <= 0.03 <= hi
    assert rep["gain_pct"] > 10.0


def test_diagnose_on_a_dask_cluster_equals_serial(cluster, tmp_path, capsys):
    """`clutch-sim diagnose --scheduler ADDRESS`: the candidate fits run on the cluster's two
    worker processes and the report (causes, parameters, intervals, every candidate's fit)
    equals the serial run's to the last bit."""
    address, client = cluster
    spec, bags = _virtual_campaign(tmp_path, seed=872, n_runs=4, run_duration_s=4.0,
                                   mechanism="torque_offset", magnitude=15.0)
    base = ["diagnose", "--bench", str(tmp_path / "campaign" / "bench.csv"), "--bags", *bags, "--mc-samples", "0",
            "--candidates", "torque_offset", "actuator_lag", "--no-progress"]
    assert cli(base + ["--out", str(tmp_path / "serial")]) == 0
    before = sum(len(v) for v in client.run(lambda dask_worker: list(dask_worker.state.log)).values())
    assert cli(base + ["--out", str(tmp_path / "dask"), "--scheduler", address]) == 0
    err = capsys.readouterr().err
    assert f"candidate fits on dask {address}" in err
    after = {w: len(v) for w, v in client.run(lambda dask_worker: list(dask_worker.state.log)).items()}
    assert sum(after.values()) > before and all(n > 0 for n in after.values())    # both workers fitted
    s = json.loads((tmp_path / "serial" / "report.json").read_text())
    d = json.loads((tmp_path / "dask" / "report.json").read_text())
    assert s["causes"] and s["causes"][0]["id"] == "torque_offset"
    for key in ("cause", "causes", "rmse_nm", "gain_pct", "candidates", "noise_model", "held_out_runs"):
        assert d[key] == s[key], key
    assert (tmp_path / "dask" / "extended_model.yaml").read_text() == (tmp_path / "serial" / "extended_model.yaml").read_text()


def test_montecarlo_chunks_bound_memory_not_results():
    """The car calibration's Monte Carlo chunks hold at most ~256 MB of predictions (an hour
    of car data would hold GBs at once) and the chunking changes a sample's RMSE by at most
    a rounding (numpy's row means over a differently shaped block), not the refined model."""
    from clutch_model.diagnosis.calibration import montecarlo_chunk_size
    from clutch_model.identification.montecarlo import run_montecarlo
    from clutch_model.virtual_car import identification_data as td

    assert montecarlo_chunk_size(50_000) == 256                   # small campaigns: as before
    assert montecarlo_chunk_size(800_000) * 16 * 800_000 <= 256e6
    model = load_model(None)
    runs = td.synthetic_runs(model, n_runs=2, duration_s=3.0, noise_nm=10.0, seed=5)
    a = run_montecarlo(model, runs, n_samples=30, spread=0.05, seed=2, halving=(), progress=False)
    b = run_montecarlo(model, runs, n_samples=30, spread=0.05, seed=2, halving=(), progress=False, chunk_size=4)
    np.testing.assert_allclose(a.rmse, b.rmse, rtol=1e-14)
    assert np.array_equal(a.accepted, b.accepted) and np.array_equal(a.refined_a, b.refined_a)
