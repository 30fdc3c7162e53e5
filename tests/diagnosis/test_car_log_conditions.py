"""Hidden-effect tests on car-log data, one small campaign per condition class.

Each campaign comes from the car-log virtual test car (clutch_model/virtual_car/hidden_campaigns.py)
with the hidden magnitudes drawn from a seed the diagnosis never sees; `clutch-sim diagnose`
runs as a subprocess on the bags only, and `clutch-sim replay` of both written models is
scored on later bags of the same true clutch that diagnose never saw, against the noise-free
true torque. A test asserts the set of named causes (`none` where there is nothing,
`unexplained` for an effect outside the catalog, never a catalog name for it), and where a
cause is named that the extended model's error on the unseen bags is below the calibrated
model's (and the parameter is the hidden one); where nothing is named the extended model is
the calibrated one.

The fast set (9 campaigns + harness checks) took 4.5 min with the diagnosis of main and 6 min
with the statistics rewrite in progress, on this 2-core machine under a load average of 7-8
(15-20 s CPU per diagnose); 13.5 min with the issue-9 fixes under a load average of 10-15;
heavier samples are marked slow.
CLUTCH_HIDDEN_SEED=<int> draws other magnitudes. bench/bench_diagnose_matrix.py runs the whole
matrix (every mechanism, pairs, lookalikes x every condition x seeds).
"""
import csv
import json
import os

import numpy as np
import pytest

from clutch_model.diagnosis.bench_anchor import BENCH_GAP_FAR
from clutch_model.plant.mechanisms import CATALOG
from clutch_model.virtual_car.car_logs import EFFECTS
from clutch_model.virtual_car.hidden_campaigns import (CONDITIONS, Case, check_campaign, judge,
                                                        make_hidden_campaign, named_causes,
                                                        run_clutch_sim, score_replay_csv)

HIDDEN_SEED = int(os.environ.get("CLUTCH_HIDDEN_SEED", "20261123"))
MC_SAMPLES = 40          # Monte Carlo samples of the car calibration (CI budget)

# (condition, case, campaign seed): one per condition class, small campaigns
# (4 runs x 8 s seen + 2 unseen; one 40 s bag + 1 unseen; 2 x 20 s + 1 unseen)
FAST = [
    ("unaligned", "none", 31),                       # topics on own clocks: no false transport_delay
    ("gateway", "none", 2),                          # the torque stamped on arrival (torque_clock)
    ("bursts", "none", 1),                           # force and torque forwarded in bursts (receive_bursts)
    ("ar1", "none", 32),                             # AR(1) phi 0.95 noise is not structure
    ("lowpass", "none", 33),                         # band-limited noise is not structure
    ("lockup", "spring_preload", 34),                # lock phases kept out
    ("long_drive", "actuator_lag", 35),              # one bag: split into time spans
    ("few_long", "transport_delay", 36),             # few long runs
    ("unaligned", "torque_sensor_lowpass", 38),      # lookalike of actuator_lag: torque_sensor_lag
    # a slow sensor drift (OU, 36 s) over two 30 s runs, time spans held out, alone read
    # `unexplained` (its lag twin is in SLOW, below)
    ("slow_drift", "none", 1),
    # a 70 ms actuator lag under 10 Hz band-limited torque noise: the model's slip noise made a
    # torque-sensor lag win the whitened comparisons (t = 693 against 37, a wrong name) until the
    # noise models were floored at the model's own noise and the slip smoothed (input_hold)
    ("lowpass", "actuator_lag", 1),
    # a 27 ms transport delay with drag under torque noise held at 10 Hz: without drag in the
    # model the delay fitted 14 ms, a torque-sensor lag led the first step and drag on top of it
    # fell short (t = 3.2): the lag alone was named (a wrong name) until the other first-step
    # candidates were each tried as the first of two (drag + a 26 ms delay)
    ("held", "transport_delay+drag_torque", 1),
    # a 15.3 N*m torque offset under torque noise held at 10 Hz: the other-first look-ahead put a
    # friction degradation beside it that won the one held-out run (t = 4.2) but fitted the
    # training runs no better (log-likelihood -4.1); backward elimination now asks for both
    ("held", "torque_offset", 3),
    # a reversible slip-power fade under 10 Hz band-limited noise: the calibration absorbed most
    # of it and a 5.4 N*m torque offset was named (a wrong name) until discovery was run on top
    # of the named causes (it found the fade, and the offset did not hold on top of the fade)
    ("lowpass", "slip_power_fade", 3),
    # a 6.5 % once-per-revolution ripple (phase per run) under 10 Hz band-limited noise: the AR
    # noise model forecast the ripple from its own past, the whitened per-run test gave t = 2.5
    # and the answer was `none` until the per-run cross-fit was also scored in plain squares
    # (cut 78 %, t = 4.9 over 32 blocks) -> unexplained
    ("lowpass", "torque_ripple", 3),
    # a friction level drawn per run (spread 9 %) under 10 Hz band-limited noise: the whitened
    # pieces scattered by 5 standard errors within a run (F = 3.2, `none`) until the pieces were
    # also fitted unweighted (F = 29.6) -> unexplained
    ("lowpass", "run_friction_level", 3),
    # the same level on the car (two 20 s runs, time spans held out): μ_f rising with the energy
    # dissipated so far fitted the two runs' levels, was named `discovered` (t = 26) and failed
    # on the unseen bags (-25 %) until an extension in the energy alone needed a whole run held out
    ("car", "run_friction_level", 2),
    # a slew-rate-limited actuator (43 kN/s): only the held-out run has force steps fast enough
    # for the limit to bite (held-out RMSE 28 N*m, the training runs at the noise's 8), so
    # nothing fitted on the training runs predicts it; it read `none` until one held-out run
    # was set against the training runs' spread (held_out_excess_test) -> unexplained
    ("lab", "actuator_rate_limit", 1),
    # the slip changes sign while slipping: a model given the sampled slip times each flip of
    # the friction torque only to a slip sample, and with those rows compared a drag of
    # 0.63 N*m/(rad/s) was named beside an 18 % hysteresis (a wrong second cause) until the
    # rows around each zero crossing were left out (lockup.LockupResult.crossings)
    ("sign_changes", "actuator_hysteresis", 1),
    # Back from the slow set at stop 48 (one numba and one BLAS thread per xdist worker took
    # `make test` from 26.6 to 15.4 min):
    # no cause on the car condition (a negligible hysteresis was once named here)
    ("car", "none", 44),
    # a 70 ms actuator lag under AR(1) 0.95 noise: torque_sensor_lag leads on the gain but loses
    # head to head (p = 0.0002); without the head-to-head rule this read `unexplained`
    ("ar1", "actuator_lag", 1),
    # a 70 ms actuator lag with friction degradation under AR(1) 0.95 noise: the degradation's
    # twin (its friction kept, the mechanism taken out) fitted the early held-out run as well as
    # it (`unexplained`) until the twin became the friction refitted alone
    ("ar1", "actuator_lag+friction_degradation", 1),
    # one drive cut into consecutive bags by a recorder rolling over: each bag restarted, the
    # pack at 150 degC at a roll-over read as a friction level jumping from bag to bag
    # (`unexplained` with nothing hidden) until such bags were joined (continued_bags.py)
    ("rollover", "none", 1),
    ("rollover", "actuator_lag", 1),
    # a logger pause of 1-3 s in every bag diagnose sees (logger_pause.py); at magnitude seed
    # 7001 the preload read `unexplained` with the rows after the pauses compared
    ("pause", "spring_preload", 2),
]
SLOW = [
    ("clipped", "spring_preload", 2),     # CI samples the class: test_a_saturated_torque_sensor_is_found_and_left_out
    ("held", "none", 41),
    ("median", "none", 42),
    ("drift", "none", 43),
    ("car", "actuator_hysteresis", 45),
    ("lab", "actuator_lag+friction_degradation", 46),
    ("lockup", "transport_delay+drag_torque", 47),
    ("few_long", "friction_degradation", 48),
    ("lab", "run_friction_level", 49),
    ("unaligned", "torque_ripple", 50),
    ("car", "torque_sensor_lowpass", 51),
    ("long_drive", "none", 52),
    # a 1 s fade, its unseen run 13 degC colder than any fit row: the fitted time constant and
    # the friction correction held outside the fit rows' range (-38 % on unseen bags before)
    ("held", "slip_power_fade", 1),
    # Two former misses, moved here from the CI set to keep `make test` near 20 minutes (the
    # look-ahead step and the twin refitted alone keep their unit tests in test_selection.py):
    # a 468 N preload and a 35 N*m offset under 10 Hz band-limited noise: neither alone beats
    # the noise model fitted to what it leaves (the other's slow misfit is forecast from its own
    # past), so the first step named nothing (`none`) until the look-ahead step
    ("lowpass", "spring_preload+torque_offset", 1),
    # Three more, moved here at stop 38 (`make test` had grown to 22 min): each keeps a CI twin.
    # Two causes at once: ("held", "transport_delay+drag_torque", 1); the fade lookalike:
    # ("lowpass", "slip_power_fade", 3); the slow drift: ("slow_drift", "none", 1) and the
    # drift noise classes of test_structure_test.py.
    ("lab", "spring_preload+torque_offset", 37),
    ("lab", "slip_power_fade", 39),
    # a 67 ms actuator lag under a slow sensor drift (OU, 36 s) over two 30 s runs, time spans
    # held out: slow library columns followed the drift across neighbouring spans and left
    # "structure" after the lag (t = 6.2, `unexplained`) until the plain remainder fit's noise
    # model came from its cross-fitted residual and had to beat the null's own noise model too
    ("slow_drift", "actuator_lag", 1),
]
# Measured on the slow set (2026-11-24, diag-none; 9 of 12 pass). Misses, with the reason:
SLOW_MEASURED_MISSES = {
    # fixed: ("car", "none", 44) named a negligible actuator_hysteresis (ratio 0.0012, t = 4.1):
    # its gain over its mechanism-free twin (the same fit, friction refitted with it) is 0.03 %
    # of the plain held-out mean square -> none
    # fixed: ("lockup", "transport_delay+drag_torque", 47) -- a 150 ms delay (+ drag) was read as
    # transport_delay alone at 113 ms: lock phases were padded 0.1 s, less than the delay, so each
    # lock phase's delayed driveline torque was compared with the model after it. A named delay or
    # sensor lag now widens the lock tail and the campaign is diagnosed again (test_lock_tail.py);
    # the pad is 0.2 s (next to a lock the small slip's sensor noise sets the model's sign)
    # a friction level drawn per run: nothing in the inputs predicts it, and one 8 s held-out
    # run gives the held-out-excess test (Welch t over stretches) a single stretch -> none. A
    # per-run level column was measured and not shipped: 9 of 11 conditions found at full size,
    # but false alarms on ("drift", "none", 43) and none@lockup#1 (docs/diagnosis_statistics.md)
    ("lab", "run_friction_level", 49): "missed: none (no input predicts a per-run level)",
    # fixed: ("car", "torque_sensor_lowpass", 51) -- torque_sensor_lag and actuator_lag could not
    # be told apart (unexplained) while the sensor's lagged lock torque after each lock phase was
    # scored; with the lock tail of the closest lookalike left out, torque_sensor_lag (70 ms, true 72)
}


