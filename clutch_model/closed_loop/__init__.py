"""Closed loop: a slip controller on the clutch in the driveline (clutch_model.simulate_driveline),
torque-split scenarios and their plots."""
from clutch_model.closed_loop.controller import PISlipController
from clutch_model.closed_loop.scenarios import SCENARIOS, Scenario, run_scenario

__all__ = ["PISlipController", "SCENARIOS", "Scenario", "run_scenario"]
