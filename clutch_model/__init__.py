"""clutch_model: the wet-clutch plant of the thesis (pure Python + numba, never rclpy)."""
from .errors import ClutchSimError, DataError, FitError, ParamsError
from .params import ClutchModel, load_model, save_model, REFERENCE_CLUTCH
from .mechanisms import CATALOG, make_mechanism
from .simulate import Plant, SimResult, BatchResult, simulate, simulate_batch, predict_measured_torque

__all__ = ["ClutchSimError", "DataError", "FitError", "ParamsError", "ClutchModel", "load_model",
           "save_model", "REFERENCE_CLUTCH", "CATALOG", "make_mechanism", "Plant", "SimResult",
           "BatchResult", "simulate", "simulate_batch", "predict_measured_torque"]
