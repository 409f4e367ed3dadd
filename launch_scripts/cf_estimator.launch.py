"""Launch cf_estimator_node: `ros2 launch cf_estimator cf_estimator.launch.py [arg:=value ...]`.

Arguments: params_file (default: the installed config/cf_estimator.yaml), use_sim_time,
namespace, node_name, imu_topic / mag_topic (input remaps), velocity_topic (velocity aiding:
TwistStamped or Odometry; empty = none), world_frame (enu, ned, nwu), body_frame (sensor, flu,
frd), output_frame_id, tf_parent_frame, publish_tf, strict_parameters (default true: the node
refuses to start on an unknown or misspelt parameter, or a params file none of whose sections
is for it), log_level. An empty value (the default of the frame, velocity and TF arguments)
leaves the parameter to params_file; a value given here overrides the file.

MAVROS (the autopilot's raw IMU and magnetometer, already in ROS frames):
    ros2 launch cf_estimator cf_estimator.launch.py \
        imu_topic:=/mavros/imu/data_raw mag_topic:=/mavros/imu/mag
PX4 angles from MAVROS (FRD body in NED, published as base_link_frd), GNSS velocity aiding:
    ros2 launch cf_estimator cf_estimator.launch.py \
        imu_topic:=/mavros/imu/data_raw mag_topic:=/mavros/imu/mag \
        world_frame:=ned body_frame:=flu velocity_topic:=/mavros/global_position/raw/gps_vel
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
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
    ("velocity_topic", "", "Velocity aiding input (TwistStamped or Odometry); empty: "
     "params_file's (none by default)"),
    ("world_frame", "", "enu, ned or nwu; empty: params_file's (enu by default)"),
    ("body_frame", "", "sensor, flu or frd; empty: params_file's (sensor by default)"),
    ("output_frame_id", "", "frame_id of the outputs and the TF child; empty: params_file's "
     "(auto: the input's, _frd/_flu added when the body axes are converted)"),
    ("tf_parent_frame", "", "Parent frame of /tf (name it for NED/NWU: map_ned); empty: "
     "params_file's"),
    ("publish_tf", "", "true or false; empty: params_file's (false by default)"),
    ("strict_parameters", "true", "Refuse to start on unknown/misspelt parameters or a params "
     "file not for this node"),
    ("log_level", "info", "Logging level of the node"),
)
#: Arguments that are node parameters, set only when given (else params_file decides).
OPTIONAL_PARAMETERS = {"velocity_topic": str, "world_frame": str, "body_frame": str,
                       "output_frame_id": str, "tf_parent_frame": str, "publish_tf": bool}


def _node(context, *_args, **_kwargs):
    """The node, with the optional parameters that were given (evaluated at launch time)."""
    overrides = {}
    for name, kind in OPTIONAL_PARAMETERS.items():
        value = LaunchConfiguration(name).perform(context).strip()
        if value:
            overrides[name] = (value.lower() in ("true", "1", "yes")) if kind is bool else value
    strict = LaunchConfiguration("strict_parameters").perform(context).strip().lower()
    return [Node(
        package="cf_estimator",
        executable="cf_estimator_node",
        name=LaunchConfiguration("node_name"),
        namespace=LaunchConfiguration("namespace"),
        output="screen",
        parameters=[
            LaunchConfiguration("params_file"),
            {"use_sim_time": ParameterValue(LaunchConfiguration("use_sim_time"), value_type=bool),
             "strict_parameters": strict in ("true", "1", "yes"),
             **overrides},
        ],
        remappings=[
            ("imu/data_raw", LaunchConfiguration("imu_topic")),
            ("imu/mag", LaunchConfiguration("mag_topic")),
        ],
        arguments=["--ros-args", "--log-level", LaunchConfiguration("log_level")],
    )]


def generate_launch_description() -> LaunchDescription:
    """One cf_estimator_node with the arguments above."""
    args = [DeclareLaunchArgument(name, default_value=default, description=text)
            for name, default, text in ARGUMENTS]
    return LaunchDescription([*args, OpaqueFunction(function=_node)])
