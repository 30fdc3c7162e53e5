"""A rosbags typestore that knows the clutch-sim interfaces, so bags holding
``clutch_msgs/msg/ClutchState`` are read and written without ROS.

The message text is the one rosidl compiles (msg_defs/clutch_msgs/msg/ClutchState.msg), so the
RIHS01 type hash rosbags computes equals the one of the compiled interface.
"""
from __future__ import annotations

import sys
from functools import lru_cache
from pathlib import Path

from rosbags.typesys import Stores, get_typestore, get_types_from_msg
from rosbags.typesys.store import Typestore

from clutch_model.errors import DataError

CLUTCH_STATE = "clutch_msgs/msg/ClutchState"
_REPO_MSG = Path(__file__).resolve().parents[2] / "msg_defs" / "clutch_msgs" / "msg" / "ClutchState.msg"
_INSTALLED_MSG = Path(sys.prefix) / "share" / "clutch_msgs" / "msg" / "ClutchState.msg"


def clutch_state_msg_path() -> Path:
    """The ClutchState.msg definition: the source tree's, else the installed one."""
    for path in (_REPO_MSG, _INSTALLED_MSG):
        if path.is_file():
            return path
    raise DataError(f"ClutchState.msg not found (looked at {_REPO_MSG} and {_INSTALLED_MSG})")


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
