"""clutch_sim_ros: the ROS 2 glue of clutch-sim (rclpy node, live bag play and record).

Modules that need rclpy import it themselves; ``bag_types``, ``bags`` and ``validation`` work
without ROS.
"""
import os as _os

# numba's on-disk cache of the compiled plant (as clutch_sim.cli does; the node is started
# directly, not through the CLI)
_os.environ.setdefault("NUMBA_CACHE_DIR", _os.path.join(
    _os.path.dirname(_os.path.dirname(_os.path.abspath(__file__))), ".numba_cache"))
