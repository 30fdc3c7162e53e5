"""The diagnosis sample of long campaigns (clutch_model.diagnosis.sample): a window started from
the plant state a whole simulation has at its first row continues exactly as that simulation
(friction_degradation's energy included, single and batch kernels); the windows span the
campaign and its operating range, hold out whole windows and leave their warm-up unscored;
campaigns under the budget are not sampled; and a sampled campaign with a hidden mechanism is
still diagnosed right."""
import json

import numpy as np
import pytest

from clutch_model.diagnosis import sample as S
from clutch_model.diagnosis.split import parse_held_out
from clutch_model.formats.bag_reader import Campaign, Run
from clutch_model.plant.mechanisms import make_mechanism
from clutch_model.plant.params import load_model
from clutch_model.plant.simulate import simulate, simulate_batch
from clutch_model.prediction import predict_campaign
from clutch_model.virtual_car.campaign import CampaignSpec, synthesize_campaign, write_campaign
from clutch_sim.cli import main as cli


def _run(name, duration_s, seed, start_ns, rate_hz=200.0):
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration_s * rate_hz)) / rate_hz
    k = (t / 1.5).astype(int)
    levels = rng.uniform(500.0, 12000.0, k.max() + 2)
    frac = np.clip((t / 1.5 - k) / 0.2, 0.0, 1.0)
    force = levels[k] + (levels[k + 1] - levels[k]) * frac
    slip = 4.0 + 3.0 * np.sin(2 * np.pi * t / 13.0) + rng.normal(0, 0.02, t.size)
    sump = 40.0 + 0.1 * t
    return Run(name=name, t=t, applied_force_n=force, slip_speed_rad_s=slip, sump_temperature_c=sump,
               torque_measured_nm=rng.normal(0, 1.0, t.size), start_time_ns=start_ns)


def _campaign(n_runs=3, duration_s=60.0):
    return Campaign([_run(f"r{j}", duration_s, j, 10**18 + j * 10**12) for j in range(n_runs)])


def _degrading_model(campaign):
    base = load_model(None)
    e_total = simulate(base, campaign.t, campaign.force, campaign.slip, campaign.sump,
                       run_start=campaign.run_start).energy_j[-1]
    # mu falls by ~30 % over the campaign: a window started from energy 0 would be far off
    return base.with_mechanisms([make_mechanism("friction_degradation", energy_scale_j=e_total / 0.35),
                                 make_mechanism("actuator_lag", tau_s=0.03),
                                 make_mechanism("actuator_hysteresis", ratio=0.05)])


def test_a_window_from_the_whole_simulations_state_reproduces_it():
    camp = _campaign()
    model = _degrading_model(camp)
    whole = simulate(model, camp.t, camp.force, camp.slip, camp.sump, run_start=camp.run_start)
    # window starts mid-engagement in the second and third runs, and at a run's first row
    starts = [int(np.flatnonzero(camp.run_index == 1)[0]) + 2345, int(np.flatnonzero(camp.run_index == 2)[0]) + 7001,
              int(np.flatnonzero(camp.run_index == 2)[0])]
    windows = [(int(camp.run_index[k]), k, k + 2000) for k in sorted(starts)]
    rows = [k0 for _, k0, _ in windows]
    fp = S.full_pass(model, camp, rows)
    assert np.array_equal(fp.torque_nm, whole.torque_nm)          # chunked = one call, bit for bit
    # no run given a state: the kernel with start states is the plain one
    none = simulate(model, camp.t, camp.force, camp.slip, camp.sump, run_start=camp.run_start,
                    start_index=np.full(camp.t.size, -1), start_states=fp.states)
    assert np.array_equal(none.torque_nm, whole.torque_nm)
    sample, idx = S.sample_campaign(camp, windows, fp.states, warmup_s=1.0)
    assert len(sample.runs) == 3 and np.array_equal(sample.t, camp.t[idx])
    pred = predict_campaign(model, sample)
    np.testing.assert_array_equal(pred.torque_nm, whole.torque_nm[idx])
    # the batch kernel (candidate fits) starts every parameter set from the same states
    other = model.with_friction(a=model.friction_coefficients * 1.02)
    batch = predict_campaign([model, other], sample).torque_nm
    np.testing.assert_array_equal(batch[0], whole.torque_nm[idx])
    assert not np.array_equal(batch[1], batch[0])
    # without the carried state (energy from 0, film and pack reset) the window is far off
    fresh = simulate(model, sample.t, sample.force, sample.slip, sample.sump, run_start=sample.run_start)
    assert np.max(np.abs(fresh.torque_nm - whole.torque_nm[idx])) > 0.1 * np.max(np.abs(whole.torque_nm[idx]))
    # warm-up rows are not scored; the rest of the measured torque is the campaign's
    tq = sample.torque_measured
    for r, sl in sample.slices():
        warm = r.t < r.t[0] + 1.0
        assert np.isnan(tq[sl][warm]).all() and np.isfinite(tq[sl][~warm]).all()
    assert np.array_equal(tq[np.isfinite(tq)], camp.torque_measured[idx][np.isfinite(tq)])


