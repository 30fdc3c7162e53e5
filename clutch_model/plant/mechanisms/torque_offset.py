"""torque_offset: a constant bias of the torque sensor."""
import numpy as np

from clutch_model.plant.mechanisms.base import Mechanism, Parameter, ParamSpec, VirtualCarRange


class TorqueOffset(Mechanism):
    id = "torque_offset"
    path = "measurement"
    parameters = (Parameter("offset_nm", "N*m", (-1e5, 1e5), "sensor bias"),)
    torque_level = "offset_nm"
    physics = "torque sensor bias: measured = true + offset"
    virtual_car = VirtualCarRange(visible=(10.0, 50.0), default=25.0)

    @classmethod
    def search_space(cls, scale):
        s = max(scale.torque_scale_nm, 1.0)
        return [ParamSpec("offset_nm", False, -s, s, np.linspace(-0.2 * s, 0.2 * s, 11))]

    def apply_to_measurement(self, t, torque, run_start):
        return torque + self.values["offset_nm"]
