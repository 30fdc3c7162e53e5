"""A second forward selection with every fit's friction correction at the ridge the data
support, taken when it names more causes than the first and its model predicts the held-out
rows better.

The first selection refits the 10-term friction correction in every fit at the weak ridge of
``fitting`` (factor 1). Under coloured noise that correction follows the noise a long way
(friction_ridge.py), and it also takes in part of a cause whose torque looks like a friction
change: on the quick car with AR(1) 0.9 torque and slip noise, a drag torque of 2.5 N*m per
rad/s was absorbed so far that no candidate predicted the held-out residual (verdict none, the
calibrated model 6.9 N*m off the true torque on later runs), and beside a transport delay the
same drag was left unnamed (14.1 N*m).

When the cross-validated ridge of the calibrated model (friction_ridge.choose_ridge_factor) is
stronger than factor 1, the selection is run again with every fit at that ridge
(``CampaignContext.friction_ridge_factor``), the baseline being the calibrated model refitted
at it. Its answer is taken only when

- it names every cause the first one named and more (``names_more``): a stronger ridge leaves
  a cause the car calibration absorbed no correction to undo it with, so a selection at it can
  lose a cause the first one found (a 120 ms actuator lag on one 40 s run came back unexplained
  at x inf) -- the first selection keeps those; and
- its final model predicts the held-out residual better than the first one's by the measure
  the first selection's remainder was judged noise by (structure_min_gain_frac, 1 %, of the
  innovation variance and of the plain held-out mean square, at ``alpha``): what the second
  names beyond the first is structure the first left. Where the ridge was chosen on a
  calibrated residual that is mostly a large missing cause (x inf), the friction error the
  correction would have held is left to the candidates, and one of them can take a sliver of
  it: a 6 N spring preload beside a friction degradation under a 60 s sample (white noise)
  cut the innovation variance by 0.6 % against the first selection's model (t = 4.5); the
  drag absorbed on the quick car cut it by 8.6 % (plain RMSE 11.8 -> 8.1 N*m).
"""
from __future__ import annotations

from dataclasses import dataclass

from clutch_model.diagnosis.candidates import MechanismCandidate, baseline_fit
from clutch_model.diagnosis.friction_ridge import ridge_label
from clutch_model.diagnosis.selection import _compare, residual
from clutch_model.diagnosis.structure_test import DEFAULT_MAX_ORDER


@dataclass
class RidgedSelection:
    """The second selection's outcome, for report.json (``selection.ridged_selection``)."""

    ridge_factor: float
    first_causes: list
    second_verdict: str
    second_causes: list
    taken: bool
    against_first: dict | None = None     # the second's final model against the first's, held out

    def to_json(self) -> dict:
        return {"ridge_factor": ridge_label(self.ridge_factor),
                "first_causes": list(self.first_causes), "second_verdict": self.second_verdict,
                "second_causes": list(self.second_causes), "against_first": self.against_first,
                "taken": self.taken}


def names_more(first, second) -> bool:
    """The second selection names every cause of the first and at least one more."""
    a, b = set(first.cause_ids), set(second.cause_ids)
    return second.verdict == "named" and a < b


def against_first(data, first, second, alpha: float, min_gain_frac: float) -> tuple:
    """(the second selection's final model predicts the held-out residual significantly better
    than the first's, the comparison for the report)."""
    head = _compare(data, residual(data, first.final), residual(data, second.final), DEFAULT_MAX_ORDER)
    ok = head.significant(alpha, min_gain_frac, plain_gain=True, noise_units=True, plain_material=True)
    return ok, {"held_out_t": float(head.t_stat), "innovation_variance_cut": float(head.gain_frac),
                "held_out_rmse": float(head.rmse_alt), "first_held_out_rmse": float(head.rmse_null)}


def selection_at_the_data_ridge(select, data, first, written, cal_base, ctx, ids, ridge, mask, alpha: float,
                                min_gain_frac: float, fit_executor=None, say=lambda msg: None):
    """(selection, base, candidates, context, RidgedSelection or None): ``first`` kept with
    (None, None, None) when the ridge is factor 1 or the second selection (``select(data, base,
    candidates)``, every fit at ``ridge.factor``; ``written``: the calibrated fit at that factor)
    does not name more or does not predict the held-out rows better (module doc)."""
    if ridge is None or ridge.factor == 1.0:
        return first, None, None, None, None
    label = ridge_label(ridge.factor)
    say(f"selection again with every friction correction at ridge x{label}")
    ctx_r = ctx.at_friction_ridge(ridge.factor)
    base_r = baseline_fit(written, cal_base, ctx_r, mask)
    cands_r = [MechanismCandidate(cid, ctx_r) for cid in ids]
    if fit_executor is not None:
        fit_executor.register(cands_r)
    second = select(data, base_r, cands_r)
    info = RidgedSelection(ridge.factor, first.cause_ids, second.verdict, second.cause_ids, False)
    line = f"at ridge x{label}: {second.verdict} {', '.join(second.cause_ids)}".rstrip()
    if not names_more(first, second):
        say(line + "; the first selection kept")
        return first, None, None, None, info
    better, info.against_first = against_first(data, first, second, alpha, min_gain_frac)
    head = info.against_first
    say(f"{line}; against the first's model on held-out rows: t = {head['held_out_t']:.1f}, RMSE "
        f"{head['held_out_rmse']:.2f} vs {head['first_held_out_rmse']:.2f} N*m"
        + ("; taken" if better else "; the first selection kept"))
    if not better:
        return first, None, None, None, info
    info.taken = True
    return second, base_r, cands_r, ctx_r, info
