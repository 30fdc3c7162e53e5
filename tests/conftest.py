"""Shared pytest setup (numba's cache directory is chosen by clutch_model._numba_cache)."""
