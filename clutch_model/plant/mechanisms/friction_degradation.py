"""friction_degradation: lining glazing / ATF ageing, mu_f scaled by exp(-E/energy_scale_j),
E = int |w T| dt the campaign's dissipated energy (carried across runs)."""
import numpy as np

from clutch_model.errors import ParamsError
from clutch_model.plant import layout
from clutch_model.plant.mechanisms.base import Mechanism, Parameter, ParamSpec, VirtualCarRange


class FrictionDegradation(Mechanism):
    """``energy_history`` (optional state, written by ``diagnose``): [[log_time_ns, E_j], ...],
    the campaign's dissipated energy at known times (its runs' starts and ends). A replay whose
    first bag starts at or after a recorded time starts from that energy, so later runs replayed
    on their own continue the campaign instead of starting from a fresh lining."""

    id = "friction_degradation"
    path = "friction"
    parameters = (Parameter("energy_scale_j", "J", (1.0, 1e15), "dissipated energy per e-fold of mu_f"),)
    state_keys = ("energy_history",)
    physics = "lining glazing / ATF ageing: mu_f scaled by exp(-E/energy_scale)"
    # the virtual car sets energy_scale_j from the campaign's energy (a fixed drop of mu_f)
    virtual_car = VirtualCarRange(visible=None, default=None)
    kernel_slot = layout.ENERGY_SCALE_J
    friction_decay = "energy_scale_j"

    @classmethod
    def search_space(cls, scale):
        e = max(scale.energy_total_j, 1.0)
        return [ParamSpec("energy_scale_j", True, 1e-3 * e, 1e6 * e, e * np.geomspace(0.3, 300.0, 10))]

    def __post_init__(self):
        super().__post_init__()
        hist = self.values.get("energy_history")
        if hist is not None:
            try:
                rows = [[int(t), float(e)] for t, e in hist]
            except (TypeError, ValueError):
                raise ParamsError("mechanism friction_degradation: energy_history must be "
                                  "[[log_time_ns, energy_j], ...]") from None
            if any(not np.isfinite(e) or e < 0 for _, e in rows):
                raise ParamsError("mechanism friction_degradation: energy_history energies must be >= 0")
            self.values["energy_history"] = sorted(rows)

    def energy_at(self, time_ns: int) -> float:
        """Campaign energy known at or before ``time_ns`` (0 before the campaign)."""
        energy = 0.0
        for t, e in self.values.get("energy_history") or []:
            if t <= time_ns:
                energy = e
        return energy
