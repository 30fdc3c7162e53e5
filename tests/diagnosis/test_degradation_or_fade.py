"""friction_degradation named beside other causes: its reversible lookalike (a slip-power fade
found by discovery) is sought on top of those other causes and, when it predicts the held-out
rows better, takes the degradation's place among them; the others stay named. (Sought on the
calibrated model alone, discovery found the other causes again: a true torque offset came back
as `discovered` torque x slip sign.) The selection and discovery are stood in for by fixed
predictions; the held-out comparison and the report's causes are the engine's own."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import clutch_model.diagnosis.engine as engine
from clutch_model.diagnosis.selection import Cause, Selection, SelectionData

from .synthetic_residuals import Fixed, run_grid

RATE_HZ, RUN_S, N_RUNS = 200.0, 10.0, 4
OFFSET_NM = 10.0


def _data(seed=0):
    t, run, run_start = run_grid(RATE_HZ, RUN_S, N_RUNS)
    # a reversible fade: the torque dips with each slip-power burst and recovers
    fade = -6.0 * np.sin(np.pi * t / 2.5) ** 2 * (1.0 + 0.3 * run)
    noise = np.random.default_rng(seed).normal(0.0, 1.0, t.size)
    y = OFFSET_NM + fade + noise
    test = run == 2
    data = SelectionData(y=y, t=t, run_start=run_start, train_mask=~test, test_mask=test)
    return data, fade


def _selection(data, fade, named):
    offset = np.full(data.y.size, OFFSET_NM)
    fits = {"torque_offset": Fixed(offset, {"offset_nm": 9.0}, {"offset_nm": [8.0, 10.0]}),
            "friction_degradation": Fixed(offset + 0.4 * fade, {"energy_scale_j": 4e6},
                                          {"energy_scale_j": [2e6, 9e6]})}
    causes = [Cause(cid, fits[cid], dict(fits[cid].parameters), dict(fits[cid].parameters_ci95), None)
              for cid in named]
    final = Fixed(offset + 0.4 * fade)             # the degradation follows part of the fade
    return Selection("named", causes, [], final, None, None, [], {}, "named", None)


@pytest.fixture
def stand_ins(monkeypatch):
    """refit_chain and the discovery's judge replaced: the chain of the other causes predicts
    the offset (with its parameter refitted to 10 N*m); discovery adds the whole fade on top
    of whatever baseline it is given."""
    seen = {}

    def refit_chain(data, baseline, ids, cand_by_id, refine):
        seen["chain"] = list(ids)
        mech = SimpleNamespace(id="torque_offset", values={"offset_nm": OFFSET_NM})
        model = SimpleNamespace(mechanisms=[mech])
        return Fixed(np.full(data.y.size, OFFSET_NM), model=model), []

    def judge(data, base, cand, say):
        seen["fade_on_top_of"] = base
        fade = seen["fade"]
        model = SimpleNamespace(mechanisms=list(getattr(base.model, "mechanisms", [])) +
                                [SimpleNamespace(id="discovered", values={})])
        fitted = Fixed(np.asarray(base.predict(data)) + fade, {"mu:slip_power_lp": -0.05},
                       {"mu:slip_power_lp": [-0.06, -0.04]}, ["mu_f falls with slip power"], model)
        return Selection("named", [Cause("discovered", fitted, dict(fitted.parameters),
                                         dict(fitted.parameters_ci95), None)],
                         [], fitted, None, None, [], {}, "named", None)

    monkeypatch.setattr(engine, "refit_chain", refit_chain)
    monkeypatch.setattr(engine, "_judge_discovery", judge)
    return seen


def test_fade_is_sought_on_top_of_the_other_causes_and_they_stay_named(stand_ins):
    data, fade = _data()
    stand_ins["fade"] = fade
    sel = _selection(data, fade, ["torque_offset", "friction_degradation"])
    base = Fixed(np.zeros(data.y.size))
    cands = [SimpleNamespace(id="torque_offset"), SimpleNamespace(id="friction_degradation")]
    out, outcome = engine._degradation_or_fade(data, base, None, None, sel, cands, lambda m: None)
    assert stand_ins["chain"] == ["torque_offset"]
    assert stand_ins["fade_on_top_of"] is not base          # on top of the offset, not the baseline
    assert np.allclose(stand_ins["fade_on_top_of"].predict(data), OFFSET_NM)
    assert outcome is not None and outcome.accepted, out.reason
    assert [c.id for c in outcome.beside] == ["torque_offset"]
    assert "reversible friction fade" in out.reason
    disc = {"id": "discovered", "parameters": dict(outcome.cause.parameters),
            "parameters_ci95": dict(outcome.cause.fitted.parameters_ci95)}
    causes = engine._beside_discovered(outcome, disc, outcome.cause.fitted.model, 0.0025)
    assert [c["id"] for c in causes] == ["torque_offset", "discovered"]
    # the offset as refitted without the degradation, its interval made to hold it
    assert causes[0]["parameters"] == {"offset_nm": OFFSET_NM}
    lo, hi = causes[0]["parameters_ci95"]["offset_nm"]
    assert lo <= OFFSET_NM <= hi


def test_degradation_alone_seeks_the_fade_on_the_baseline(stand_ins):
    data, fade = _data(1)
    stand_ins["fade"] = fade + OFFSET_NM           # on the baseline the fade must carry the level too
    sel = _selection(data, fade, ["friction_degradation"])
    base = Fixed(np.zeros(data.y.size))
    out, outcome = engine._degradation_or_fade(data, base, None, None, sel, [], lambda m: None)
    assert "chain" not in stand_ins
    assert stand_ins["fade_on_top_of"] is base
    assert outcome is not None and outcome.accepted and outcome.beside == []
