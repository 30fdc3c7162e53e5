"""Where numba keeps the compiled plant between runs: the one place NUMBA_CACHE_DIR is set.

Imported first by ``clutch_model/__init__.py``, so it runs before any module of the package
imports numba. An explicit ``NUMBA_CACHE_DIR`` in the environment wins; otherwise the cache
goes to the user's cache directory (``$XDG_CACHE_HOME/clutch-sim/numba``, by default
``~/.cache/clutch-sim/numba``), which is writable for an installed wheel as well as for a
checkout.
"""
from __future__ import annotations

import os


def default_cache_dir() -> str:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "clutch-sim", "numba")


os.environ.setdefault("NUMBA_CACHE_DIR", default_cache_dir())
