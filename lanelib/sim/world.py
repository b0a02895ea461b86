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


@dataclass(frozen=True)
class Paint:
    """A painted line of a world, beside the track's centre line."""

    offset: float  # [lane widths] + to the left of the robot's lane centre
    colour: tuple  # BGR
    width: float  # [m]
    dashes: tuple = None  # (on, off) [m], or None: solid


WHITE, YELLOW, RED = (235, 235, 235), (20, 200, 235), (40, 40, 210)


@dataclass(frozen=True)
class World:
    """What the floor looks like round a track: its surface, its paint, its light, the camera.

    lines: empty for the lecture's two grey tapes (Scene's floor and tape levels)."""

    name: str = 'lecture'
    floor: str = 'plain'  # plain | mats (foam mats with seams) | wood (planks)
    floor_colour: tuple = (95, 95, 95)  # BGR
    lines: tuple = ()  # Paint
    lane_width: float = None  # [m] between the lane's line centres; None: the track's
    stop_every: float = 0.0  # [m] a red stop line across the lane this often; 0: none
    lighting: float = 0.0  # the light over the floor varies by up to this fraction
    shadows: int = 0  # dark patches on the floor
    cast: tuple = (1.0, 1.0, 1.0)  # BGR gains: the light's colour and the white balance
    blur: int = 0  # [px] motion blur along the image rows
    camera: str = 'lecture'  # lecture | duckiebot (lanelib.camera.CAMERAS)
    mounting: tuple = None  # (height [m], pitch [deg], forward [m]); None: the track's
    lane: str = 'lecture'  # the lane profile (lanelib/lanes.py) that describes its lines


def _duckietown_lines():
    """A two-lane Duckietown road, the robot in the right lane: white right edge, yellow
    dashed centre line (2 in pieces, 1 in gaps), white left edge of the other lane."""
    return (Paint(-0.5, WHITE, 0.05), Paint(0.5, YELLOW, 0.025, (0.05, 0.025)),
            Paint(1.5, WHITE, 0.05))


WORLDS = {
    'lecture': World(),
    'wood': World('wood', floor='wood', floor_colour=(60, 110, 160),
                  lines=(Paint(-0.5, WHITE, 0.03), Paint(0.5, WHITE, 0.03)), lighting=0.3,
                  shadows=4, cast=(0.85, 0.95, 1.1), mounting=(0.20, 15.0, 0.10)),
    'duckietown': World('duckietown', floor='mats', floor_colour=(45, 45, 45),
                        lines=_duckietown_lines(), lane_width=0.2375, stop_every=2.5,
                        lighting=0.25, shadows=3, cast=(1.05, 1.0, 0.9), camera='duckiebot',
                        mounting=(0.10, 20.0, 0.05), lane='duckietown'),
    'autorace': World('autorace', floor='plain', floor_colour=(70, 70, 70),
                      lines=(Paint(-0.5, WHITE, 0.015), Paint(0.5, YELLOW, 0.015)),
                      lane_width=0.285, lighting=0.2, shadows=2, camera='duckiebot',
                      mounting=(0.12, 25.0, 0.05), lane='autorace'),
}


def segment_shape(seg):
    """(length [m], curvature [1/m, + left]) of a track segment: {"straight": metres} or
    {"arc": {"radius": m, "angle_deg": deg}}."""
    if 'straight' in seg:
        return float(seg['straight']), 0.0
    radius, angle = float(seg['arc']['radius']), math.radians(float(seg['arc']['angle_deg']))
    return radius * abs(angle), math.copysign(1.0 / radius, angle)


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
            length, curvature = segment_shape(seg)
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

    def curvature_at(self, s):
        """The centre line's curvature [1/m, + bending left] at arc length s (the segment's
        that s lies in; beyond the end, the last one's)."""
        start = 0.0
        for seg in self.segments:
            length, curvature = segment_shape(seg)
            start += length
            if s < start:
                break
        return curvature

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


