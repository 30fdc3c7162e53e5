"""Car-data calibration step of diagnose: regression (least squares on the identifiable
friction coefficients, identification.calibrate) then a Monte Carlo refinement around it
(identification.montecarlo, thesis §5.3), both on the fit runs only."""
from __future__ import annotations

import math

from clutch_model.identification.calibrate import calibrate_friction
from clutch_model.identification.montecarlo import run_montecarlo

MC_CHUNK_BYTES = 256e6     # one Monte Carlo chunk's predictions (torque + pack temperature, float64)


def montecarlo_chunk_size(n_rows: int, largest: int = 256) -> int:
    """Samples per Monte Carlo chunk so that a chunk's predictions stay within MC_CHUNK_BYTES
    (an hour of car data at 333 Hz: 200 samples at once would hold ~2.6 GB). A sample's RMSE
    depends on the chunking by a rounding at most (1e-16 relative); campaigns up to ~62,000
    rows keep the 256-sample chunks of before."""
    return int(max(1, min(largest, MC_CHUNK_BYTES // (16 * max(int(n_rows), 1)))))


def car_calibration(model, fit_campaign, mc_samples: int = 200, spread: float = 0.05, seed: int = 0,
                    progress=None):
    """-> (calibrated model, info dict). Mechanisms of ``model`` are kept."""
    say = progress or (lambda msg: None)
    cal = calibrate_friction(model, fit_campaign)
    info = {"regression": {"rmse_before_nm": cal.rmse_before, "rmse_after_nm": cal.rmse_after,
                           "coefficients_moved": [f"a{k}" for k in cal.coefficients_moved]}}
    best = cal.model
    say(f"regression: fit-run RMSE {cal.rmse_before:.2f} -> {cal.rmse_after:.2f} N*m "
        f"(moved {', '.join(f'a{k}' for k in cal.coefficients_moved) or 'nothing'})")
    if mc_samples > 0:
        mc = run_montecarlo(best, fit_campaign, n_samples=mc_samples, spread=spread, seed=seed,
                            halving=(), progress=False, chunk_size=montecarlo_chunk_size(len(fit_campaign.t)))
        refined = mc.refined_model
        rmse_ref = mc.rmse_refined
        info["montecarlo"] = {"samples": mc_samples, "spread": spread, "seed": seed,
                              "accepted": int(mc.accepted.sum()), "better_than_start": int(mc.better.sum()),
                              "rmse_start_nm": mc.rmse_nominal, "rmse_refined_nm": rmse_ref}
        if refined is not None and math.isfinite(rmse_ref) and rmse_ref < mc.rmse_nominal:
            best = refined
        say(f"Monte Carlo: {int(mc.better.sum())}/{int(mc.accepted.sum())} samples beat the regression; "
            f"fit-run RMSE {mc.rmse_nominal:.2f} -> {min(rmse_ref, mc.rmse_nominal):.2f} N*m")
    return best.with_mechanisms(model.mechanisms), info
