"""The simulator's world: what a camera on a Kobuki sees of tape lines on the floor.

The track is drawn once from above into a floor map (FLOOR_RES metres per pixel). Each camera
pixel's ray, through the lens distortion, is intersected with the floor once per mounting;
rendering a pose is then one cv2.remap from the floor map. Rays that miss the floor, or hit it
beyond `max_range`, see a wall whose brightness changes with direction (furniture, doors):
extra edges above the lane, like the lecture's "camera's view" for algorithm 1.0.

Frames and the camera's mounting: lanelib/geometry.py.
"""

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from lanelib.geometry import Mounting, ray_directions, rays_to_floor
from lanelib.robot import arc_step

FLOOR_RES = 0.003  # [m/px] floor map resolution (a pixel 3 m ahead covers about 3.4 mm)


@dataclass
class Scene:
    floor: float = 95.0  # floor brightness [0-255]
    tape: float = 235.0  # tape brightness [0-255]
    noise: float = 3.0  # frame noise sigma [grey levels]
    max_range: float = 3.0  # [m] floor visible up to here, then a wall
    wall: float = 150.0  # mean wall brightness [0-255]
    gradient: float = 0.0  # lighting gradient across the frame, left to right [grey levels]
    glare: float = 0.0  # brightness added by a glare patch near the image centre [grey levels]


@dataclass
class Track:
    """A lane of two tape lines either side of a centre line made of straights and arcs.

    segments: [{"straight": metres}, {"arc": {"radius": m, "angle_deg": deg}}, ...];
    positive angle_deg turns left. The centre line starts at (0, 0) heading along +x.
    """

    lane_width: float = 0.35  # [m] between the tape centres
    tape_width: float = 0.03  # [m]
    segments: list = field(default_factory=lambda: [{'straight': 3.0}])
    start: tuple = (0.0, 0.0, 0.0)  # centre line start (x, y, heading) [m, m, rad]
    step: float = 0.005  # [m] centre line sampling

    def __post_init__(self):
        self.centre = self._sample()  # (N, 4): x, y, heading, s

    def _sample(self):
        x, y, h = self.start
        pts, s = [(x, y, h, 0.0)], 0.0
        for seg in self.segments:
            if 'straight' in seg:
                length, curvature = float(seg['straight']), 0.0
            else:
                arc = seg['arc']
                radius, angle = float(arc['radius']), math.radians(float(arc['angle_deg']))
                length, curvature = radius * abs(angle), math.copysign(1.0 / radius, angle)
            n = max(1, int(math.ceil(length / self.step)))
            ds = length / n
            for _ in range(n):
                x, y, h = arc_step(x, y, h, 1.0, curvature, ds)  # unit speed: t is length
                s += ds
                pts.append((x, y, h, s))
        return np.array(pts)

    @property
    def length(self):
        return float(self.centre[-1, 3])

    def pose_at(self, s, offset=0.0, yaw_error=0.0):
        """Robot pose at arc length s, `offset` metres left of the centre line, yawed."""
        i = int(np.clip(np.searchsorted(self.centre[:, 3], s), 0, len(self.centre) - 1))
        x, y, h, _ = self.centre[i]
        return (x - offset * math.sin(h), y + offset * math.cos(h), h + yaw_error)

    def tape_lines(self):
        """The two tape centre lines as (N, 2) arrays: left, right."""
        c = self.centre
        normal = np.stack([-np.sin(c[:, 2]), np.cos(c[:, 2])], axis=1)
        half = self.lane_width / 2
        return c[:, :2] + half * normal, c[:, :2] - half * normal


def tape_painted(s, side, gaps=(), dashes=None):
    """Where along the track (arc lengths s) the tape on `side` is laid."""
    painted = np.ones(len(s), bool)
    if dashes and dashes['line'] in (side, 'both'):
        painted &= (s % (dashes['on'] + dashes['off'])) < dashes['on']
    for gap in gaps:
        if gap['line'] in (side, 'both'):
            painted &= ~((s >= gap['at']) & (s < gap['at'] + gap['length']))
    return painted


