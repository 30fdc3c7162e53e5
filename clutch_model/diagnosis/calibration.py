"""Car-data calibration used by diagnose (placeholder until identification.calibrate lands)."""


def car_calibration(model, fit_campaign, mc_samples=200, seed=0, progress=None):
    return model, {}
