"""Launch the clutch_sim node (for full ROS 2 Jazzy installs with launch / launch_ros).

    ros2 launch launch/clutch_sim.launch.py namespace:=rig1 use_sim_time:=false \
        params_file:=config/clutch_sim.yaml

Same as the process command line (which needs no launch):

    clutch-sim-node --ros-args -r __ns:=/rig1 --params-file config/clutch_sim.yaml

The node is the console entry ``clutch-sim-node`` of the pip-installed clutch-sim package
(not an ament package), so it is started by executable name from PATH.
"""
from pathlib import Path

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

DEFAULT_PARAMS = str(Path(__file__).resolve().parents[1] / "config" / "clutch_sim.yaml")


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="clutch",
                              description="namespace of the node's topics (inputs and outputs)"),
        DeclareLaunchArgument("params_file", default_value=DEFAULT_PARAMS,
                              description="ROS parameter file of the node"),
        DeclareLaunchArgument("use_sim_time", default_value="false",
                              description="step on /clock (lock-step with clutch-sim play --clock)"),
        Node(
            executable="clutch-sim-node",
            name="clutch_sim",
            namespace=LaunchConfiguration("namespace"),
            parameters=[LaunchConfiguration("params_file"),
                        {"use_sim_time": ParameterValue(LaunchConfiguration("use_sim_time"), value_type=bool)}],
            output="screen",
            emulate_tty=True,
        ),
    ])
