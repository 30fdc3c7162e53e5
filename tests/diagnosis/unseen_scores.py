"""The models a diagnosis wrote, scored against the true torque on the bags it never saw."""
from __future__ import annotations

import math

from clutch_model.formats.bag_reader import read_bags
from clutch_model.plant.params import load_model
from clutch_model.virtual_car.car_logs import measurement_tail_s, score_against_truth


def unseen_rmse_nm(camp, model_path) -> float:
    """RMSE (N*m) of the model at ``model_path`` against the true torque of ``camp``'s unseen
    bags (at the torque stamps, lock phases and the measurement tail left out)."""
    runs = read_bags(camp.seen_bags + camp.unseen_bags)
    unseen = [p.rsplit("/", 1)[-1] for p in camp.unseen_bags]
    sc = score_against_truth(load_model(model_path), runs, camp.truth_dir, tail_s=measurement_tail_s(camp.spec))
    n = sc["run_samples"]
    return math.sqrt(sum(sc["runs"][r] ** 2 * n[r] for r in unseen) / sum(n[r] for r in unseen))
