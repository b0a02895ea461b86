"""The message types the rospy stand-in carries, with the fields the node and the simulator use:
geometry_msgs/Twist (and Vector3) for the commands, nav_msgs/Odometry (Pose, Quaternion) for the
simulator's odometry. lanelib/rospy_standin.py offers them beside its rospy calls."""

from dataclasses import dataclass, field


@dataclass
class Vector3:
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass
class Twist:
    """geometry_msgs/Twist: linear [m/s] and angular [rad/s] velocity."""

    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class Quaternion:
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    w: float = 1.0


@dataclass
class Pose:
    position: Vector3 = field(default_factory=Vector3)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class PoseWithCovariance:
    pose: Pose = field(default_factory=Pose)


@dataclass
class Odometry:
    """nav_msgs/Odometry, as far as the lane memory reads it: pose.pose (position,
    orientation), and twist.twist."""

    pose: PoseWithCovariance = field(default_factory=PoseWithCovariance)
    twist: Twist = field(default_factory=Twist)
