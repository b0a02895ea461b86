"""The simulator as a frame source: a Kobuki-like base on a track, seen through its camera.

Each read moves the base up to the current time on the clock of the rospy stand-in (or real
ROS) with the Twists the node's loop has published, which reach it through `ros.listeners`,
then renders the onboard view. A run ends when the robot completes the track, departs the lane
(its centre more than half a lane width from the centre line), stalls (no 5 cm of progress in
30 s), or reaches its time limit. Also: the benchmark's conditions (VARIANTS) and the pictures
(TopDown, SideBySide).
"""

import json
import math

import cv2
import numpy as np

from lanelib.camera import CAMERAS
from lanelib.improved import ImprovedParams
from lanelib.outputs import VideoSink
from lanelib.robot import ODOM_TOPIC, VELOCITY_TOPIC
from lanelib.rospy_standin import Odometry
from lanelib.sim.base import DiffDriveBase
from lanelib.sim.world import ColourFloorMap, FloorCamera, FloorMap, Track

STALL_TIME = 30.0  # [s] without 5 cm of progress ends a run


def improved_params(spec, mounting=None):
    """The improved controller's settings for a track: its camera mounting (or `mounting`, what
    the controller is told, e.g. measured by calibration.py --ground), its lane width and the
    lane profile of its world."""
    m = mounting or spec.mounting
    return ImprovedParams(camera_height=m.height, camera_pitch=m.pitch_deg,
                          camera_forward=m.forward, camera_roll=m.roll_deg,
                          lane_width=spec.track.lane_width, lane=spec.world.lane)


def floor_map(spec, track=None, seed=0):
    """The floor a track's camera sees: the lecture's grey tapes, or its world in colour (made
    once per track, world, gaps and dashes in a process: a coloured floor takes seconds)."""
    track = track or spec.track
    if not spec.world.lines:
        return FloorMap(track, spec.gaps, spec.dashes)
    key = (json.dumps([track.segments, track.lane_width, track.tape_width, spec.gaps,
                       spec.dashes], sort_keys=True), spec.world, seed)
    if key not in _COLOUR_FLOORS:
        _COLOUR_FLOORS.clear()  # one at a time: each is tens of megabytes
        _COLOUR_FLOORS[key] = ColourFloorMap(track, spec.world, spec.gaps, spec.dashes, seed)
    return _COLOUR_FLOORS[key]


_COLOUR_FLOORS = {}


def odometry_message(x, y, yaw):
    """The stand-in's nav_msgs/Odometry at pose (x, y, yaw)."""
    msg = Odometry()
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return msg


