"""spring_preload: return springs take the first preload_n of the force."""
import numpy as np

from clutch_model.plant import layout
from clutch_model.plant.mechanisms.base import Mechanism, Parameter, ParamSpec, VirtualCarRange


class SpringPreload(Mechanism):
    id = "spring_preload"
    path = "pack_force"
    parameters = (Parameter("preload_n", "N", (0.0, 50000.0), "return-spring preload"),)
    physics = "return springs: pack force = max(F - preload, 0)"
    virtual_car = VirtualCarRange(visible=(300.0, 1500.0), default=800.0)
    kernel_slot = layout.PRELOAD_N
    force_level = "preload_n"

    @classmethod
    def search_space(cls, scale):
        hi = max(scale.max_force_n, 100.0)
        return [ParamSpec("preload_n", True, 1.0, hi, np.geomspace(20.0, 0.5 * hi, 10))]
