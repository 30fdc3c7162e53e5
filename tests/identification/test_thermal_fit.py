import numpy as np
import pytest

from clutch_model.errors import DataError, FitError
from clutch_model.virtual_car import identification_data as td
from clutch_model.identification import thermal_fit as tf


def test_viscosity_recovery(rc1):
    th, mu = td.synthetic_viscosity(rc1, noise_rel=0.01, seed=4)
    v = tf.fit_viscosity(th, mu)
    assert abs(v.alpha0 - 31.67) < 4 * v.stderr[0]
    assert abs(v.alpha1 - 1.89) < 4 * v.stderr[1]
    assert v.rmse < 0.001


def test_viscosity_bad_input(tmp_path):
    with pytest.raises(FitError):
        tf.fit_viscosity([60.0, 60.0, 60.0], [0.01, 0.01, 0.01])
    p = tmp_path / "v.csv"
    p.write_text("temperature,visc\n20,0.1\n")
    with pytest.raises(DataError):
        tf.read_viscosity_csv(p)


@pytest.fixture(scope="module")
def thermal_runs(rc1):
    return td.synthetic_runs(rc1, n_runs=6, seed=2, noise_nm=15.0, pack_noise_c=0.3)


def test_heat_transfer_exact_without_noise(rc1):
    runs = td.synthetic_runs(rc1, n_runs=4, seed=2, noise_nm=0.0, pack_noise_c=0.0)
    h = tf.fit_heat_transfer(runs, rc1, window_s=0.2, evaluate=False)
    assert h.b[0] == pytest.approx(149.40, rel=0.02)
    assert h.b[1] == pytest.approx(13.72, rel=0.05)
    # b3, b4 are tiny and weakly determined even without noise; the H_tf they predict is right
    s = tf.heat_transfer_samples(runs, rc1, window_s=0.2)
    x = s["x"][s["used"]]
    htf_true = x @ np.array(rc1.data["thermal"]["b"])
    assert np.max(np.abs(x @ h.b - htf_true) / htf_true) < 0.03


def test_heat_transfer_noisy_recovery_and_identifiability(rc1, thermal_runs):
    start = tf.with_thermal(rc1, b=[90.0, 4.0, 0.0, 0.0])
    h = tf.fit_heat_transfer(thermal_runs, start)
    truth = np.array([149.40, 13.72, -0.0036, -0.0099])
    assert np.all(np.abs(h.b - truth) < 3.5 * h.stderr), (h.b, h.stderr)
    assert h.identifiable[0]
    assert not h.identifiable[2] and not h.identifiable[3]     # b3, b4 with F in kN: barely identifiable
    assert any("barely identifiable" in n for n in h.notes)
    assert h.rmse_pack_after < h.rmse_pack_before
    assert h.rmse_pack_after < 0.45                            # pack sensor noise 0.3 C


def test_heat_transfer_needs_pack_temperature(rc1):
    runs = td.synthetic_runs(rc1, n_runs=1, seed=2)
    with pytest.raises(FitError):
        tf.fit_heat_transfer(runs, rc1)