class TrackSimulator:
    """A frame source that is a robot on a track; it hears the node's Twists via `ros`."""

    live = False
    skipped = 0
    total = None

    def __init__(self, spec, ros, seed=0, time_limit=None, keep_going=False, start_offset=0.0,
                 start_yaw=0.0, limits=None, odometry=False):
        self.spec, self.ros = spec, ros
        track = spec.track
        # open tracks go on straight beyond the finish so the camera still sees tape there
        shown = track if spec.closed else Track(track.lane_width, track.tape_width,
                                                 track.segments + [{'straight': 3.5}])
        self.floor_map = floor_map(spec, shown)
        self.camera = FloorCamera(CAMERAS[spec.camera], spec.mounting)
        ros.listeners.append(lambda t, topic, msg: topic == VELOCITY_TOPIC and
                             self.base.command(t, msg.linear.x, msg.angular.z))
        # the base's odometry on /odom, as kobuki_node publishes it (odometry=True)
        self.odom = ros.Publisher(ODOM_TOPIC, Odometry, queue_size=10) if odometry else None
        self.rng = np.random.default_rng(seed)
        self.seed = seed
        self.keep_going = keep_going
        self._start = (start_offset, start_yaw, limits, time_limit)
        self.frames = 0
        self.restart(0.0)

    def restart(self, t0):
        """Put the robot back at the start at time t0, for a new run on the same track."""
        offset, yaw, limits, time_limit = self._start
        track = self.spec.track
        self.base = DiffDriveBase(track.pose_at(0.0, offset, yaw), limits, t0=t0,
                                  seed=self.seed)
        self.time_limit = t0 + (time_limit or (track.length / 0.04 + 30.0))
        self.history = []  # (t, x, y, s, offset)
        self.departure_points = []
        self.ended = None
        self._idx = 0
        self._departed = False
        self._best = (0.0, t0)  # (progress s, time reached)

    def where(self):
        """Arc length along the centre line and signed offset (+ left) of the robot."""
        c = self.spec.track.centre
        lo, hi = max(0, self._idx - 60), min(len(c), self._idx + 400)
        d = np.hypot(c[lo:hi, 0] - self.base.x, c[lo:hi, 1] - self.base.y)
        self._idx = lo + int(np.argmin(d))
        cx, cy, heading, s = c[self._idx]
        offset = -(self.base.x - cx) * math.sin(heading) + (self.base.y - cy) * math.cos(heading)
        return s, offset

    def truth(self):
        """Where the robot is in its lane now: (offset [m, + left of the centre line], heading
        [rad, + turned left of the line's direction], the line's curvature there [1/m]), the
        signs of the improved controller's estimate (ImprovedController.extra)."""
        s, offset = self.where()
        heading = self.base.pose[2] - self.spec.track.centre[self._idx, 2]
        heading = (heading + math.pi) % (2 * math.pi) - math.pi
        return offset, heading, self.spec.track.curvature_at(s)

    def _check(self, t):
        s, offset = self.where()
        self.history.append((t, self.base.x, self.base.y, s, offset))
        out = abs(offset) > self.spec.track.lane_width / 2
        if out and not self._departed:
            self.departure_points.append((self.base.x, self.base.y))
        self._departed = out
        if s > self._best[0] + 0.05:
            self._best = (s, t)
        if s >= self.spec.track.length - 0.02:
            return 'completed'
        if out and not self.keep_going:
            return 'departure'
        if t >= self.time_limit:
            return 'time limit'
        if t - self._best[1] > STALL_TIME:
            return 'stalled'
        return None

    def read(self):
        t = self.ros.clock.now()
        self.base.advance(t)
        self.ended = self.ended or self._check(t)
        if self.ended:
            return False, None, None
        if self.odom is not None:
            self.odom.publish(odometry_message(*self.base.odometry))
        frame = self.camera.render(self.floor_map, self.base.pose, self.spec.scene, self.rng)
        self.frames += 1
        return True, frame, self.frames - 1

    def release(self):
        pass

    def metrics(self, controller):
        h = np.array(self.history) if self.history else np.zeros((1, 5))
        t = float(h[-1, 0])
        length = self.spec.track.length
        offsets = h[:, 4]
        return dict(track=self.spec.name, world=self.spec.world.name, controller=controller,
                    completed=self.ended == 'completed',
                    progress=round(min(1.0, float(h[:, 3].max()) / length), 4),
                    distance_m=round(self.base.distance, 3), time_s=round(t, 2),
                    mean_speed_mps=round(self.base.distance / t, 4) if t > 0 else 0.0,
                    rms_offset_m=round(float(np.sqrt(np.mean(offsets ** 2))), 4),
                    max_offset_m=round(float(np.abs(offsets).max()), 4),
                    departures=len(self.departure_points), ended=self.ended,
                    frames=self.frames, seed=self.seed, track_length_m=round(length, 3))


