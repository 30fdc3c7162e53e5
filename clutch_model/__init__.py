"""clutch_model: the wet-clutch plant of the thesis (pure Python + numba, never rclpy)."""
from clutch_model.errors import ClutchSimError, DataError, FitError, ParamsError
from clutch_model.plant.params import ClutchModel, load_model, save_model, REFERENCE_CLUTCH
from clutch_model.plant.mechanisms import CATALOG, make_mechanism
from clutch_model.plant.simulate import Plant, SimResult, BatchResult, simulate, simulate_batch, predict_measured_torque
from clutch_model.plant.driveline_sim import DrivelineParams, DrivelinePlant, DrivelineResult, simulate_driveline

__all__ = ["ClutchSimError", "DataError", "FitError", "ParamsError", "ClutchModel", "load_model",
           "save_model", "REFERENCE_CLUTCH", "CATALOG", "make_mechanism", "Plant", "SimResult",
           "BatchResult", "simulate", "simulate_batch", "predict_measured_torque",
           "DrivelineParams", "DrivelinePlant", "DrivelineResult", "simulate_driveline"]
