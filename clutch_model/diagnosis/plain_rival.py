"""A named cause that another candidate beats by far in the torque's own units.

A cause is named on held-out innovations: the noise model fitted to the data whitens the
residual, and the named cause must cut what the noise model cannot forecast. Under a slow,
strongly coloured misfit the noise model forecasts most of it from its own past, and two
candidates can then part ways: one cuts a sliver of the innovations significantly (many small
edges), another cuts the plain held-out error by far with innovations too noisy to be
significant (a smooth misfit the noise model half forecasts). The named one does not explain the
data as well as its rival, and the rival's structure is not what the named one claims: the
answer is ``unexplained``, both reported as the closest.

The check: the model with every named cause against each first-step candidate that is not named,
on the held-out rows in plain squares. The rival takes the name away when it cuts the named
model's plain held-out mean square by ``RIVAL_CUT`` or more, its cut positive over the blocks on
the whole (t > 0, structure_test.plain_cross_fit_test). The bar is on the size of the cut, as the
named cause's own materiality in plain squares is (structure_test.PLAIN_ONLY_FACTOR): the named
cause was found significant, and the question is only whether it explains the data as well as
another. Slow misfits make the block test weak: on the case below the rival's 38 % cut had
t = 0.9 over 12 blocks, one held-out span at 107 N*m against 20-56 for the others.

Measured on the virtual car's torque_sensor_asymmetric_lag@few_long#11 (``--quick``, magnitude
seed 6811: the torque reading lags 15 ms away from zero and 231 ms toward it): an actuator
hysteresis of ratio 0.046 was named (held-out t = 4.1, 0.4 % of the innovation variance, plain
RMSE 64.6 N*m against 71.5 calibrated); an actuator lag predicted the held-out rows at 50.8 N*m
(t = 1.3) and a torque sensor lag at 50.8 (t = 1.4). Over the named cells of the virtual car, the
CI campaigns and two outside generators, the named model's plain held-out RMSE was at most 1.09
times the best rival's elsewhere (a torque offset under held noise: 10.0 against a drag's 9.2).
"""
from __future__ import annotations

import numpy as np

RIVAL_CUT = 0.3      # share of the named model's plain held-out mean square the rival must cut


def named_or_plain_rival(data, sel, say=lambda msg: None) -> tuple:
    """``sel`` (verdict ``named``) against the first step's candidates that are not named ->
    (selection, what the check found, or None when nothing was checked). Module docstring."""
    from clutch_model.diagnosis.selection import leaves_of, residual
    from clutch_model.diagnosis.structure_test import plain_cross_fit_test

    if sel.verdict != "named" or not sel.steps:
        return sel, None
    named = set(sel.cause_ids)
    r_named = np.asarray(residual(data, sel.final), float)
    test = np.asarray(data.test_mask, bool)
    leaves = leaves_of(data, r_named, sel.remainder_structure)
    found = {"named_held_out_rmse": leaves["held_out_rmse"], "rivals": {}}
    best = None
    for sc in sel.steps[0].scores:
        if sc.id in named:
            continue
        r_rival = np.asarray(residual(data, sc.fitted), float)
        rows = test & np.isfinite(r_named) & np.isfinite(r_rival)
        if rows.sum() < 10:
            continue
        plain = plain_cross_fit_test(r_named, r_named - r_rival, rows, data.run_start, data.t)
        entry = {"held_out_rmse": float(np.sqrt(np.mean(r_rival[rows] ** 2))), "cut_frac": float(plain.cut_frac),
                 "t": float(plain.t_stat), "p": float(plain.p_value), "blocks": int(plain.n_blocks)}
        found["rivals"][sc.id] = entry
        if plain.cut_frac >= RIVAL_CUT and plain.t_stat > 0 and (best is None or plain.cut_frac > best[1]["cut_frac"]):
            best = (sc, entry)
    found["took_the_name"] = best is not None
    if best is None:
        return sel, found
    sc, entry = best
    found["rival"] = sc.id
    names = " + ".join(sel.cause_ids)
    why = (f"{names} predicts the held-out rows at {found['named_held_out_rmse']:.2f} N*m, and {sc.id}, not named, "
           f"at {entry['held_out_rmse']:.2f} (its plain mean square {100 * entry['cut_frac']:.0f} % lower, "
           f"t = {entry['t']:.1f} over {entry['blocks']} blocks): no candidate explains the residual as well as "
           f"another")
    say(f"not named: {why}")
    return sel.overruled([*sel.cause_ids, sc.id], leaves, f"{sel.reason}; but {why}"), found