def _check(tmp_path, condition, case, seed):
    camp = make_hidden_campaign(case, condition, seed, tmp_path / "campaign",
                                magnitude_seed=HIDDEN_SEED, quick=True)
    res = check_campaign(camp, tmp_path, mc_samples=MC_SAMPLES, stamps=False)
    evidence = (res.report or {}).get("cause", {}).get("evidence", res.error)
    what = (f"{case} under {condition} (hidden {camp.spec.mechanisms or camp.spec.effects}): expected "
            f"{camp.expected_label}, diagnose said {res.named_label}: {evidence}")
    assert res.verdict not in ("refused", "error", "timeout"), what
    # diagnosed with --no-plots: the report without figures
    assert "<img" not in (tmp_path / "diag" / "report.html").read_text() and not list((tmp_path / "diag").glob("*.png"))
    assert res.judgement == "ok", what
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    if res.named:
        # the gain holds on bags diagnose never saw, against the true torque
        assert ext < cal, f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"
        causes = (res.report.get("causes") or [res.report["cause"]])
        hidden = [dict(m) for m in camp.spec.mechanisms if m["id"] != "friction_degradation"]
        hidden += [{"id": EFFECTS[e["name"]]["catalog_equivalent"], **{k: v for k, v in e.items() if k != "name"}}
                   for e in camp.spec.effects if EFFECTS[e["name"]]["catalog_equivalent"] in CATALOG]
        for mech in hidden:     # the fitted parameter is the hidden one, within 30 %
            got = next(c for c in causes if c["id"] == mech["id"])
            (name,) = [k for k in mech if k != "id"]
            assert got["parameters"][name] == pytest.approx(mech[name], rel=0.3), what
    elif res.verdict == "discovered":
        # a term beyond the catalog: its gain holds on the unseen bags against the true torque,
        # and for slip-power fade mu_f / (1 + k P_slip) (low-passed) the slip-power terms sum to -k
        assert ext < cal, f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"
        terms = res.report["cause"]["parameters"]
        for effect in camp.spec.effects:
            if effect["name"] == "slip_power_fade":
                fade = sum(v for k, v in terms.items() if k.startswith("mu:slip_power"))
                assert fade == pytest.approx(-effect["k_per_kw"], rel=0.3), what
    else:
        # none / unexplained: the extended model is the calibrated one
        assert ext == pytest.approx(cal, rel=1e-9), what
    return res


# Cells that once read a wrong name, at the magnitudes that did (drawn from magnitude seed
# 20261126): the answer may miss (`unexplained`, one of two causes) but never name wrongly,
# nor restate the hidden catalog mechanism as an extension beyond the catalog (`discovered`).
NEVER_WRONG = [
    # a 3.48 N*m/(rad/s) drag under AR(1) 0.95 noise: the catalog drag fell short (t = 3.2) and
    # discovery named "the torque gains 3.07 N*m per rad/s of signed slip" (the drag without its
    # viscosity factor) until the extension met the catalog's candidates as lookalikes
    pytest.param("ar1", "drag_torque", 1, {"drag_torque": 3.476276203055645}, id="ar1-drag_torque"),
    # a 60 ms delay with a 3.35 drag on the car: an actuator hysteresis of ratio 0.0023 (a 7 N
    # band against 20 N force noise) was named as a third cause until bands on the force had
    # to be wider than twice its noise
    pytest.param("car", "transport_delay+drag_torque", 1,
                 {"transport_delay": 0.05970713754093431, "drag_torque": 3.345556926785983},
                 marks=pytest.mark.slow, id="car-transport_delay+drag_torque"),    # a slew-rate-limited actuator (43 kN/s) on the car, outside the catalog: an 11 ms transport
    # delay (t = 5.4) was named, better on 2 of 4 held-out spans and worse on the others, with a
    # fade found on top; on the unseen run it made the model worse (7.8 -> 15.2 N*m) until a
    # cause's gain over its twin had to hold on most held-out pieces
    pytest.param("car", "actuator_rate_limit", 1, {"actuator_rate_limit": 43229.06250592479},
                 marks=pytest.mark.slow, id="car-actuator_rate_limit"),
]