class ColourFloorMap:
    """A world's floor drawn from above in colour (BGR): its surface, its light and shadows,
    its painted lines and stop lines. Seeded, so a run can be repeated."""

    def __init__(self, track, world, gaps=(), dashes=None, seed=0, margin=3.5, res=FLOOR_RES):
        c = track.centre
        normal = np.stack([-np.sin(c[:, 2]), np.cos(c[:, 2])], axis=1)
        w = track.lane_width
        lines = [(paint, c[:, :2] + paint.offset * w * normal) for paint in world.lines]
        pts = np.vstack([xy for _, xy in lines] + [c[:, :2]])
        self.origin = pts.min(axis=0) - margin
        size = np.ceil((pts.max(axis=0) + margin - self.origin) / res).astype(int) + 1
        self.res, self.world = res, world
        rng = np.random.default_rng(seed)
        canvas = _surface(world, size[1], size[0], res, self.origin, rng)
        for paint, xy in lines:
            side = 'left' if paint.offset == 0.5 else 'right' if paint.offset == -0.5 else None
            pattern = dashes if (dashes and side) else (
                dict(line='both', on=paint.dashes[0], off=paint.dashes[1]) if paint.dashes
                else None)
            painted = tape_painted(c[:, 3], side or 'none', gaps if side else (), pattern)
            self._paint(canvas, xy, painted, paint.colour, paint.width)
        if world.stop_every > 0:
            for s_stop in np.arange(world.stop_every, track.length, world.stop_every):
                i = int(np.searchsorted(c[:, 3], s_stop))
                a = c[i, :2] + 0.5 * w * normal[i]
                b = c[i, :2] - 0.5 * w * normal[i]
                self._paint(canvas, np.array([a, b]), np.ones(2, bool), RED, 0.05)
        for _ in range(world.shadows):  # a patch of shade somewhere near the track
            centre = c[rng.integers(len(c)), :2] + rng.normal(0.0, 0.3, 2)
            corners = centre + rng.normal(0.0, 0.35, (5, 2))
            shade = np.zeros(canvas.shape[:2], np.uint8)
            cv2.fillPoly(shade, [np.round(self.to_pixels(corners)).astype(np.int32)], 255)
            shade = cv2.GaussianBlur(shade, (0, 0), 0.03 / res) / 255.0
            canvas *= (1.0 - 0.35 * shade)[..., None]
        self.image = np.clip(np.round(canvas), 0, 255).astype(np.uint8)

    def _paint(self, canvas, xy, painted, colour, width):
        px = np.round((xy - self.origin) / self.res * 16).astype(np.int32)
        thickness = max(1, int(round(width / self.res)))
        for run in np.split(np.arange(len(xy)), np.flatnonzero(np.diff(painted)) + 1):
            if painted[run[0]] and len(run) > 1:
                cv2.polylines(canvas, [px[run].reshape(-1, 1, 2)], False, colour, thickness,
                              cv2.LINE_AA, shift=4)

    def to_pixels(self, xy):
        return (xy - self.origin) / self.res


