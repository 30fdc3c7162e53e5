import glob

import pytest

from clutch_model.formats.bag_reader import read_bags
from clutch_model.virtual_car.car_logs import CarLogSpec, synthesize_car_logs, write_car_logs


def make_campaign(tmp_path_factory, name, **spec):
    out = tmp_path_factory.mktemp(name)
    result = synthesize_car_logs(CarLogSpec(**spec))
    paths = write_car_logs(result, out)
    runs = read_bags(sorted(glob.glob(str(out / "bags" / "*"))))
    return result, paths, runs


@pytest.fixture(scope="session")
def short_campaign(tmp_path_factory):
    """Default car-log conditions: force 200 Hz ±1 ms, slip 100 Hz, torque 50 Hz, lock-up."""
    return make_campaign(tmp_path_factory, "short", seed=11, n_runs=4)
