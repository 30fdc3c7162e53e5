"""Beyond the catalog: find the missing term in the data (issue: discovery).

``discover(campaign, calibrated_model, split, noise_model=None) -> DiscoveryResult``
(identify.py) over the candidate-term library of terms.py; the plant applies what it finds as
the mechanism ``discovered`` (clutch_model.plant.mechanisms.discovered).
"""
from clutch_model.discovery.heldout import HeldOutVerdict, block_gain_test
from clutch_model.discovery.identify import DiscoveryResult, discover
from clutch_model.discovery.terms import Term, TermSignals, default_library

__all__ = ["discover", "DiscoveryResult", "Term", "TermSignals", "default_library", "HeldOutVerdict",
           "block_gain_test"]
