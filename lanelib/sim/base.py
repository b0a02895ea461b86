"""A Kobuki-like differential-drive base: unicycle kinematics integrated exactly along arcs, the
Kobuki's speed limits, optional acceleration limits, the time from publish to the wheels, the
driver's timeout (no command for 0.6 s and the base stops), and its odometry: the wheels'
motion integrated, with slip (the wheels turn more than the robot moves) and noise; and, for a
base that does not turn as asked, the share of the turn asked that it turns."""

import math
from dataclasses import dataclass

import numpy as np

from lanelib.robot import COMMAND_TIMEOUT, MAX_ANGULAR, MAX_LINEAR, arc_step


@dataclass
class BaseLimits:
    v_max: float = MAX_LINEAR  # [m/s]
    omega_max: float = MAX_ANGULAR  # [rad/s]
    accel: float = 0.0  # [m/s^2] linear acceleration limit, 0 for none
    alpha: float = 0.0  # [rad/s^2] angular acceleration limit, 0 for none
    timeout: float = COMMAND_TIMEOUT  # [s] no command for this long and the base stops
    latency: float = 0.05  # [s] from publish to the wheels
    slip: float = 0.0  # the wheels (and so odometry) turn this fraction more than the robot moves
    odom_noise: float = 0.0  # [rad/s] sigma of odometry's turn rate error, per 10 ms step
    turn_response: float = 1.0  # the base turns this fraction of the turn asked (odometry says
    # how much it did): a Duckiebot's wheels uncalibrated; gym-duckietown's turns about 0.6


def _approach(value, target, rate_limit, dt):
    if rate_limit <= 0:
        return target
    step = rate_limit * dt
    return value + float(np.clip(target - value, -step, step))


class DiffDriveBase:
    """A differential-drive base integrated exactly along arcs in `dt` steps."""

    def __init__(self, pose, limits=None, dt=0.01, t0=0.0, seed=0):
        self.x, self.y, self.yaw = pose
        self.odometry = (0.0, 0.0, 0.0)  # where the wheels say the base is, from where it began
        self._rng = np.random.default_rng(seed)
        self.limits = limits or BaseLimits()
        self.dt = dt
        self.t = t0
        self.v = self.omega = 0.0
        self.distance = 0.0
        self._pending = []  # (time it reaches the wheels, v, omega)
        self._cmd = (0.0, 0.0)
        self._cmd_time = -math.inf

    @property
    def pose(self):
        return (self.x, self.y, self.yaw)

    def command(self, t, v, omega):
        """A Twist published at time t."""
        self._pending.append((t + self.limits.latency, float(v), float(omega)))

    def advance(self, t_end):
        """Drive until t_end."""
        lim = self.limits
        while self.t < t_end - 1e-12:
            dt = min(self.dt, t_end - self.t)
            while self._pending and self._pending[0][0] <= self.t + 1e-12:
                self._cmd_time, *cmd = self._pending.pop(0)
                self._cmd = tuple(cmd)
            v_cmd, w_cmd = self._cmd if self.t - self._cmd_time <= lim.timeout else (0.0, 0.0)
            v_cmd = float(np.clip(v_cmd, -lim.v_max, lim.v_max))
            w_cmd = float(np.clip(w_cmd, -lim.omega_max, lim.omega_max))
            self.v = _approach(self.v, v_cmd, lim.accel, dt)
            self.omega = _approach(self.omega, w_cmd * lim.turn_response, lim.alpha, dt)
            self.x, self.y, self.yaw = arc_step(self.x, self.y, self.yaw, self.v, self.omega, dt)
            turn = self.omega * (1 + lim.slip)
            if lim.odom_noise:
                turn += self._rng.normal(0.0, lim.odom_noise)
            self.odometry = arc_step(*self.odometry, self.v * (1 + lim.slip), turn, dt)
            self.distance += abs(self.v) * dt
            self.t += dt
