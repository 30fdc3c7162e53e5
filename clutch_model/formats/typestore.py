"""A rosbags typestore that knows the clutch-sim interfaces, so bags holding
``clutch_msgs/msg/ClutchState`` are read and written without ROS.

The message text ships as package data (clutch_model/data/ClutchState.msg, a copy of the
msg_defs/clutch_msgs/msg/ClutchState.msg rosidl compiles; a test keeps the two identical), so the
RIHS01 type hash rosbags computes equals the one of the compiled interface, in a checkout and in
an installed wheel alike.
"""
from __future__ import annotations

from functools import lru_cache
from importlib import resources
from pathlib import Path

from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from rosbags.typesys.store import Typestore

from clutch_model.errors import DataError

CLUTCH_STATE = "clutch_msgs/msg/ClutchState"
_PACKAGED_MSG = Path(str(resources.files("clutch_model") / "data" / "ClutchState.msg"))


def clutch_state_msg_path() -> Path:
    """The ClutchState.msg definition shipped with the package."""
    if not _PACKAGED_MSG.is_file():
        raise DataError(f"ClutchState.msg not found at {_PACKAGED_MSG} (broken installation)")
    return _PACKAGED_MSG


@lru_cache(maxsize=1)
def _cached() -> Typestore:
    store = get_typestore(Stores.ROS2_JAZZY)
    text = clutch_state_msg_path().read_text()
    store.register(get_types_from_msg(text, CLUTCH_STATE))
    return store


def typestore() -> Typestore:
    """rosbags typestore: ROS 2 Jazzy types + clutch_msgs/msg/ClutchState.

    Cached: the same store object is returned on every call (treat it as read-only).
    """
    return _cached()
