"""clutch_sim_ros: the ROS 2 glue of clutch-sim (rclpy node, live bag play and record).

Modules that need rclpy import it themselves. (numba's cache directory is chosen by
clutch_model, which every module here imports before the plant.)
"""
