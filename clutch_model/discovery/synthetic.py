"""Campaigns with a known out-of-catalog truth, for the honesty tests and bench/.

The virtual test car (clutch_model.virtual_car.campaign) drives a true clutch that carries a
``discovered`` mechanism with known terms and coefficients (so the truth is exact and is
simulated by the same kernel), with coloured torque noise (white + an Ornstein-Uhlenbeck
component). Optionally each run's torque level is scaled by a random factor: friction levels
that vary from run to run and that nothing in the inputs predicts.

The calibrated model the discovery starts from is made as the diagnosis makes it: the
friction polynomials fitted on the campaign's bench table, then the baseline friction
correction on the fit runs (diagnosis.fitting.fit_candidate).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from clutch_model.diagnosis.engine import choose_held_out
from clutch_model.diagnosis.sump_reading import smooth_sump
from clutch_model.diagnosis.fitting import fit_candidate
from clutch_model.formats.bag_reader import Campaign, Run
from clutch_model.identification.friction_fit import fit_friction
from clutch_model.plant.mechanisms import make_mechanism
from clutch_model.plant.params import ClutchModel, load_model
from clutch_model.replay import replay_runs
from clutch_model.virtual_car.campaign import CampaignSpec, synthesize_campaign


@dataclass
class TruthCase:
    campaign: Campaign               # what a diagnosis reads (measured channels on the run grids)
    true_model: ClutchModel
    true_terms: dict                 # term id -> coefficient ({} = no effect)
    held_out: list                   # run names held out
    calibrated_model: ClutchModel
    bench_model: ClutchModel         # the bench fit the calibration started from
    noise_free_torque: np.ndarray    # true sensor torque on the campaign grid


def _campaign_from(result, run_level_spread: float, rng) -> tuple:
    runs, clean = [], []
    for r in result.runs:
        s = r.signals
        t = s.applied_force.t_s
        sump_idx = np.clip(np.searchsorted(s.sump_temperature.t_s, t, side="right") - 1, 0, None)
        torque = s.measured_torque.values.copy()
        sensor = r.sensor_torque_nm.copy()
        if run_level_spread > 0:
            extra = float(rng.normal(0.0, run_level_spread)) * sensor
            torque = torque + extra
            sensor = sensor + extra
        runs.append(Run(name=r.name, t=t.copy(), applied_force_n=s.applied_force.values.copy(),
                        slip_speed_rad_s=s.slip_speed.values.copy(),
                        sump_temperature_c=s.sump_temperature.values[sump_idx].copy(),
                        torque_measured_nm=torque, start_time_ns=r.start_time_ns))
        clean.append(sensor)
    return Campaign(runs), np.concatenate(clean)


def make_case(seed: int, true_terms: dict | None = None, *, n_runs: int = 9,
              run_duration_s: float = 7.0, white_noise_nm: float = 6.0, coloured_noise_nm: float = 5.0,
              coloured_tau_s: float = 0.3, run_level_spread: float = 0.0, friction_spread: float = 0.05,
              extra_effect: str | None = None, extra_magnitude: float | None = None,
              base_model: ClutchModel | None = None, **spec_kw) -> TruthCase:
    """A synthetic campaign whose true clutch carries ``true_terms`` (term id -> coefficient),
    and the calibrated model a diagnosis would start the discovery from. ``extra_effect``: one
    of the virtual car's own effects outside the catalog instead (its implementation, not the
    discovered mechanism: 'pressure_temperature_cross', or 'torque_ripple' whose phase is
    random per run). ``spec_kw``: further CampaignSpec fields (rate_hz, ...)."""
    true_terms = dict(true_terms or {})
    base = base_model if base_model is not None else load_model(None)
    if true_terms:
        mech = make_mechanism("discovered", terms=list(true_terms), coefficients=list(true_terms.values()))
        base = base.with_mechanisms([m for m in base.mechanisms if m.id != "discovered"] + [mech])
    spec = CampaignSpec(seed=seed, n_runs=n_runs, run_duration_s=run_duration_s,
                        friction_spread=friction_spread, torque_noise_nm=white_noise_nm,
                        torque_drift_nm=coloured_noise_nm, torque_drift_tau_s=coloured_tau_s,
                        extra_effect=extra_effect, magnitude=extra_magnitude, **spec_kw)
    result = synthesize_campaign(spec, base_model=base)
    rng = np.random.default_rng([seed, 7])
    campaign, clean = _campaign_from(result, run_level_spread, rng)
    campaign = smooth_sump(campaign)
    held_out = choose_held_out(campaign.names, campaign.runs)
    eval_mask = np.isin(campaign.run_index, [campaign.names.index(n) for n in held_out])
    # calibration as the diagnosis does it: bench fit, then the friction correction on fit runs
    bench_model = fit_friction(result.bench, base_model=load_model(None)).model
    rep = replay_runs(bench_model, campaign)
    torque_scale = float(np.nanpercentile(np.abs(campaign.torque_measured), 95))
    cal = fit_candidate(bench_model, campaign, ~eval_mask, None, float(rep.sim.energy_j[-1]), torque_scale,
                        noise_sigma_nm=white_noise_nm)
    return TruthCase(campaign=campaign, true_model=result.true_model, true_terms=true_terms,
                     held_out=held_out, calibrated_model=cal.model, bench_model=bench_model, noise_free_torque=clean)