@pytest.mark.parametrize("condition,case,seed,magnitudes", NEVER_WRONG)
def test_car_log_condition_never_wrong(tmp_path, condition, case, seed, magnitudes):
    camp = make_hidden_campaign(case, condition, seed, tmp_path / "campaign", magnitudes=magnitudes, quick=True)
    res = check_campaign(camp, tmp_path, mc_samples=MC_SAMPLES, stamps=False)
    evidence = (res.report or {}).get("cause", {}).get("evidence", res.error)
    what = f"{case} under {condition}: diagnose said {res.named_label}: {evidence}"
    assert res.judgement in ("ok", "missed", "partial"), what
    assert res.verdict != "discovered", what        # a catalog mechanism restated beyond the catalog
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    assert ext <= cal * (1 + 1e-9), f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"


def _diagnosed(tmp_path, case, condition, seed, magnitudes):
    """A quick campaign at fixed hidden magnitudes, diagnosed and replayed -> (result, what it said)."""
    camp = make_hidden_campaign(case, condition, seed, tmp_path / "campaign", magnitudes=magnitudes, quick=True)
    res = check_campaign(camp, tmp_path, mc_samples=MC_SAMPLES, stamps=False)
    return res, f"diagnose said {res.named_label}: {(res.report or {}).get('cause', {}).get('evidence', res.error)}"


# An actuator with inertia (a second-order force path, damping 0.7) is outside the catalog: a
# transport delay of its group delay matches it to second order in frequency, the remainder after
# the delay read as noise and the delay was named (a wrong name, +66-82 % on the unseen bags, on
# lab#2, ar1#2, car#2 and lab#3 of the matrix) until a named time mechanism had to beat a
# second-order force path fitted in its place (diagnosis/force_dynamics.py).
@pytest.mark.parametrize("condition,seed,f_n_hz", [("lab", 2, 3.35), pytest.param("ar1", 2, 3.35, marks=pytest.mark.slow)])
def test_second_order_actuator_is_not_named_a_catalog_time_mechanism(tmp_path, condition, seed, f_n_hz):
    res, what = _diagnosed(tmp_path, "actuator_second_order", condition, seed, {"actuator_second_order": f_n_hz})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["force_path_check"]
    assert check["took_the_name"] and check["in_place_of"], check
    # the rival recovers the true force path (f_n within 10 %, damping 0.7 within 0.1)
    assert check["parameters"]["f_n_hz"] == pytest.approx(f_n_hz, rel=0.10), check
    assert check["parameters"]["damping"] == pytest.approx(0.7, abs=0.1), check
    assert check["held_out_rmse"] < check["named_held_out_rmse"], check


# Gear or linkage backlash (a play of constant half-width, 333 N) is outside the catalog: the
# catalog's hysteresis band F(1 +- ratio) grows with the force. On the car the band was named
# (ratio fitted to the typical force, a wrong name); under torque noise held at 10 Hz the
# calibration absorbed part of the play into the friction, a band fitted on top only added error,
# and the answer read `none` (the calibrated model 32 N*m off the true torque on the unseen
# runs). A named band now meets a play of constant width fitted in its place, and where nothing
# is named the play is fitted on the calibrated model (diagnosis/force_dynamics.py).
@pytest.mark.parametrize("condition,named_before", [("car", True), ("held", False)])
def test_constant_width_backlash_is_not_named_the_catalog_hysteresis(tmp_path, condition, named_before):
    half_width = 333.31653521427467
    res, what = _diagnosed(tmp_path, "actuator_backlash", condition, 1, {"actuator_backlash": half_width})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["force_band_check"]
    assert check["took_the_name"], check
    assert (check.get("in_place_of") == ["actuator_hysteresis"]) == named_before, check
    assert check["parameters"]["half_width_n"] == pytest.approx(half_width, rel=0.2), check
    # the play leaves less than half the held-out error of the model without it (named band or
    # calibrated), near the sensor noise (8 N*m; held at 10 Hz, timing adds to it)
    without = check.get("named_held_out_rmse", check.get("calibrated_held_out_rmse"))
    assert check["held_out_rmse"] < min(0.5 * without, 15.0), check


# A force sensor that reads the pack force through a play of 337 N (mechanical hysteresis in the
# sensor: the log trails the pack force, the pack force leads the log) is outside the catalog,
# whose band can only trail; nothing was named under 12 of 13 conditions of the matrix, and on
# the lab the slip-power terms discovery named made the unseen runs 16 % worse, until the pack
# force leading the log by a play was fitted where nothing is named and against a discovered
# extension (diagnosis/force_dynamics.py, none_or_sensor_play).
def test_a_force_sensor_play_is_not_named_or_discovered(tmp_path):
    half_width = 336.9363287446416
    res, what = _diagnosed(tmp_path, "force_sensor_hysteresis", "unaligned", 1,
                           {"force_sensor_hysteresis": half_width})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["force_band_check"]
    check = check.get("force_sensor_play", check)
    assert check["kind"] == "force sensor play" and check["took_the_name"], check
    assert check["parameters"]["half_width_n"] == pytest.approx(half_width, rel=0.2), check
    assert check["held_out_rmse"] < 0.6 * check["calibrated_held_out_rmse"], check


# A judder (the torque oscillating at 10 Hz, 4 % of it at zero slip and less as the slip grows)
# is outside the catalog: its phase is no function of the inputs, so the flexible residual model
# cannot predict it, and a long noise model forecasts it from its own past; an outside generator's
# 9.8 Hz judder read `none`. Where nothing is named, a spectral line in the calibrated residual
# whose power the inputs predict on held-out rows reads `unexplained` (diagnosis/torque_line.py).
def test_a_judder_is_not_read_as_noise(tmp_path):
    res, what = _diagnosed(tmp_path, "torque_judder", "car", 1, {"torque_judder": 0.04})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["torque_line_check"]
    assert check["took_the_name"], check
    assert check["frequency_hz"] == pytest.approx(10.0, abs=0.5), check
    assert check["envelope_mean_square_cut"] > 0.5, check
    assert "torque_line" in res.report["selection"]["closest_leaves"], res.report["selection"]["closest_leaves"]


# Every value logged in steps (slip 0.01 rad/s with 0.004 rad/s of noise, below one step): a
# locked clutch's slip reads exact zeros with a stray +-0.01, the slip noise estimate collapsed to
# nothing and every stray step broke the lock phases (2 % of the locked slip samples found, an
# outside generator's campaigns read `none` or named the wrong pair) until the estimate was
# floored at the step's quantisation noise (lockup.slip_quantum): all found, the lag named.
def test_lock_phases_are_found_on_a_slip_logged_in_steps(tmp_path):
    res, what = _diagnosed(tmp_path, "actuator_lag", "quantised", 2, {"actuator_lag": 0.088})
    assert res.named == ["actuator_lag"], what
    assert res.report["locked_rows"] > 500, res.report["locked_rows"]    # 613 of the 1600 torque rows, padded
    tau = res.report["causes"][0]["parameters"]["tau_s"]
    assert tau == pytest.approx(0.088, rel=0.15), tau


# A torque sensor saturating at 0.8 of the campaign's peak torque reads its limit beyond it: the
# calibration was fitted to the pinned readings (held-out RMSE 58.0 N*m under 8 N*m of noise) and
# an outside generator's campaign with nothing hidden (clipped at 78 % of its peak) read
# `unexplained` until the readings on a rail were found and left out (diagnosis/torque_range.py).
def test_a_saturated_torque_sensor_is_found_and_left_out(tmp_path):
    res, what = _diagnosed(tmp_path, "none", "clipped", 1, {})
    assert res.verdict == "none", what
    rail = json.loads((tmp_path / "campaign" / "truth.json").read_text())["sensor_range"]["measured_torque"]["rail"]
    found = res.report["inputs"]["torque_rails_nm"]
    assert found and all(abs(abs(r) - rail) < 1e-6 * rail for r in found), (found, rail)
    assert res.report["inputs"]["torque_samples_at_rails"] > 10
    assert res.report["rmse_nm"]["calibrated"] < 1.5 * 8.0, res.report["rmse_nm"]    # the noise, 8 N*m