class FloorMap:
    """The track drawn from above: 255 where there is tape, 0 where there is floor."""

    def __init__(self, track, gaps=(), dashes=None, margin=3.5, res=FLOOR_RES):
        left, right = track.tape_lines()
        pts = np.vstack([left, right])
        self.origin = pts.min(axis=0) - margin
        size = np.ceil((pts.max(axis=0) + margin - self.origin) / res).astype(int) + 1
        self.res = res
        canvas = np.zeros((size[1], size[0]), np.uint8)
        thickness = max(1, int(round(track.tape_width / res)))
        s = track.centre[:, 3]
        for side, line in (('left', left), ('right', right)):
            painted = tape_painted(s, side, gaps, dashes)
            px = np.round((line - self.origin) / res * 16).astype(np.int32)  # 4 bits subpixel
            for run in np.split(np.arange(len(s)), np.flatnonzero(np.diff(painted)) + 1):
                if painted[run[0]] and len(run) > 1:
                    cv2.polylines(canvas, [px[run].reshape(-1, 1, 2)], False, 255, thickness,
                                  cv2.LINE_AA, shift=4)
        self.image = canvas

    def to_pixels(self, xy):
        return (xy - self.origin) / self.res


class FloorCamera:
    """Renders the onboard view of a track from a robot pose."""

    def __init__(self, camera, mounting=None, supersample=2):
        self.camera = camera
        self.mounting = mounting or Mounting()
        self.supersample = supersample
        w, h = camera.image_size
        n = supersample
        # subpixel centres of every pixel, through the lens, to normalised rays
        us = (np.arange(w * n) + 0.5) / n - 0.5
        vs = (np.arange(h * n) + 0.5) / n - 0.5
        uu, vv = np.meshgrid(us, vs)
        pix = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float64).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
        norm = cv2.undistortPointsIter(pix, camera.matrix, camera.distortion, None, None, crit)
        self._norm = norm.reshape(h * n, w * n, 2)
        d = ray_directions(self._norm[..., 0], self._norm[..., 1], self.mounting.pitch_deg)
        self._azimuth = np.arctan2(d[..., 1], d[..., 0])  # ray direction, robot frame [rad]
        self._hits = {}

    def floor_hits(self, max_range):
        """Per subpixel: floor point (x, y) in the robot frame, and whether it is on the floor."""
        if max_range not in self._hits:
            self._hits[max_range] = self._floor_hits(max_range)
        return self._hits[max_range]

    def _floor_hits(self, max_range):
        m = self.mounting
        x, y, ok = rays_to_floor(self._norm[..., 0], self._norm[..., 1], m)
        return x, y, ok & (np.hypot(x - m.forward, y) <= max_range)

    def render(self, floor_map, pose, scene=None, rng=None):
        """One BGR frame of the floor at robot pose (x, y, yaw)."""
        scene = scene or Scene()
        x, y, hit = self.floor_hits(scene.max_range)
        px, py, yaw = pose
        c, s = math.cos(yaw), math.sin(yaw)
        wx = px + c * x - s * y
        wy = py + s * x + c * y
        mx = ((wx - floor_map.origin[0]) / floor_map.res).astype(np.float32)
        my = ((wy - floor_map.origin[1]) / floor_map.res).astype(np.float32)
        mx[~hit] = -1
        my[~hit] = -1
        tape = cv2.remap(floor_map.image, mx, my, cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        img = scene.floor + ((scene.tape - scene.floor) / 255.0) * tape
        # the wall: brightness by world direction of the ray, in 12 degree panels
        panel = np.floor((self._azimuth + yaw + math.pi) / math.radians(12)).astype(int) % 30
        wall_levels = scene.wall + 60 * np.sin(np.arange(30) * 2.39996)  # golden-angle spread
        img = np.where(hit, img, wall_levels[panel])
        n = self.supersample
        h, w = img.shape[0] // n, img.shape[1] // n
        img = img.reshape(h, n, w, n).mean(axis=(1, 3))
        if scene.gradient:
            img = img + scene.gradient * (np.linspace(-0.5, 0.5, w)[None, :])
        if scene.glare:
            yy, xx = np.mgrid[0:h, 0:w]
            img = img + scene.glare * np.exp(-(((xx - w * 0.55) / (w * 0.12)) ** 2
                                               + ((yy - h * 0.7) / (h * 0.12)) ** 2))
        if scene.noise:
            rng = rng if rng is not None else np.random.default_rng(0)
            img = img + rng.normal(0.0, scene.noise, img.shape)
        gray = np.clip(np.round(img), 0, 255).astype(np.uint8)
        return cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