def _surface(world, height, width, res, origin, rng):
    """The bare floor (float32 BGR), with its texture and the light over it."""
    base = np.array(world.floor_colour, np.float32)
    floor = np.empty((height, width, 3), np.float32)
    floor[:] = base
    grain = rng.normal(0.0, 1.0, (height, width)).astype(np.float32)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    wx, wy = origin[0] + xx * res, origin[1] + yy * res
    if world.floor == 'mats':  # foam mats: a fine relief and seams every 61 cm
        floor += 6.0 * cv2.GaussianBlur(grain, (0, 0), 1.0)[..., None]
        seam = (np.abs(((wx + 0.305) % 0.61) - 0.305) > 0.302) | \
            (np.abs(((wy + 0.305) % 0.61) - 0.305) > 0.302)
        floor[seam] += 18.0
    elif world.floor == 'wood':  # planks 12 cm wide along x, each its own tone, grain, seams
        plank = np.floor(wy / 0.12).astype(int)
        tone = rng.normal(0.0, 12.0, plank.max() - plank.min() + 1)[plank - plank.min()]
        streak = cv2.resize(rng.normal(0.0, 1.0, (height, max(1, width // 40))).astype(
            np.float32), (width, height))
        floor += (tone + 8.0 * streak)[..., None] * np.array([0.6, 0.8, 1.0], np.float32)
        floor[(wy % 0.12) < 0.004] *= 0.55
    else:
        floor += 2.0 * grain[..., None]
    if world.lighting:  # a smooth field of light over the floor, a cell a metre across
        cells = rng.uniform(-1.0, 1.0, (int(height * res) + 2, int(width * res) + 2))
        light = cv2.resize(cells.astype(np.float32), (width, height),
                           interpolation=cv2.INTER_CUBIC)
        floor *= (1.0 + world.lighting * np.clip(light, -1.0, 1.0))[..., None]
    return floor


class ChessboardFloor:
    """A chessboard lying flat on a plain floor in front of the robot, drawn from above like
    FloorMap (255 white, 0 black, the floor 110), as lanelib/mounting.py says to lay it: its
    `pattern` (columns x rows of inner corners) with the columns across the robot, centred on
    its centre line, the nearest row of inner corners `board_ahead` metres ahead, a white
    margin of one square round it."""

    def __init__(self, pattern, square, board_ahead, res=0.001, size=3.5):
        cols, rows = pattern
        self.res = res
        self.origin = np.array([-0.5, -size / 2])
        n = int(round(size / res))
        canvas = np.full((n, n), 110, np.uint8)
        x0, y0 = board_ahead - 2 * square, -(cols + 3) / 2 * square  # the margin's corner
        margin = np.array([[x0, y0], [x0 + (rows + 3) * square, y0],
                           [x0 + (rows + 3) * square, -y0], [x0, -y0]])
        cv2.fillPoly(canvas, [self._px(margin)], 255, cv2.LINE_AA, shift=4)
        for i in range(rows + 1):
            for j in range(cols + 1):
                if (i + j) % 2:
                    continue
                x, y = board_ahead + (i - 1) * square, (j - (cols + 1) / 2) * square
                corners = np.array([[x, y], [x + square, y], [x + square, y + square],
                                    [x, y + square]])
                cv2.fillPoly(canvas, [self._px(corners)], 0, cv2.LINE_AA, shift=4)
        self.image = canvas

    def _px(self, xy):
        return np.round((xy - self.origin) / self.res * 16).astype(np.int32).reshape(-1, 1, 2)


def chessboard_view(camera, mounting, pattern, square, board_ahead, noise=2.0, seed=0):
    """What `camera` mounted so on a Kobuki sees of a ChessboardFloor: one BGR frame, for
    calibration.py --ground."""
    board = ChessboardFloor(pattern, square, board_ahead)
    return FloorCamera(camera, mounting).render(board, (0.0, 0.0, 0.0),
                                                Scene(floor=20.0, tape=235.0, noise=noise),
                                                np.random.default_rng(seed))


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
        d = ray_directions(self._norm[..., 0], self._norm[..., 1], self.mounting.pitch_deg,
                           self.mounting.roll_deg)
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
        if floor_map.image.ndim == 3:
            return self._render_colour(floor_map, mx, my, hit, yaw, scene, rng)
        tape = cv2.remap(floor_map.image, mx, my, cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        img = scene.floor + ((scene.tape - scene.floor) / 255.0) * tape
        img = self._finish(np.where(hit, img, self._wall(yaw, scene)), scene, rng)
        gray = np.clip(np.round(img), 0, 255).astype(np.uint8)
        return cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)

    def _wall(self, yaw, scene):
        """Beyond the floor, a wall whose brightness changes by direction in 12 degree
        panels."""
        panel = np.floor((self._azimuth + yaw + math.pi) / math.radians(12)).astype(int) % 30
        wall_levels = scene.wall + 60 * np.sin(np.arange(30) * 2.39996)  # golden-angle spread
        return wall_levels[panel]

    def _finish(self, img, scene, rng):
        """Supersampling, the light's gradient and glare, and the camera's noise."""
        n = self.supersample
        h, w = img.shape[0] // n, img.shape[1] // n
        img = img.reshape((h, n, w, n) + img.shape[2:]).mean(axis=(1, 3))
        per_pixel = (lambda a: a[..., None]) if img.ndim == 3 else (lambda a: a)
        if scene.gradient:
            img = img + per_pixel(scene.gradient * (np.linspace(-0.5, 0.5, w)[None, :]))
        if scene.glare:
            yy, xx = np.mgrid[0:h, 0:w]
            img = img + per_pixel(scene.glare * np.exp(-(((xx - w * 0.55) / (w * 0.12)) ** 2
                                                        + ((yy - h * 0.7) / (h * 0.12)) ** 2)))
        if scene.noise:
            rng = rng if rng is not None else np.random.default_rng(0)
            img = img + rng.normal(0.0, scene.noise, img.shape)
        return img

    def _render_colour(self, floor_map, mx, my, hit, yaw, scene, rng):
        world = floor_map.world
        img = cv2.remap(floor_map.image, mx, my, cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_CONSTANT, borderValue=0).astype(np.float32)
        wall = self._wall(yaw, scene).astype(np.float32)
        img[~hit] = wall[~hit][:, None]
        img *= np.array(world.cast, np.float32)
        n = self.supersample
        if world.blur:
            img = cv2.blur(img, (world.blur * n, 1))
        h, w = img.shape[0] // n, img.shape[1] // n
        img = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)  # the n x n means
        if scene.gradient:
            img += (scene.gradient * np.linspace(-0.5, 0.5, w, dtype=np.float32))[None, :, None]
        if scene.glare:
            yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
            img += (scene.glare * np.exp(-(((xx - w * 0.55) / (w * 0.12)) ** 2
                                           + ((yy - h * 0.7) / (h * 0.12)) ** 2)))[..., None]
        if scene.noise:
            rng = rng if rng is not None else np.random.default_rng(0)
            img += scene.noise * rng.standard_normal(img.shape, dtype=np.float32)
        return np.clip(np.round(img), 0, 255).astype(np.uint8)
