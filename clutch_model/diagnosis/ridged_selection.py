"""A second forward selection with every fit's friction correction at the ridge the data
support, taken when it names more causes than the first.

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
at it. Its answer is taken only when it names every cause the first one named and more: a
stronger ridge leaves a cause the car calibration absorbed no correction to undo it with, so a
selection at it can lose a cause the first one found (a 120 ms actuator lag on one 40 s run
came back unexplained at x inf) -- the first selection keeps those.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

from clutch_model.diagnosis.candidates import MechanismCandidate, baseline_fit


@dataclass
class RidgedSelection:
    """The second selection's outcome, for report.json (``selection.ridged_selection``)."""

    ridge_factor: float
    first_causes: list
    second_verdict: str
    second_causes: list
    taken: bool

    def to_json(self) -> dict:
        return {"ridge_factor": "inf" if self.ridge_factor == float("inf") else f"{self.ridge_factor:g}",
                "first_causes": list(self.first_causes), "second_verdict": self.second_verdict,
                "second_causes": list(self.second_causes), "taken": self.taken}


def names_more(first, second) -> bool:
    """The second selection names every cause of the first and at least one more."""
    a, b = set(first.cause_ids), set(second.cause_ids)
    return second.verdict == "named" and a < b


def selection_at_the_data_ridge(select, data, first, written, cal_base, ctx, ids, ridge, mask,
                                fit_executor=None, say=lambda msg: None):
    """(selection, base, candidates, context, RidgedSelection or None): ``first`` kept with
    (None, None, None) when the ridge is factor 1 or the second selection (``select(data, base,
    candidates)``, every fit at ``ridge.factor``; ``written``: the calibrated fit at that factor)
    does not name more."""
    if ridge is None or ridge.factor == 1.0:
        return first, None, None, None, None
    label = "inf" if ridge.factor == float("inf") else f"{ridge.factor:g}"
    say(f"selection again with every friction correction at ridge x{label}")
    ctx_r = replace(ctx, friction_ridge_factor=ridge.factor)
    base_r = baseline_fit(written, cal_base, ctx_r, mask)
    cands_r = [MechanismCandidate(cid, ctx_r) for cid in ids]
    if fit_executor is not None:
        fit_executor.register(cands_r)
    second = select(data, base_r, cands_r)
    taken = names_more(first, second)
    info = RidgedSelection(ridge.factor, first.cause_ids, second.verdict, second.cause_ids, taken)
    say(f"at ridge x{label}: {second.verdict} {', '.join(second.cause_ids)}".rstrip()
        + ("; it names more, taken" if taken else "; the first selection kept"))
    if not taken:
        return first, None, None, None, info
    return second, base_r, cands_r, ctx_r, info