# A resonant torque sensor (second order, 6.1 Hz, damping 0.3) is outside the catalog: a first-order
# sensor lag takes its group delay and what it leaves, the ringing, a long noise model forecasts
# from its past; an outside generator's 6.6 Hz sensor was named torque_sensor_lag (the unseen bags
# 54.8 -> 48.0 N*m) until a named lag or delay on the measurement had to beat a second-order torque
# reading fitted in its place (diagnosis/force_dynamics.py, named_or_sensor_dynamics).
def test_a_resonant_torque_sensor_is_not_named_a_sensor_lag(tmp_path):
    # the matrix's cell (magnitude seed 20261202: 6.07 Hz)
    camp = make_hidden_campaign("torque_sensor_resonance", "held", 2, tmp_path / "campaign",
                                magnitude_seed=20261202, quick=True)
    res = check_campaign(camp, tmp_path, mc_samples=MC_SAMPLES, stamps=False)
    what = f"diagnose said {res.named_label}: {(res.report or {}).get('cause', {}).get('evidence', res.error)}"
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["lag_rival_checks"]["second_order_torque_reading"]
    assert check["took_the_name"] and check["resonant"], check
    assert check["parameters"]["f_n_hz"] == pytest.approx(6.0726, rel=0.1), check
    assert check["parameters"]["damping"] == pytest.approx(0.3, abs=0.1), check
    assert check["held_out_rmse"] < check["named_held_out_rmse"], check


# A force sensor reading 389 N low is outside the catalog (read high it would be spring_preload):
# on the car the calibration absorbed most of it, nothing was named, and the bench anchor then
# named a 43.5 N*m torque offset on the bench friction (a wrong name; 24.3 -> 16.2 N*m on the
# unseen runs) until a signed offset on the measured force was fitted where nothing is named and
# in place of every named cause (diagnosis/force_dynamics.py). At campaign seed 3 (624 N low)
# torque_offset was named (70 N*m) and the offset on the force in its place was better on both
# counts, each at 5 % but neither at the rival's first two bars: the innovations at t = 2.9
# (-18 %), the plain held-out mean square -44 % at p = 0.03 (force_dynamics.rival_takes_the_name,
# its third way since stop 56).
@pytest.mark.parametrize("seed,offset", [(1, 388.6939341366807), (3, 623.7740378055598)])
def test_a_force_sensor_offset_is_not_named_a_catalog_mechanism(tmp_path, seed, offset):
    res, what = _diagnosed(tmp_path, "force_sensor_offset", "car", seed, {"force_sensor_offset": offset})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["force_offset_check"]
    assert check["took_the_name"], check
    assert check["parameters"]["offset_n"] == pytest.approx(offset, rel=0.2), check
    without = check.get("named_held_out_rmse", check.get("calibrated_held_out_rmse"))
    assert check["held_out_rmse"] < 0.8 * without, check


# An actuator that applies fast and releases slowly (a first-order lag of 40 ms applying, 239 ms
# releasing) is outside the catalog, whose lags have one time constant: over one 40 s drive the
# catalog named torque_sensor_lag (a wrong name, +52 % on the unseen bag; also on ar1#1, car#1,
# and actuator_lag on unaligned#1 of the matrix) until a named time mechanism had to beat an
# asymmetric lag on the force path fitted in its place (diagnosis/lag_rivals.py).
def test_an_asymmetric_actuator_lag_is_not_named_a_catalog_time_mechanism(tmp_path):
    tau_release = 0.23860788602090102
    res, what = _diagnosed(tmp_path, "actuator_asymmetric_lag", "long_drive", 1,
                           {"actuator_asymmetric_lag": tau_release})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["lag_rival_checks"]["asymmetric_lag"]
    assert check["took_the_name"] and check["in_place_of"], check
    # the rival recovers both time constants (the apply one is the effect's default, 40 ms)
    assert check["parameters"]["tau_apply_s"] == pytest.approx(0.04, rel=0.2), check
    assert check["parameters"]["tau_release_s"] == pytest.approx(tau_release, rel=0.2), check
    assert check["held_out_rmse"] < 0.5 * check["named_held_out_rmse"], check


# A force that reaches the pack 30 ms late by a pure delay (the slip and the reading on time) is
# outside the catalog, whose transport_delay reads the whole torque late. Under lock-up phases
# transport_delay was named (held-out t = 166); the force delay fitted in its place (28 ms) beat
# it head to head at t = 5.1 (diagnosis/lag_rivals.py; an outside generator's 18.3 ms force delay
# had been named transport_delay at 22.8 ms, 12.8 N*m off the true torque on the unseen runs).
def test_a_pure_force_delay_is_not_named_a_transport_delay(tmp_path):
    res, what = _diagnosed(tmp_path, "actuator_force_delay", "lockup", 1, {"actuator_force_delay": 0.03})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["lag_rival_checks"]["force_delay"]
    assert check["took_the_name"] and check["in_place_of"] == ["transport_delay"], check
    assert check["parameters"]["delay_s"] == pytest.approx(0.03, rel=0.15), check
    assert check["held_out_rmse"] < check["named_held_out_rmse"], check


# An actuator whose force stops at a ceiling (64 % of the campaign's largest request) is outside
# the catalog. On the lab condition the calibration absorbed what it could and the answer was
# `none` (the unseen runs 77.7 N*m off the true torque); the ceiling fitted on the calibrated
# model takes the name (force_ceiling.py; an outside generator's 73 % ceiling under a 108 Hz
# dither had been named torque_sensor_lag).
def test_a_ceiling_on_the_pack_force_is_found_beyond_the_catalog(tmp_path):
    share = 0.639
    res, what = _diagnosed(tmp_path, "actuator_force_ceiling", "lab", 1, {"actuator_force_ceiling": share})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["force_ceiling_check"]
    assert check["took_the_name"] and check["binding_row_fraction"] > 0.05, check
    assert check["held_out_rmse"] < 0.6 * check["calibrated_held_out_rmse"], check
    # the ceiling found is the true one: the share of the campaign's largest request
    from clutch_model.virtual_car.car_logs import load_truth_sidecar
    peak = max(float(np.max(load_truth_sidecar(f)["fine_applied_force_n"]))
               for f in (tmp_path / "campaign" / "truth").glob("*.npz"))
    assert check["parameters"]["ceiling_n"] == pytest.approx(share * peak, rel=0.05), (peak, check)


# A torque sensor whose zero moves with the oil's temperature (0.436 N*m per degree of sump above
# 60 C) is outside the catalog; over three 30 s runs whose sump warms with the energy dissipated
# it mimics a friction decline, and friction_degradation was named (a wrong name, the unseen runs
# 20 % worse). The offset with its slope takes the named causes' place (sump_offset.py; an outside
# generator's 0.59 N*m per degree had read `none`).
def test_a_torque_offset_following_the_sump_is_not_named_a_friction_decline(tmp_path):
    slope = 0.436
    res, what = _diagnosed(tmp_path, "torque_sensor_thermal_offset", "few_long", 3,
                           {"torque_sensor_thermal_offset": slope})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["sump_offset_check"]
    assert check["took_the_name"] and check["in_place_of"] == ["friction_degradation"], check
    assert check["parameters"]["slope_nm_per_c"] == pytest.approx(slope, rel=0.2), check
    assert check["held_out_rmse"] < check["named_held_out_rmse"], check


