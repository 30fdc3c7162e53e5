"""actuator_lag: the pack force follows the measured force through a first-order lag."""
import numpy as np

from clutch_model.plant import layout
from clutch_model.plant.mechanisms.base import Mechanism, Parameter, ParamSpec, VirtualCarRange


class ActuatorLag(Mechanism):
    id = "actuator_lag"
    path = "pack_force"
    parameters = (Parameter("tau_s", "s", (0.0, 2.0), "time constant of the actuator"),)
    physics = "pack force follows the measured force through a first-order lag"
    virtual_car = VirtualCarRange(visible=(0.05, 0.3), default=0.15)
    kernel_slot = layout.LAG_TAU_S

    @classmethod
    def search_space(cls, scale):
        return [ParamSpec("tau_s", True, 1e-4, 2.0, np.geomspace(0.005, 1.0, 10))]
