"""actuator_hysteresis: ball-ramp friction, a play operator on the force reaching the pack."""
import numpy as np

from clutch_model.plant import layout
from clutch_model.plant.mechanisms.base import Mechanism, Parameter, ParamSpec, VirtualCarRange


class ActuatorHysteresis(Mechanism):
    id = "actuator_hysteresis"
    path = "pack_force"
    parameters = (Parameter("ratio", "-", (0.0, 0.9), "half-width of the band F(1±ratio)"),)
    physics = "ball-ramp friction: pack force moves only when the band F(1±ratio) pushes it"
    virtual_car = VirtualCarRange(visible=(0.05, 0.2), default=0.12)
    kernel_slot = layout.HYST_RATIO
    force_band = "ratio"

    @classmethod
    def search_space(cls, scale):
        return [ParamSpec("ratio", True, 1e-4, 0.9, np.geomspace(0.005, 0.5, 10))]