# An actuator whose lag grows with the force (20 ms at no force, 137 ms at 6 kN) is outside the
# catalog: over one 40 s drive the catalog named torque_sensor_lag (78 ms; a wrong name, +45 %
# on the unseen bag) and every rival in its place lost, fitted on top of the named model's
# friction correction with a second one (force_dynamics.taken_out: the rivals now start from
# the friction the named fit started from).
def test_a_force_dependent_actuator_lag_is_not_named_a_catalog_time_mechanism(tmp_path):
    tau_high = 0.13657649497006213
    res, what = _diagnosed(tmp_path, "actuator_force_dependent_lag", "long_drive", 1,
                           {"actuator_force_dependent_lag": tau_high})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["lag_rival_checks"]["force_dependent_lag"]
    assert check["took_the_name"] and check["in_place_of"], check
    p = check["parameters"]
    # the effect's constant is linear in the force, 20 ms at 0 N to tau_high at 6 kN: the
    # rival's, linear between its two reported forces, must match it there
    for force_key, tau_key in (("force_low_n", "tau_low_s"), ("force_high_n", "tau_high_s")):
        truth = 0.02 + (tau_high - 0.02) * p[force_key] / 6000.0
        assert p[tau_key] == pytest.approx(truth, rel=0.35), (force_key, check)
    assert check["held_out_rmse"] < 0.85 * check["named_held_out_rmse"], check


# A friction that follows the slip's acceleration (frictional memory, c = 0.011 s^2/rad through a
# 30 ms low-pass) is outside the catalog: where the slip's acceleration does not follow the
# force edges no time mechanism mimics it, and the calibrated model, 35.7 N*m off the true torque
# on the unseen runs, read `none` (the noise model forecast the smooth misfit) until the
# slip-acceleration friction was fitted where nothing is named (diagnosis/slip_acceleration.py).
def test_a_slip_acceleration_friction_is_found_beyond_the_catalog(tmp_path):
    gain = 0.011
    res, what = _diagnosed(tmp_path, "slip_acceleration_friction", "lab", 1,
                           {"slip_acceleration_friction": gain})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["lag_rival_checks"]["slip_acceleration_friction"]
    assert check["took_the_name"] and check["against_twin_t"] > 3.0, check
    assert check["parameters"]["gain_s2_per_rad"] == pytest.approx(gain, rel=0.2), check
    assert check["parameters"]["tau_s"] == pytest.approx(0.03, rel=0.6), check
    assert check["held_out_rmse"] < 0.5 * check["calibrated_held_out_rmse"], check


# A slew-rate-limited actuator (23.5 kN/s) is outside the catalog and no first-order mechanism
# carries it (a lag fitted to the large force edges is wrong on the small ones); the calibrated
# residual, a smooth misfit at the fast edges, was forecast by the noise model and the answer read
# `none` under every condition of the seed-7 draw until a rate-limited force path was fitted
# where nothing was named (diagnosis/force_dynamics.py, none_or_rate_limit).
def test_rate_limited_actuator_is_found_beyond_the_catalog(tmp_path):
    rate = 23485.80078697058
    res, what = _diagnosed(tmp_path, "actuator_rate_limit", "ar1", 7, {"actuator_rate_limit": rate})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["force_path_check"]
    assert check["kind"] == "rate-limited force path" and check["took_the_name"], check
    assert check["against_twin_t"] > 3.0, check        # the force path's gain, not the friction refit's
    assert check["parameters"]["rate_n_per_s"] == pytest.approx(rate, rel=0.10), check
    # what the rate limit leaves on the held-out rows is near the sensor noise (8 N*m)
    assert check["held_out_rmse"] < 0.6 * check["calibrated_held_out_rmse"], check
    assert check["held_out_rmse"] < 10.0, check


# The same slew limit (26.6 kN/s) on the car (unaligned topics, AR(1) 0.9 torque and slip noise,
# lock-up, few long runs): actuator_lag was named, a wrong name, while the rate limit met only
# the none path; a named actuator lag now meets a rate-limited force path in its place
# (force_dynamics.named_or_rate_limit: 25.5 kN/s, held-out 28.9 -> 8.0 N*m).
def test_rate_limited_actuator_is_not_named_an_actuator_lag_on_the_car(tmp_path):
    rate = 26632.070673524533
    res, what = _diagnosed(tmp_path, "actuator_rate_limit", "car", 3, {"actuator_rate_limit": rate})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["force_path_check"]["rate_limited_force_path"]
    assert check["took_the_name"] and check["in_place_of"] == ["actuator_lag"], check
    assert check["parameters"]["rate_n_per_s"] == pytest.approx(rate, rel=0.15), check
    assert check["held_out_rmse"] < 0.5 * check["named_held_out_rmse"], check


# An actuator lag with a transport delay (54 + 96 ms): the lag named first took up the pair's
# group delay, a delay fitted on top of it as it was only added delay, and the delay alone was
# named (lab#3, ar1#3 of the matrix; a missed second cause) until a time mechanism fitted on
# top of another moved that one with it (fitting.co_fitted_ids). The lab cell runs in CI (since
# stop 48), the ar1 cell with -m slow; the co-fit alone is checked by
# test_candidate_fit.py::test_a_time_mechanism_on_top_of_another_moves_it_back.
@pytest.mark.parametrize("condition,seed,magnitudes", [
    ("lab", 3, {"actuator_lag": 0.05381363382159282, "transport_delay": 0.09639873809998827}),
    pytest.param("ar1", 3, {"actuator_lag": 0.05381363382159282, "transport_delay": 0.09639873809998827},
                 marks=pytest.mark.slow)])
def test_a_lag_and_a_delay_are_named_together(tmp_path, condition, seed, magnitudes):
    _named_together(tmp_path, "actuator_lag+transport_delay", condition, seed, magnitudes,
                    (("actuator_lag", "tau_s"), ("transport_delay", "delay_s")), quick=True, unseen_cut=0.2)


def _named_together(tmp_path, case, condition, seed, magnitudes, parameters, quick, unseen_cut):
    """Both hidden causes named, each within 15 % of its hidden value and inside its own 95 %
    interval; the extended model's error on the unseen bags below ``unseen_cut`` x the
    calibrated model's."""
    camp = make_hidden_campaign(case, condition, seed, tmp_path / "campaign", magnitudes=magnitudes, quick=quick)
    res = check_campaign(camp, tmp_path, mc_samples=MC_SAMPLES, stamps=False)
    what = f"diagnose said {res.named_label}: {(res.report or {}).get('cause', {}).get('evidence', res.error)}"
    assert res.judgement == "ok", what
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    assert ext < unseen_cut * cal, f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"
    got = {c["id"]: c for c in res.report["causes"]}
    for mech_id, name in parameters:
        assert got[mech_id]["parameters"][name] == pytest.approx(magnitudes[mech_id], rel=0.15), what
        lo, hi = got[mech_id]["parameters_ci95"][name]
        assert lo < got[mech_id]["parameters"][name] < hi, what


# A spring preload (710 N) with a torque offset (13.4 N*m) on the car at its own size (three
# seen runs of 30 s): the preload fitted alone took part of the offset (649 N) and the offset
# fitted on top of it reached t = 2.8 (9.0 N*m): the preload alone was named until the second
# step's close candidates were refitted together with the named cause (selection.
# _backfitted_second: t = 7.0). In CI since stop 48 (65 s).
def test_a_preload_and_an_offset_are_named_together_on_the_car(tmp_path):
    _named_together(tmp_path, "spring_preload+torque_offset", "car", 1,
                    {"spring_preload": 709.9367362342127, "torque_offset": 13.44862737078797},
                    (("spring_preload", "preload_n"), ("torque_offset", "offset_nm")), quick=False, unseen_cut=0.5)