def test_start_states_are_checked():
    camp = _campaign(1, 5.0)
    with pytest.raises(ValueError):
        simulate_batch([load_model(None)], camp.t, camp.force, camp.slip, camp.sump,
                       start_index=np.zeros(3, np.int64), start_states=np.zeros((1, 5)))


def test_windows_span_the_campaign_and_its_operating_range():
    camp = _campaign(n_runs=4, duration_s=150.0)
    model = load_model(None)
    fp = S.full_pass(model, camp, [])
    windows = S.choose_windows(camp, 100.0, fp.pack_temperature_c, fp.power_w)
    assert len(windows) == 10
    # inside one run each, of the window's length, in campaign order, one per stratum of time
    for j, k0, k1 in windows:
        assert (camp.run_index[k0:k1] == j).all()
        assert camp.t[k1 - 1] - camp.t[k0] == pytest.approx(S.WINDOW_S, abs=0.01)
    assert [k0 for _, k0, _ in windows] == sorted(k0 for _, k0, _ in windows)
    # the middle of window i lies in the i-th tenth of the campaign's time (runs end to end)
    dur = camp.runs[0].duration_s
    mids = np.array([j * dur + 0.5 * (camp.t[k0] + camp.t[k1 - 1]) for j, k0, k1 in windows])
    assert np.array_equal(np.floor(mids / (0.4 * dur)), np.arange(10))
    assert set(j for j, _, _ in windows) == {0, 1, 2, 3}
    # the sample covers most of the campaign's force x slip bins (a window per stratum placed
    # where it adds the most)
    labels = S._bin_labels(camp, fp.pack_temperature_c, fp.power_w)["force x slip"]
    rows = np.concatenate([np.arange(k0, k1) for _, k0, k1 in windows])
    common = np.unique(labels, return_counts=True)
    frequent = set(common[0][common[1] > 0.002 * labels.size])
    assert len(frequent & set(np.unique(labels[rows]))) >= 0.8 * len(frequent)


def test_only_campaigns_over_the_budget_are_sampled():
    camp = _campaign(n_runs=2, duration_s=60.0)
    assert S.plan_for(180.0, camp) is False
    assert S.plan_for(100.0, camp) is True
    assert S.plan_for(0.0, camp) is False and S.plan_for(None, camp) is False


def _sampled_diagnosis(tmp_path, spec, budget_s):
    write_campaign(synthesize_campaign(spec), tmp_path / "campaign")
    bags = sorted(str(p) for p in (tmp_path / "campaign" / "bags").iterdir())
    out = tmp_path / "diag"
    rc = cli(["diagnose", "--bench", str(tmp_path / "campaign" / "bench.csv"), "--bags", *bags,
              "--out", str(out), "--mc-samples", "20", "--sample-budget-s", str(budget_s), "--no-progress",
              "--candidates", "actuator_lag", "spring_preload", "friction_degradation", "transport_delay"])
    assert rc == 0
    rep = json.loads((out / "report.json").read_text())
    smp = rep["diagnosis_sample"]
    assert smp["sampled"] and smp["budget_s"] == budget_s and len(smp["windows"]) == budget_s // S.WINDOW_S
    assert smp["sampled_s"] <= budget_s and smp["rows"]["sample"] < smp["rows"]["campaign"]
    # the held-out data are whole windows, none of them fitted
    assert set(rep["held_out_runs"]) <= set(smp["windows"]) and set(rep["fit_runs"]) <= set(smp["windows"])
    assert not set(rep["held_out_runs"]) & set(rep["fit_runs"]) and len(rep["held_out_runs"]) >= 2
    # moved off the windows with the bench model's extreme pack temperature, as whole runs are
    assert rep["split"].startswith("whole windows") and "pack temperature" in rep["split"]
    return rep, smp


