"""The camera's mounting on the robot: undistorted pixels to floor points, and back.

Frames (robot): x forward, y left, z up, metres; yaw counter-clockwise, radians.
Camera: OpenCV's (x right, y down, z along the optical axis), pitched down by `pitch_deg`.
"""

import math
from dataclasses import dataclass, replace

import numpy as np


@dataclass
class Mounting:
    height: float = 0.20  # [m] lens above the floor
    pitch_deg: float = 0.0  # [deg] optical axis below horizontal
    forward: float = 0.10  # [m] lens ahead of the robot's centre
    roll_deg: float = 0.0  # [deg] about the optical axis, + when the camera's right side is lower

    def looking_down(self, turn_deg):
        """The same camera looking `turn_deg` further down (itself for 0)."""
        return replace(self, pitch_deg=self.pitch_deg + turn_deg) if turn_deg else self


def camera_axes(pitch_deg, roll_deg=0.0):
    """The camera's x (right), y (down) and z (optical axis) in the robot frame."""
    p = math.radians(pitch_deg)
    x_cam, y_cam = np.array([0.0, -1.0, 0.0]), np.array([-math.sin(p), 0.0, -math.cos(p)])
    if roll_deg:  # turned about the optical axis: right towards down
        r = math.radians(roll_deg)
        x_cam, y_cam = (math.cos(r) * x_cam + math.sin(r) * y_cam,
                        math.cos(r) * y_cam - math.sin(r) * x_cam)
    return x_cam, y_cam, np.array([math.cos(p), 0.0, -math.sin(p)])


def ray_directions(xn, yn, pitch_deg, roll_deg=0.0):
    """Normalised image coordinates to ray directions (..., 3) in the robot frame."""
    return np.stack(_ray_components(xn, yn, pitch_deg, roll_deg), axis=-1)


def _ray_components(xn, yn, pitch_deg, roll_deg):
    """ray_directions' three components (ahead, left, up), each an array of xn's shape: a
    frame's pixels in an (N, 3) array took four times as long to project."""
    x_cam, y_cam, z_cam = camera_axes(pitch_deg, roll_deg)
    xn, yn = np.asarray(xn, float), np.asarray(yn, float)
    return tuple(xn * x_cam[i] + yn * y_cam[i] + z_cam[i] for i in range(3))


def rays_to_floor(xn, yn, mounting):
    """Normalised image coordinates to floor points (x, y) in the robot frame.

    Returns x, y and a mask of the rays that point down to the floor.
    """
    ahead, left, up = _ray_components(xn, yn, mounting.pitch_deg, mounting.roll_deg)
    down = -up
    ok = down > 1e-9
    t = mounting.height / np.where(ok, down, 1.0)
    return mounting.forward + t * ahead, t * left, ok


def pixels_to_floor(uv, matrix, mounting):
    """Pixels of an undistorted image (camera matrix `matrix`) to floor points, robot frame."""
    uv = np.asarray(uv, float)
    xn = (uv[..., 0] - matrix[0, 2]) / matrix[0, 0]
    yn = (uv[..., 1] - matrix[1, 2]) / matrix[1, 1]
    return rays_to_floor(xn, yn, mounting)


def floor_to_row(distance, matrix, mounting):
    """The undistorted image row where floor `distance` metres ahead of the lens appears
    (in the image's middle column, with the camera rolled)."""
    angle = math.atan2(mounting.height, distance) - math.radians(mounting.pitch_deg)
    return matrix[1, 2] + matrix[1, 1] * math.tan(angle)


def floor_to_pixels(x, y, matrix, mounting):
    """Floor points (robot frame) to pixels of the undistorted image: u, v and a mask of the
    points in front of the camera."""
    x_cam, y_cam, z_cam = camera_axes(mounting.pitch_deg, mounting.roll_deg)
    rel = np.stack([np.asarray(x, float) - mounting.forward, np.asarray(y, float),
                    np.full(np.shape(x), -mounting.height)], axis=-1)
    depth = rel @ z_cam
    ok = depth > 1e-6
    depth = np.where(ok, depth, 1.0)
    u = matrix[0, 0] * (rel @ x_cam) / depth + matrix[0, 2]
    v = matrix[1, 1] * (rel @ y_cam) / depth + matrix[1, 2]
    return u, v, ok


def repitched(x, y, mounting, turn_deg):
    """Floor points (robot frame) found with `mounting`, moved to where they lie if the camera
    looks `turn_deg` further down than the mounting says: each pixel's ray turned down as much
    (exact for a camera turned about its own sideways axis; a pitch off by d draws a point
    d_true ahead of the lens at (d_true + h tan d) / (1 - d_true tan d / h), and its sideways
    distance 1 / (cos d (1 - d_true tan d / h)). turn_deg may be an array, broadcast against
    x and y: the points at each of several turns in one array, each turn's part the same
    numbers as alone."""
    t, cos = _tan_cos(turn_deg)
    ahead = np.asarray(x, float) - mounting.forward
    scale = np.maximum(1.0 + ahead * t / mounting.height, 1e-3)  # (beyond the horizon: far)
    return (mounting.forward + (ahead - mounting.height * t) / scale,
            np.asarray(y, float) / (scale * cos))


def _tan_cos(degrees):
    """tan and cos of an angle [deg], or of each of an array of them (math's, value by value)."""
    if np.ndim(degrees) == 0:
        return math.tan(math.radians(degrees)), math.cos(math.radians(degrees))
    flat = [math.radians(v) for v in np.ravel(degrees)]
    shape = np.shape(degrees)
    return (np.reshape([math.tan(v) for v in flat], shape),
            np.reshape([math.cos(v) for v in flat], shape))