# An actuator lag (55 ms) under torque noise drawn at 10 Hz and held, and a torque-sensor lag
# (32 ms) on the car: the other lag explained the held-out residual about as well and neither
# won head to head in the whitened one-step errors, so both read `unexplained`; the plain
# squares over every row part them (selection.plainly_better). The same sensor lag under a
# drifting sensor (white noise plus an OU drift, 4 N*m, 10 s) read `unexplained` too: the plain
# squares fell short (t = 0.9) and the encompassing test on the held-out rows parts them
# (selection.encompasses, t = 2.1).
@pytest.mark.parametrize("case,condition,seed,magnitudes,parted_by", [
    ("actuator_lag", "held", 1, {"actuator_lag": 0.054760947913056336}, "parted_in_plain_squares"),
    pytest.param("torque_sensor_lag", "car", 1, {"torque_sensor_lag": 0.0323545078065161},
                 "parted_in_plain_squares", marks=pytest.mark.slow),
    ("torque_sensor_lag", "drift", 1, {"torque_sensor_lag": 0.0323545078065161}, "parted_by_encompassing")])
def test_an_actuator_lag_is_told_from_a_sensor_lag(tmp_path, case, condition, seed, magnitudes, parted_by):
    camp = make_hidden_campaign(case, condition, seed, tmp_path / "campaign", magnitudes=magnitudes, quick=True)
    res = check_campaign(camp, tmp_path, mc_samples=MC_SAMPLES, stamps=False)
    what = f"diagnose said {res.named_label}: {(res.report or {}).get('cause', {}).get('evidence', res.error)}"
    assert res.judgement == "ok", what
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    assert ext < 0.5 * cal, f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"
    cause = res.report["causes"][0]
    assert cause["parameters"]["tau_s"] == pytest.approx(magnitudes[case], rel=0.2), what
    lo, hi = cause["parameters_ci95"]["tau_s"]
    assert lo < magnitudes[case] < hi, what
    other = ({"actuator_lag", "torque_sensor_lag"} - {case}).pop()
    parted = res.report["selection"]["steps"][0][parted_by]
    assert other in parted and parted[other]["t"] > 0, parted
    assert f"{case} told from {other}" in res.report["cause"]["evidence"], what


# A 324 N preload on one 40 s drive (3.3 s spans held out): the drive's one 11.5 kN hold lay in a
# held-out span beyond the fitted spans' 8 kN; the preload model was 0.4 % above the true torque
# there, the flexible residual model extrapolated the fitted rows' torque x force trend to it and
# read "structure" after the preload (t = 8.4; the true model's own remainder t = 0.7), so the
# preload, fitted at 325 N, read `unexplained` until the flexible models were scored only on the
# held-out rows within the fitted rows' range of force, slip and pack temperature
# (structure_test.within_fitted_range). Magnitude from seed 20261129, campaign seed 8.
def test_a_preload_is_named_where_a_held_out_span_reaches_beyond_the_fitted_force(tmp_path):
    preload = 323.92065180934145
    res, what = _diagnosed(tmp_path, "spring_preload", "long_drive", 8, {"spring_preload": preload})
    assert res.judgement == "ok", what
    assert res.report["inputs"]["held_out_rows_outside_fitted_range"] > 0, res.report["inputs"]
    cause = res.report["causes"][0]
    assert cause["parameters"]["preload_n"] == pytest.approx(preload, rel=0.03), what
    lo, hi = cause["parameters_ci95"]["preload_n"]
    assert lo < preload < hi, what
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    assert ext < 0.2 * cal, f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"


# Known misses of the diagnosis (statistics of the held-out tests, not the harness): run with
# `-m slow`, kept out of CI until fixed.
KNOWN_MISSES = {
    # fixed: ("unaligned", "none", 31) -- the torque at 50 Hz, the model simulated on the torque
    # stamps only (20 ms steps, inputs held between rows) was late: a lag fitted to the residual
    # was 7.9 ms (half a 50 Hz period is 10 ms) and the flexible model found it (t = 5.1 ->
    # unexplained). The diagnosis now gives the plant the force at each step's midpoint
    # (clutch_model/diagnosis/input_hold.py) -> none.
    # fixed (docs/diagnosis_statistics.md): ("lowpass", "none", 33) was read as structure at
    # t = 14.6 (the library columns carried the measured inputs' sensor noise, and materiality was
    # in units of the innovation variance, 3 % of the noise variance under a 10 Hz band limit);
    # ("lab", "spring_preload+torque_offset", 37) had t = 4.3 on 7 degrees of freedom (1 s blocks
    # of an 8 s held-out run) and a preload that had absorbed part of the offset (no backfit)
}


def _fast_params():
    out = []
    for cell in FAST:
        marks = [pytest.mark.slow] if cell in KNOWN_MISSES else []
        out.append(pytest.param(*cell, marks=marks, id=f"{cell[0]}-{cell[1]}"))
    return out


@pytest.mark.parametrize("condition,case,seed", _fast_params())
def test_car_log_condition(tmp_path, condition, case, seed):
    _check(tmp_path, condition, case, seed)


@pytest.mark.slow
@pytest.mark.parametrize("condition,case,seed", SLOW, ids=[f"{k}-{c}" for k, c, _ in SLOW])
def test_car_log_condition_slow(tmp_path, condition, case, seed):
    _check(tmp_path, condition, case, seed)


def test_a_logger_pause_is_found_where_the_truth_put_it(tmp_path):
    """Every bag diagnose sees has a logger pause (condition `pause`, nothing hidden): report.json
    lists each one at the truth's span (to within two torque periods of the car's 50 Hz
    torque); where the rows after a pause let its heat be estimated, that heat is the car's
    true one within 25 % and the pack temperature it leaves the pause with is off by under a
    fifth of the worst case's bound (measured: 5618 J against 5916, 7474 against 6439, and 0.6
    and 2.0 K off where the worst case allowed 15 and 45 K); the answer is `none`."""
    res = _check(tmp_path, "pause", "none", 1)
    truth = json.loads((tmp_path / "campaign" / "truth.json").read_text())
    spans = {r["name"]: r["logger_pause_s"] for r in truth["runs"] if r.get("logger_pause_s")}
    found = {p["bag"]: p for p in res.report["inputs"]["logger_pauses"]}
    assert set(found) == set(spans) and len(spans) == CONDITIONS["pause"].seen_runs(quick=True)
    estimated = 0
    for bag, (t0, t1) in spans.items():
        assert found[bag]["t0_s"] == pytest.approx(t0, abs=0.04) and found[bag]["t1_s"] == pytest.approx(t1, abs=0.04)
        assert found[bag]["left_out_to_s"] >= found[bag]["t1_s"]
        heat = found[bag].get("heat")
        if heat is None:
            continue
        # the heat the estimate gives the pause and the pack temperature it leaves it with,
        # against the car's own (its plant on its fine grid through the pause)
        truth_run = np.load(tmp_path / "campaign" / "truth" / f"{bag}.npz")
        t = truth_run["fine_t_s"]
        inside = (t > found[bag]["t0_s"]) & (t < found[bag]["t1_s"])
        heat_true = float(np.sum(np.abs(truth_run["fine_torque_nm"] * truth_run["fine_slip_speed_rad_s"])[inside]
                                 * np.diff(t, prepend=t[0])[inside]))
        pack_true = float(np.interp(found[bag]["t1_s"], t, truth_run["fine_pack_temperature_c"]))
        assert heat["heat_j"] == pytest.approx(heat_true, rel=0.25)
        assert abs(heat["pack_after_c"][1] - pack_true) < 0.2 * heat["worst_case_bound_k"]
        estimated += 1
    assert estimated >= 1