class TopDown:
    """The track from above, in pixels; the driven path coloured by offset."""

    def __init__(self, sim, size=480):
        self.sim = sim
        left, right = sim.spec.track.tape_lines()
        pts = np.vstack([left, right])
        lo, hi = pts.min(axis=0) - 0.4, pts.max(axis=0) + 0.4
        self.scale = size / float(max(hi - lo))
        self.lo = lo
        self.shape = (int((hi[1] - lo[1]) * self.scale) + 1, int((hi[0] - lo[0]) * self.scale) + 1)
        self.background = np.full(self.shape + (3,), 40, np.uint8)
        for line in (left, right):
            cv2.polylines(self.background, [self.px(line)], False, (200, 200, 200), 2,
                          cv2.LINE_AA)

    def px(self, xy):
        xy = np.asarray(xy, float).reshape(-1, 2)
        u = (xy[:, 0] - self.lo[0]) * self.scale
        v = self.shape[0] - 1 - (xy[:, 1] - self.lo[1]) * self.scale
        return np.stack([u, v], axis=1).round().astype(np.int32).reshape(-1, 1, 2)

    def draw(self, title=None):
        img = self.background.copy()
        h = np.array(self.sim.history) if self.sim.history else None
        half = self.sim.spec.track.lane_width / 2
        if h is not None and len(h) > 1:
            pts = self.px(h[:, 1:3])
            level = np.clip(np.abs(h[:, 4]) / half * 255, 0, 255).astype(np.uint8)
            colours = cv2.applyColorMap(level.reshape(-1, 1), cv2.COLORMAP_JET).reshape(-1, 3)
            for i in range(len(pts) - 1):
                cv2.line(img, tuple(pts[i, 0]), tuple(pts[i + 1, 0]),
                         tuple(int(c) for c in colours[i]), 2, cv2.LINE_AA)
        for x, y in self.sim.departure_points:
            u, v = self.px([x, y])[0, 0]
            cv2.drawMarker(img, (int(u), int(v)), (0, 0, 255), cv2.MARKER_TILTED_CROSS, 14, 2)
        base = self.sim.base
        nose = [base.x + 0.15 * math.cos(base.yaw), base.y + 0.15 * math.sin(base.yaw)]
        cv2.arrowedLine(img, tuple(self.px([base.x, base.y])[0, 0]), tuple(self.px(nose)[0, 0]),
                        (255, 255, 255), 2, tipLength=0.4)
        if title:  # in a band of its own above the track, never over it
            lines = title.split('\n')
            band = np.full((16 * len(lines) + 8, img.shape[1], 3), 20, np.uint8)
            for i, text in enumerate(lines):
                cv2.putText(band, text, (6, 16 + 16 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.42,
                            (255, 255, 255), 1, cv2.LINE_AA)
            img = np.vstack([band, img])
        cv2.putText(img, 'path colour: |offset| 0 (blue) .. half a lane (red); x: departure',
                    (6, img.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.36, (220, 220, 220), 1,
                    cv2.LINE_AA)
        return img


class SideBySide(VideoSink):
    """Annotated onboard view beside the top-down view, for --video."""

    def __init__(self, path, fps, topdown):
        super().__init__(path, fps)
        self.topdown = topdown

    def write(self, image):
        top = self.topdown.draw()
        h = image.shape[0]
        top = cv2.resize(top, (int(top.shape[1] * h / top.shape[0]), h))
        super().write(np.hstack([image, top]))


VARIANTS = {  # the robustness conditions of the benchmark
    'clean': {},
    'noise 10': dict(noise=10.0),
    'lighting gradient': dict(gradient=80.0),
    'gap 20 cm': dict(gap=0.2),
}


def apply_variant(spec, variant):
    """The track with a benchmark condition: noise, a lighting gradient, or a gap."""
    cond = VARIANTS[variant]
    if 'noise' in cond:
        spec.scene.noise = cond['noise']
    if 'gradient' in cond:
        spec.scene.gradient = cond['gradient']
    if 'gap' in cond:
        # 40 % of the way along every built-in track is in a left bend, where the right (outer)
        # tape is the only one in view: the gap takes away all the camera sees
        spec.gaps = spec.gaps + [dict(line='right', at=0.4 * spec.track.length,
                                      length=cond['gap'])]
    return spec
