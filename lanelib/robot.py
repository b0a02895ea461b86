"""The Kobuki, as far as the node and the simulator need it: the command, its limits, its motion.

Limits from Kobuki's documentation and driver: top speed 0.7 m/s, top turn rate pi rad/s
(kobuki_node clips to these), and the driver stops the wheels when no command has come for
0.6 s (kobuki_node's cmd_vel_timeout).
"""

import math
from dataclasses import dataclass

VELOCITY_TOPIC = '/mobile_base/commands/velocity'  # kobuki_node's velocity command input
ODOM_TOPIC = '/odom'  # kobuki_node's odometry (nav_msgs/Odometry)
MAX_LINEAR = 0.7  # [m/s] the Kobuki's top speed
MAX_ANGULAR = math.pi  # [rad/s] the Kobuki's top turn rate
COMMAND_TIMEOUT = 0.6  # [s] the driver stops the wheels after this long without a command


@dataclass(frozen=True)
class Command:
    decision: str  # left | right | straight | none
    linear_x: float  # [m/s]
    angular_z: float  # [rad/s]


STOP = Command('none', 0.0, 0.0)


def within_limits(command):
    """The command within the Kobuki's limits; anything not finite becomes a stop."""
    if not (math.isfinite(command.linear_x) and math.isfinite(command.angular_z)):
        return STOP
    return Command(command.decision,
                   min(max(command.linear_x, -MAX_LINEAR), MAX_LINEAR),
                   min(max(command.angular_z, -MAX_ANGULAR), MAX_ANGULAR))


def arc_step(x, y, yaw, v, omega, dt):
    """Unicycle motion, exactly along the arc: the pose after `dt` s at (v [m/s], omega
    [rad/s]) from (x, y [m], yaw [rad]). The simulated base, the lane memory's dead reckoning
    and the track's centre line all move this way."""
    yaw2 = yaw + omega * dt
    if abs(omega) < 1e-9:
        return x + v * dt * math.cos(yaw), y + v * dt * math.sin(yaw), yaw2
    r = v / omega
    return x + r * (math.sin(yaw2) - math.sin(yaw)), y - r * (math.cos(yaw2) - math.cos(yaw)), yaw2


def moved_by(x, y, yaw, ahead, left, turned):
    """The pose (x, y, yaw) after moving `ahead` and `left` [m] and turning `turned` [rad] in
    the robot's frame at (x, y, yaw): a step of odometry, composed onto a pose."""
    c, s = math.cos(yaw), math.sin(yaw)
    return x + c * ahead - s * left, y + s * ahead + c * left, yaw + turned


def seen_from(origin, pose):
    """(ahead, left, turned): `pose` (x, y, yaw) in the robot's frame at `origin` (x, y, yaw),
    moved_by's inverse: how far the robot at `origin` must move and turn to be at `pose`. The
    turn is the yaws' plain difference (a caller that needs it within +-pi wraps it)."""
    dx, dy = pose[0] - origin[0], pose[1] - origin[1]
    c, s = math.cos(origin[2]), math.sin(origin[2])
    return c * dx + s * dy, -s * dx + c * dy, pose[2] - origin[2]


def could_move(distance, turn, dt, slack=2.0):
    """Whether the robot can have moved `distance` [m] and turned `turn` [rad] in `dt` [s]: at
    most `slack` times its top speeds, and 5 cm and 0.2 rad besides (odometry comes in bursts
    after a stall, and each message is a step of its own). Odometry that jumps further is
    not believed."""
    return (math.isfinite(distance) and math.isfinite(turn) and
            abs(distance) <= slack * MAX_LINEAR * max(dt, 0.0) + 0.05 and
            abs(turn) <= slack * MAX_ANGULAR * max(dt, 0.0) + 0.2)


class TurnResponse:
    """How much of the turn asked for the base turns, from odometry: the ratio of the turns it
    reports to the turns commanded, each summed over blocks of `block` seconds (the base acts a
    frame or two after the command, and a block of a second holds both), weighed by least
    squares, blocks older by `memory` seconds counting e times less. `gain` is 1 (as asked)
    until the blocks hold `evidence` rad^2 of commanded turn, then within `limits`.

    A base that controls its wheels' speed (kobuki_node) is taken to turn as asked; that was
    not measured here. gym-duckietown's Duckiebot, driven through ../shared/duckietown/run.sh,
    turned 0.59 to 0.63 of it over one-second blocks (two episodes, loop_empty and
    zigzag_dists, 2026-12-01; its speed 0.99 of the speed asked): asked for a corner, it drove
    a wider one. A Duckiebot's uncalibrated wheels may do the same (not measured here)."""

    def __init__(self, block=1.0, memory=20.0, evidence=1.0, limits=(0.5, 2.0)):
        self.block, self.memory, self.evidence, self.limits = block, memory, evidence, limits
        self.turned = self.asked = self.spent = 0.0  # the block being summed
        self.cross = self.square = 0.0  # sums over the blocks: turned x asked, asked^2
        self.gain = 1.0

    def update(self, turned, asked, dt):
        """The base turned `turned` [rad] by odometry in the `dt` seconds in which `asked`
        [rad] was commanded."""
        self.turned += turned
        self.asked += asked
        self.spent += dt
        if self.spent < self.block:
            return
        keep = math.exp(-self.spent / self.memory)
        self.cross = keep * self.cross + self.turned * self.asked
        self.square = keep * self.square + self.asked * self.asked
        self.turned = self.asked = self.spent = 0.0
        if self.square >= self.evidence:
            self.gain = min(max(self.cross / self.square, self.limits[0]), self.limits[1])