def test_every_condition_class_is_sampled():
    classes = {CONDITIONS[k].klass for k, _, _ in FAST + SLOW}
    assert classes == {c.klass for c in CONDITIONS.values()}


# ------------------------------------------------------------------ the harness itself
def test_scoring_against_the_true_torque(tmp_path):
    """The true model replayed over every bag scores near 0 on the unseen ones (about 3 N*m:
    the noisy force and slip it is driven with, held on the replay grid), well below the 8 N*m
    torque noise; the nominal model without the offset scores far worse."""
    camp = make_hidden_campaign("torque_offset", "unaligned", 61, tmp_path / "c",
                                magnitudes={"torque_offset": 30.0}, quick=True)
    assert [len(camp.seen_bags), len(camp.unseen_bags)] == [4, 2]
    unseen = {os.path.basename(b) for b in camp.unseen_bags}
    scores = {}
    for name in ("truth.yaml", "nominal"):
        args = ["replay", "--bag", *camp.seen_bags, *camp.unseen_bags, "--out", tmp_path / f"{name}.csv"]
        if name == "truth.yaml":
            args += ["--params", camp.root / name]
        rc, err, _, _ = run_clutch_sim(args)
        assert rc == 0, err
        scores[name] = score_replay_csv(tmp_path / f"{name}.csv", camp.truth_dir, unseen)
    assert set(scores["truth.yaml"]["runs"]) == unseen
    assert scores["truth.yaml"]["rmse_nm"] < 5.0            # torque noise is 8 N*m
    assert scores["nominal"]["rmse_nm"] > 10.0              # friction spread + the 30 N*m offset
    # lock phases are left out: the scored rows are fewer than the unseen bags' rows
    with open(tmp_path / "truth.yaml.csv", newline="") as fh:
        n_rows = sum(r["bag"] in unseen for r in csv.DictReader(fh))
    assert 0 < scores["truth.yaml"]["samples"] <= n_rows


def test_report_reading_and_judging():
    one = {"cause": {"id": "actuator_lag", "parameters": {"tau_s": 0.1}}}
    many = {"cause": {"id": "spring_preload"}, "causes": [{"id": "spring_preload"}, {"id": "torque_offset"}]}
    assert named_causes(one) == ("actuator_lag", ["actuator_lag"])
    assert named_causes({"cause": {"id": "none"}}) == ("none", [])
    assert named_causes({"cause": {"id": "unexplained"}, "causes": []}) == ("unexplained", [])
    assert named_causes(many) == ("spring_preload", ["spring_preload", "torque_offset"])
    pair = ["spring_preload", "torque_offset"]
    assert judge("spring_preload", pair, "spring_preload", pair[::-1]) == "ok"
    assert judge("spring_preload", pair, "spring_preload", pair[:1]) == "partial"
    assert judge("spring_preload", pair, "spring_preload", ["spring_preload", "actuator_lag"]) == "wrong"
    assert judge("none", [], "unexplained", []) == "false-alarm"
    assert judge("none", [], "transport_delay", ["transport_delay"]) == "wrong"
    assert judge("unexplained", [], "friction_degradation", ["friction_degradation"]) == "wrong"
    assert judge("unexplained", [], "unexplained", []) == "ok"
    assert judge("unexplained", [], "none", []) == "missed"
    assert judge("actuator_lag", ["actuator_lag"], "refused", []) == "refused"
    assert "torque_sensor_lag" in CATALOG


def test_magnitudes_come_from_the_hidden_seed(tmp_path):
    from clutch_model.virtual_car.hidden_campaigns import CASES, draw_magnitudes

    a = draw_magnitudes(CASES["spring_preload+torque_offset"], 1, HIDDEN_SEED)
    assert a == draw_magnitudes(CASES["spring_preload+torque_offset"], 1, HIDDEN_SEED)
    assert a != draw_magnitudes(CASES["spring_preload+torque_offset"], 1, HIDDEN_SEED + 1)
    lo, hi = CATALOG["spring_preload"].virtual_car.visible
    assert lo <= a["spring_preload"] <= hi
    assert np.isfinite(list(a.values())).all()


@pytest.mark.slow
def test_slip_power_fade_is_not_named_friction_degradation(tmp_path):
    """A reversible slip-power fade under held torque noise (seed 1, full size: 6 seen runs x 8 s)
    was named friction_degradation before the degradation-vs-fade check (engine
    ._degradation_or_fade): its rival, discovery without energy terms, now predicts the held-out
    residual better head to head -> discovered, and the gain holds on the unseen bags."""
    camp = make_hidden_campaign("slip_power_fade", "held", 1, tmp_path / "campaign", magnitude_seed=HIDDEN_SEED)
    res = check_campaign(camp, tmp_path, mc_samples=MC_SAMPLES, stamps=False)
    what = f"diagnose said {res.named_label}: {(res.report or {}).get('cause', {}).get('evidence', res.error)}"
    assert "friction_degradation" not in res.named, what
    assert res.judgement == "ok", what
    if res.verdict == "discovered":
        assert res.replay_rmse_nm["extended"] < res.replay_rmse_nm["calibrated"], res.replay_rmse_nm


# A friction that follows pressure x pack temperature, on one 40 s drive with time spans held out:
# the search found slip power and pressure x the energy dissipated since the campaign start
# (held-out t = 11.7) and was named `discovered`; on the later bag the energy was beyond any it
# was fitted on and the extended model was 47.5 N*m off against the calibrated model's 5.0
# (-846 %). Held-out spans between fitted ones check an energy term only where it was fitted.
def test_an_energy_term_that_spans_cannot_check_is_not_claimed(tmp_path):
    res, what = _diagnosed(tmp_path, "pressure_temperature_cross", "long_drive", 7,
                           {"pressure_temperature_cross": 0.002431928105172907})
    assert res.judgement == "ok", what             # unexplained, or an extension beyond the catalog
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    assert ext <= cal * (1 + 1e-9), f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"
    if res.verdict == "discovered":
        assert not any("energy" in term for term in res.report["cause"]["parameters"]), what


# A 34 N*m torque offset on the quick car (AR(1) 0.9 noise, lock-up, two 20 s runs, four 3.3 s
# spans held out): the offset was far better than its twin on two spans (12.4 against 32.4 and
# 9.5 against 22.4 N*m) and worse on the other two (a tie, and the high-slip span), failed "better
# on most pieces", and the drag was chosen with the offset as its lookalike (`unexplained`) until
# half of four pieces held when no one piece carries the gain.
def test_an_offset_far_better_on_half_the_spans_is_named(tmp_path):
    offset = 34.35250068205923
    res, what = _diagnosed(tmp_path, "torque_offset", "car", 7, {"torque_offset": offset})
    assert named_causes(res.report) == ("torque_offset", ["torque_offset"]), what
    got = res.report["cause"]["parameters"]["offset_nm"]
    assert got == pytest.approx(offset, rel=0.15), what
    lo, hi = res.report["cause"]["parameters_ci95"]["offset_nm"]
    assert lo < offset < hi, what
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    assert ext < 0.7 * cal, f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"