def test_a_sampled_campaign_still_names_a_hidden_lag(tmp_path):
    """4 runs of 25 s (100 s) with a hidden actuator lag of 80 ms, diagnosed on 6 windows of
    10 s under a 60 s budget, windows starting mid-run from the whole simulation's state: the
    lag is named with its value."""
    spec = CampaignSpec(seed=834, n_runs=4, run_duration_s=25.0, n_requests=8, mechanism="actuator_lag",
                        magnitude=0.08)
    rep, smp = _sampled_diagnosis(tmp_path, spec, 60.0)
    labels = [parse_held_out(w) for w in smp["windows"]]
    assert any(h.t0 > 0 for h in labels)                                   # windows inside runs
    for a in labels:                                                       # that never overlap
        assert all(a == b or a.run != b.run or a.t1 <= b.t0 or b.t1 <= a.t0 for b in labels)
    assert rep["cause"]["id"] == "actuator_lag", rep["cause"]["evidence"]
    assert rep["cause"]["parameters"]["tau_s"] == pytest.approx(0.08, rel=0.1)
    assert rep["gain_pct"] > 20.0


def test_a_sampled_campaign_still_names_friction_degradation(tmp_path):
    """12 runs of 9 s with friction falling by 12 % over the campaign with its dissipated
    energy, diagnosed on 6 of them under a 60 s budget: each window starts from the energy the
    whole campaign's simulation has there, so the degradation is named and its energy scale
    is recovered (95 % interval holding the truth)."""
    import yaml

    spec = CampaignSpec(seed=832, n_runs=12, run_duration_s=9.0, mechanism="friction_degradation")
    rep, smp = _sampled_diagnosis(tmp_path, spec, 60.0)
    truth = yaml.safe_load((tmp_path / "campaign" / "truth.yaml").read_text())
    true_scale = next(m["energy_scale_j"] for m in truth["mechanisms"] if m["id"] == "friction_degradation")
    assert rep["cause"]["id"] == "friction_degradation", rep["cause"]["evidence"]
    lo, hi = rep["cause"]["parameters_ci95"]["energy_scale_j"]
    assert lo <= true_scale <= hi
    assert rep["cause"]["parameters"]["energy_scale_j"] == pytest.approx(true_scale, rel=0.05)


@pytest.mark.parametrize("bad", ["x", "-5", "inf"])
def test_a_bad_sample_budget_is_a_one_line_error(tmp_path, capsys, bad):
    rc = cli(["diagnose", "--bench", str(tmp_path / "b.csv"), "--bags", str(tmp_path / "r"), "--out",
              str(tmp_path / "o"), "--sample-budget-s", bad])
    err = capsys.readouterr().err.strip()
    assert rc != 0 and "--sample-budget-s" in err and len(err.splitlines()) == 1


def test_given_held_out_spans_apply_to_the_windows_row_by_row():
    """--held-out on a sampled campaign: the given bags / spans, in the bags' own time, decide
    which window rows are held out (diagnose maps each window row to its bag)."""
    from clutch_model.diagnosis.split import choose_split

    camp = _campaign(n_runs=3, duration_s=60.0)
    fp = S.full_pass(load_model(None), camp, [])
    windows = S.choose_windows(camp, 90.0, fp.pack_temperature_c, fp.power_w)
    starts = [k0 for _, k0, _ in windows]
    sample, idx = S.sample_campaign(camp, windows, S.full_pass(load_model(None), camp, starts).states)
    split = choose_split(camp.runs, ["r1", "r2[20:40]"])
    fit, held = split.masks(camp.names, S.source_index(sample, camp.names), sample.t)
    src = camp.run_index[idx]
    expect = (src == 1) | ((src == 2) & (sample.t >= 20.0) & (sample.t < 40.0))
    assert held.any() and fit.any()
    assert not (held & ~expect).any()                    # nothing held out that was not given
    assert not (fit & expect).any()                      # nothing given is fitted
    # only the guard (0.25 s after each change between held-out and fitted rows) is neither
    assert (~held & ~fit).sum() < 0.05 * sample.t.size


# --- windows started again from the states of the model a first diagnosis came to ----------

def _restart_case(causes=(), verdict="named", best_significant=True, sampled=True, extended=5.0,
                  mechanisms=("spring_preload",), held_out=("run_000[25:35]",)):
    from types import SimpleNamespace

    from clutch_model.plant.params import load_model

    from clutch_model.plant.mechanisms import make_mechanism

    values = {"spring_preload": {"preload_n": 300.0}, "torque_offset": {"offset_nm": 2.0}}
    model = load_model(None).with_mechanisms([make_mechanism(m, **values[m]) for m in mechanisms])
    best = SimpleNamespace(significant=best_significant, fitted=SimpleNamespace(model=model))
    sel = SimpleNamespace(causes=list(causes), verdict=verdict, final=SimpleNamespace(model=model),
                          steps=[SimpleNamespace(scores=[best])], closest=[], closest_leaves={})
    return SimpleNamespace(causes=[{"id": c} for c in causes], selection=sel, held_out=list(held_out),
                           rmse={"extended": extended}, diagnosis_sample={"sampled": sampled}, inputs={},
                           candidates=[], cause_id=causes[0] if causes else verdict)


