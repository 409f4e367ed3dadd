"""Launch cf_estimator_node: `ros2 launch cf_estimator cf_estimator.launch.py [arg:=value ...]`.

Arguments: params_file (default: the installed config/cf_estimator.yaml), use_sim_time,
namespace, node_name, imu_topic / mag_topic (input remaps), log_level.

MAVROS (the autopilot's raw IMU and magnetometer, already in ROS frames):
    ros2 launch cf_estimator cf_estimator.launch.py \
        imu_topic:=/mavros/imu/data_raw mag_topic:=/mavros/imu/mag
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

ARGUMENTS = (
    ("params_file", PathJoinSubstitution([FindPackageShare("cf_estimator"), "config",
                                          "cf_estimator.yaml"]),
     "ROS 2 parameter file for the node"),
    ("use_sim_time", "false", "Use /clock (bag replay, simulation)"),
    ("namespace", "", "Namespace of the node and of its relative topics"),
    ("node_name", "cf_estimator", "Name of the node"),
    ("imu_topic", "imu/data_raw", "Input sensor_msgs/Imu topic (remap of imu/data_raw)"),
    ("mag_topic", "imu/mag", "Input sensor_msgs/MagneticField topic (remap of imu/mag)"),
    ("log_level", "info", "Logging level of the node"),
)


def generate_launch_description() -> LaunchDescription:
    """One cf_estimator_node with the arguments above."""
    args = [DeclareLaunchArgument(name, default_value=default, description=text)
            for name, default, text in ARGUMENTS]
    node = Node(
        package="cf_estimator",
        executable="cf_estimator_node",
        name=LaunchConfiguration("node_name"),
        namespace=LaunchConfiguration("namespace"),
        output="screen",
        parameters=[
            LaunchConfiguration("params_file"),
            {"use_sim_time": ParameterValue(LaunchConfiguration("use_sim_time"), value_type=bool)},
        ],
        remappings=[
            ("imu/data_raw", LaunchConfiguration("imu_topic")),
            ("imu/mag", LaunchConfiguration("mag_topic")),
        ],
        arguments=["--ros-args", "--log-level", LaunchConfiguration("log_level")],
    )
    return LaunchDescription([*args, node])