# A 78 ms actuator lag beside a friction decline, one 40 s drive with four 3.3 s spans held out:
# the second-order rival fitted in the lag's place (20.8 Hz at the damping bound of 5: a 76 ms lag
# with a 0.8 ms pole beside it, the lag itself) beat the named lag at t = 5.4 through the friction
# correction refitted with it, and the answer read `unexplained`, until the rival had to beat the
# lag refitted with the friction as well (t = -0.6).
@pytest.mark.slow
def test_a_lag_is_not_taken_by_a_force_path_that_refits_the_friction(tmp_path):
    res, what = _diagnosed(tmp_path, "actuator_lag+friction_degradation", "long_drive", 7,
                           {"actuator_lag": 0.07843908996841246, "friction_degradation": 0.1572507789934871})
    check = res.report["selection"]["force_path_check"]
    assert not check["took_the_name"], what
    assert "actuator_lag" in named_causes(res.report)[1], what
    tau = next(c for c in res.report["causes"] if c["id"] == "actuator_lag")["parameters"]["tau_s"]
    assert tau == pytest.approx(0.0784, rel=0.1), what
    # the decline beside it, which the calibration took as a temperature effect, is found against
    # the bench since stop 43 (diagnosis/bench_anchor.py)
    assert "friction_degradation" in named_causes(res.report)[1], what
    assert res.report["selection"]["bench_anchor"]["named"] == "friction_degradation", what
    # the decline is no level beside the lag (since stop 47: _Check.against_level)
    assert res.report["selection"]["bench_anchor"]["friction_level"]["mechanism_better"], what
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    assert ext < 0.2 * cal, f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"


# A friction decline (10 % over the seen drive) on one 40 s drive with four 3.3 s spans held out:
# the pack heats as the energy is dissipated, the car calibration moved mu_C's temperature slope
# and took the decline as a temperature effect (held-out 8.24 N*m against 8.0 of noise), nothing
# predicted the held-out residual and the answer read `none`; on the later drive, after the pack
# had cooled, the calibrated model was 38 N*m off. The bench measured that temperature slope: on
# the bench friction the model is 20.0 N*m off on the held-out spans, and the degradation on the
# bench friction closes 99 % of that (diagnosis/bench_anchor.py).
def test_a_decline_the_calibration_took_as_temperature_is_found_against_the_bench(tmp_path):
    res, what = _diagnosed(tmp_path, "friction_degradation", "long_drive", 7,
                           {"friction_degradation": 0.10000241666398738})
    assert named_causes(res.report) == ("friction_degradation", ["friction_degradation"]), what
    check = res.report["selection"]["bench_anchor"]
    assert check["absorbed"] and check["named"] == "friction_degradation", what
    truth = json.loads((tmp_path / "campaign" / "truth.json").read_text())["mechanisms"][0]["energy_scale_j"]
    got = res.report["cause"]["parameters"]["energy_scale_j"]
    assert got == pytest.approx(truth, rel=0.1), what
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    assert ext < 0.2 * cal, f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"
    # the decline is no level: the bench friction moved by a constant does not account for it
    assert check["friction_level"]["mechanism_better"], check["friction_level"]


# A 60 ms actuator lag on a drive whose friction sits 4 % below the bench's (a per-run friction
# level, outside the catalog), one 40 s drive: the lag was named, the calibration had absorbed
# the level, and a friction degradation beside the lag on the bench friction accounted for it
# and was named as a second cause (wrong: on the later drive, at +5 %, 64.0 N*m off the true
# torque against 66.2 calibrated). The lag on the bench friction moved by one constant accounts
# for it as well (diagnosis/bench_anchor.py, _Check.against_level): the lag alone is named and the
# later drive reads 36.6 N*m.
def test_a_friction_level_beside_a_named_cause_is_not_a_second_cause(tmp_path):
    case = Case("actuator_lag+run_friction_level", "outside", mechanisms=("actuator_lag",),
                effects=("run_friction_level",))
    res, what = _diagnosed(tmp_path, case, "long_drive", 8,
                           {"actuator_lag": 0.06, "run_friction_level": 0.06994948441216753})
    assert named_causes(res.report) == ("actuator_lag", ["actuator_lag"]), what
    tau = res.report["cause"]["parameters"]["tau_s"]
    assert tau == pytest.approx(0.06, rel=0.1), what
    check = res.report["selection"]["bench_anchor"]
    assert check["beside"] == "actuator_lag" and check["absorbed"], check
    assert not check["friction_level"]["mechanism_better"] and "named" not in check, check
    assert -0.012 < check["friction_level"]["shift"] < -0.002, check["friction_level"]
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    assert ext < 0.7 * cal, f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"


# The drive's friction 4 % below the bench's on one 40 s drive (a per-run friction level): the
# calibration absorbed it, a friction degradation on the bench friction closed 96 % of the gap
# and was named, and on the later drive (+5 %) the extended model was 64 N*m off the true torque
# against 37 for the calibrated one. The bench friction moved by one constant accounts for the
# gap as well (diagnosis/bench_anchor.py): no degradation is named. One drive cannot tell that
# level from the car's own (or a torque sensor's gain): a small level that leaves no gap is the
# calibration's, `none`, and the report says which level it took.
def test_a_friction_level_off_the_bench_is_not_named_a_degradation(tmp_path):
    res, what = _diagnosed(tmp_path, "run_friction_level", "long_drive", 8,
                           {"run_friction_level": 0.06994948441216753})
    assert res.verdict == "none", what
    check = res.report["selection"]["bench_anchor"]
    assert check["absorbed"] and not check["friction_level"]["mechanism_better"], check
    assert "named" not in check and check.get("a_friction_level"), check
    # the level found is the drive's: mu about 4 % below the bench's (mu ~ 0.12-0.2), and it
    # leaves no gap against the calibrated model
    assert -0.012 < check["friction_level"]["shift"] < -0.002, check["friction_level"]
    assert check["friction_level"]["gap_left_frac"] < 1.0, check["friction_level"]
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    assert ext == pytest.approx(cal), f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"


# A torque sensor reading a few per cent low (its gain, no discrepancy of the clutch) on one
# drive: the calibration takes it into the friction level. A friction degradation on the bench
# friction closed 92 % of the gap it left to the bench's friction, and so did the bench friction
# moved by one constant, and the answer read `unexplained`; the level is the calibration's.
def test_a_torque_sensor_gain_is_the_calibrations(tmp_path):
    res, what = _diagnosed(tmp_path, "torque_sensor_gain", "long_drive", 1, {"torque_sensor_gain": 0.9593})
    assert res.verdict == "none", what
    assert res.report["causes"] == [], what
    check = res.report["selection"]["bench_anchor"]
    assert check["absorbed"] and check.get("a_friction_level"), check
    # 4.1 % low on a friction coefficient of about 0.12-0.2
    assert -0.012 < check["friction_level"]["shift"] < -0.004, check["friction_level"]
    cal = res.replay_rmse_nm["calibrated"]
    assert cal < 3.0, f"{what}; unseen bags: calibrated {cal:.2f} N*m off the true torque"


# A friction coefficient with a pressure-temperature cross term (mu_f x (1 + c P (theta - 60 C)),
# outside the catalog) on the car: the car calibration took it into its temperature and level
# coefficients, nothing predicted the held-out residual and the answer read `none`, while on the
# bench friction the model was off by 64 times the calibrated mean square and no mechanism there
# closed the gap. A gap that far beyond what a bench fit's extrapolation gives is `unexplained`
# (diagnosis/bench_anchor.py, BENCH_GAP_FAR).
def test_a_gap_to_the_bench_that_no_mechanism_closes_is_unexplained(tmp_path):
    case = Case("pressure_temperature_cross", "outside", effects=("pressure_temperature_cross",))
    res, what = _diagnosed(tmp_path, case, "car", 3, {"pressure_temperature_cross": 0.003456132707908824})
    assert res.verdict == "unexplained", what
    check = res.report["selection"]["bench_anchor"]
    assert check["absorbed"] and check.get("far_gap"), check
    assert check["gap_frac"] > BENCH_GAP_FAR and "named" not in check, check
    assert res.report["causes"] == [], what
    cal, ext = res.replay_rmse_nm["calibrated"], res.replay_rmse_nm["extended"]
    assert ext == pytest.approx(cal), f"{what}; unseen bags: calibrated {cal:.2f}, extended {ext:.2f} N*m"