def test_the_windows_start_again_only_from_a_plant_cause_of_a_sampled_diagnosis():
    """engine._window_state_model: a sampled diagnosis naming a cause on the plant's paths, or
    ending unexplained with its first step's best candidate significant and on the plant; never a
    `none`, a measurement mechanism alone, a whole-campaign diagnosis or a second restart."""
    from clutch_model.diagnosis.engine import _window_state_model

    model, ids = _window_state_model(_restart_case(causes=["spring_preload"]))
    assert ids == ["spring_preload"] and [m.id for m in model.mechanisms] == ["spring_preload"]
    assert _window_state_model(_restart_case(verdict="unexplained")) is not None
    assert _window_state_model(_restart_case(verdict="unexplained", best_significant=False)) is None
    assert _window_state_model(_restart_case(verdict="none")) is None
    assert _window_state_model(_restart_case(causes=["torque_offset"], mechanisms=("torque_offset",))) is None
    assert _window_state_model(_restart_case(causes=["spring_preload"], sampled=False)) is None
    again = _restart_case(causes=["spring_preload"])
    again.diagnosis_sample["restarted_from"] = ["spring_preload"]
    assert _window_state_model(again) is None


@pytest.mark.parametrize("restarted_rmse,kept", [(4.0, True), (4.95, False)])
def test_the_restarted_diagnosis_is_kept_only_when_it_predicts_the_held_out_rows_better(monkeypatch, restarted_rmse,
                                                                                        kept):
    """diagnose_campaign: the second diagnosis (windows from the first one's model) is kept when
    it names its causes and predicts the same held-out rows 2 % better; its stages then reach the
    writer after the first one's, else the first one's report is written again."""
    import clutch_model.diagnosis.engine as engine

    first = _restart_case(verdict="unexplained", extended=5.0)
    second = _restart_case(causes=["spring_preload"], extended=restarted_rmse)
    calls = []

    def fake(nominal, bench_model, campaign, checkpoint=None, window_states=None, input_reading=None, **kw):
        calls.append(None if window_states is None else window_states[1])
        d = first if window_states is None else second
        checkpoint("selected", diagnosis=d)
        return d

    from clutch_model.formats.bag_reader import Campaign, Run

    monkeypatch.setattr(engine, "_diagnose_readings", fake)
    monkeypatch.setattr(engine, "_diagnose_reading", fake)
    t = np.arange(0.0, 1.0, 0.005)
    run = Run("run_000", t, np.full(t.size, 3000.0), np.full(t.size, 5.0), np.full(t.size, 60.0),
              torque_measured_nm=np.full(t.size, 100.0))
    written = []
    got = engine.diagnose_campaign(None, None, Campaign([run]), checkpoint=lambda stage, **out: written.append(out["diagnosis"]))
    assert calls == [None, ["spring_preload"]]
    assert got is (second if kept else first)
    assert got.diagnosis_sample["restarted_from"] == ["spring_preload"]
    assert got.diagnosis_sample["restart_kept"] is kept
    assert written == ([first, second] if kept else [first, first])


def test_a_restart_names_what_the_first_left_open_only_near_the_noise():
    """engine._restarted_better: where the first diagnosis named nothing, the restarted one is
    kept only when what its causes leave on the held-out rows is within RESTART_NOISE_FACTOR
    times the first's noise innovation sd (a slow misfit the remainder test's noise model
    forecasts passes for noise); where the first named causes, the 2 % bar alone decides."""
    from clutch_model.diagnosis.engine import RESTART_NOISE_FACTOR, _restarted_better

    first = _restart_case(verdict="unexplained", extended=32.4)
    first.noise = {"innovation_sigma_nm": 0.65}
    far = _restart_case(causes=["spring_preload"], extended=17.8)
    near = _restart_case(causes=["spring_preload"], extended=0.9 * RESTART_NOISE_FACTOR * 0.65)
    assert not _restarted_better(first, far)[0]
    assert _restarted_better(first, near)[0]
    named = _restart_case(causes=["spring_preload"], extended=32.4)
    named.noise = {"innovation_sigma_nm": 0.65}
    assert _restarted_better(named, far)[0]
    assert not _restarted_better(named, _restart_case(causes=["spring_preload"], extended=32.0))[0]
