"""The improved controller: the lane's offset, heading and curvature from the Hough segments
projected onto the floor, and a PD steering law on them. The lecture's answer to its own
closing remark: "you have to do continuous estimation of the angle how much to turn".

Perception uses the lecture's stages (undistort, gray, blur, Canny, mask, HoughLinesP) with
settings for the floor: the mask is the floor band `roi_near`..`roi_far` metres ahead given
by the camera model, and Hough accepts shorter segments. Each segment is projected onto the
floor (camera matrix + mounting), sorted to the left or right line by which side of the
predicted centre line it lies, shifted half a lane width towards the centre, and a centre line
y = a + b x + c x^2 (robot frame: x ahead, y left) is fitted to all of it. One line is enough,
since the lane width is known. The fit is blended over time with a prediction from the
commanded motion, weighted by a confidence. No lane for `lost_timeout` seconds: stop.

Lane memory (`memory` seconds, 0 for none): the camera sees the floor from about 0.6 m ahead,
so the lane between the robot and there is only known from earlier frames. The centre-line
points of each frame are kept in the frame the robot started in, moved by dead reckoning on the
commanded motion; they sort the next frame's segments to left and right (where the latest
estimate, extrapolated, can be a lane off at a gap or an S-bend), and steering looks at the
remembered centre line `memory_lookahead` ahead instead of the latest fit. With too little
remembered there (the first frames) it steers on the latest estimate as below. The robot still
stops after `lost_timeout` without a lane in view, memory or not.

Steering looks at the fitted centre line a distance L ahead, where the segments are (a short
piece of one line seen on a bend is not extrapolated back to the robot): its lateral position
y_L and its slope there. The commanded path curvature is
    k_cmd = alpha * 2 y_L / L^2 + (1 - alpha) * slope_L / L,     angular.z = v * k_cmd.
On a circle of radius R both terms are 1/R, so there is no steady-state error. With offset e
[m, + left of centre] and heading h [rad, + turned left], y_L ~ -e - L h + L^2 / 2R and
slope_L ~ -h + L / R, so this is PD on offset (gain 2 alpha / L^2) and heading (gain
(1 + alpha) / L) with curvature feed-forward; alpha = 1 is pure pursuit, alpha = 3 (damping
ratio 0.82) closes in on the centre line about 1.7 times faster per metre. angular.z is
saturated to `omega_max`; speed is `v_max`, reduced on bends and when the confidence is low.
"""

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from lanelib.camera import LECTURE_CAMERA, undistortion_maps
from lanelib.fast import FastPipeline
from lanelib.geometry import Mounting, floor_to_row, pixels_to_floor
from lanelib.robot import STOP, Command, arc_step
from lanelib.settings import finite, fraction, non_negative, positive, setting


@dataclass
class ImprovedParams:
    """The improved controller's settings: perception, estimate, steering."""

    camera_height: float = setting(0.20, 'camera lens above the floor', 'm', positive)
    camera_pitch: float = setting(0.0, 'camera optical axis below horizontal', 'deg',
                                  finite)
    camera_forward: float = setting(0.10, 'camera lens ahead of the robot centre', 'm',
                                    finite)
    lane_width: float = setting(0.35, 'between the tape centres', 'm', positive)
    roi_near: float = setting(0.3, 'floor mask starts this far ahead (clipped to the view)', 'm',
                              positive)
    roi_far: float = setting(1.2, 'floor mask ends this far ahead', 'm', positive)
    hough_rho_improved: float = setting(2.0, 'HoughLinesP rho for the improved perception',
                                        'px', positive)
    hough_threshold_improved: int = setting(30, 'HoughLinesP votes for the improved perception',
                                            'votes', positive)
    min_line_length_improved: float = setting(20.0, 'HoughLinesP minLineLength, improved', 'px',
                                              finite)
    max_line_gap_improved: float = setting(10.0, 'HoughLinesP maxLineGap, improved', 'px',
                                           finite)
    max_edge_fraction: float = setting(0.15, 'a frame whose floor mask is more than this '
                                       'fraction edge pixels (dense texture) is not read: Hough '
                                       'is skipped, which bounds the time per frame', '',
                                       fraction)
    max_segments: int = setting(60, 'at most this many segments used per frame (the longest); '
                                'bounds the work on cluttered frames', '', positive)
    smoothing: float = setting(0.6, 'weight of a full-confidence measurement against the '
                               'prediction', '', fraction)
    lost_timeout: float = setting(1.0, 'stop when no lane has been seen for this long', 's',
                                  positive)
    v_max: float = setting(0.35, 'forward speed on a straight, confident lane', 'm/s',
                           positive)
    v_min: float = setting(0.08, 'forward speed never drops below this while driving', 'm/s',
                           positive)
    curve_slowdown: float = setting(0.4, 'speed divided by (1 + this x |curvature|)', 'm',
                                    finite)
    lookahead: float = setting(0.9, 'steer at the centre line this far ahead, or nearer where '
                               'the lane is seen nearer', 'm', positive)
    lookahead_min: float = setting(0.6, 'the look-ahead never comes closer than this', 'm',
                                   positive)
    lateral_gain: float = setting(3.0, 'alpha: weight of the look-ahead offset against its '
                                  'direction (1 = pure pursuit)', '', positive)
    omega_max: float = setting(1.5, 'turn rate limit', 'rad/s', positive)
    memory: float = setting(4.0, 'remember the centre line seen this long (dead reckoning on '
                            'the commands) and steer on it; 0: steer on the latest estimate '
                            'only', 's', non_negative)
    memory_lookahead: float = setting(0.55, 'with memory: steer at the remembered centre line '
                                      'this far ahead', 'm', positive)
    memory_window: float = setting(0.25, 'with memory: fit the points this far either side of '
                                   'the look-ahead', 'm', positive)
    dead_band: float = setting(0.05, "angular.z within this is recorded as 'straight'", 'rad/s',
                               finite)

    @property
    def mounting(self):
        return Mounting(self.camera_height, self.camera_pitch, self.camera_forward)


@dataclass
class LaneEstimate:
    a: float  # centre line y at x = 0 [m]
    b: float  # slope of the centre line at x = 0
    c: float  # half its curvature [1/m]
    confidence: float  # 0..1
    left: int = 0  # segments on the left line
    right: int = 0  # segments on the right line
    reach: float = 1.0  # [m] mean distance ahead of the points the fit rests on
    points: tuple = None  # the centre-line points the fit rests on: x, y, weight (robot frame)

    @property
    def offset(self):  # robot left of the lane centre [m]
        return -self.a

    @property
    def heading(self):  # robot turned left of the lane direction [rad]
        return -math.atan(self.b)

    @property
    def curvature(self):  # the lane bends left [1/m]
        return 2 * self.c / (1 + self.b ** 2) ** 1.5


def floor_roi(width, height, p, camera=None, margin=4):
    """Mask (255 = keep) of the floor band roi_near..roi_far ahead. With a calibration, less
    the border that undistortion leaves empty: its edge would otherwise look like a line."""
    matrix = (camera or LECTURE_CAMERA).scaled_to(width, height).matrix
    top = int(np.clip(math.floor(floor_to_row(p.roi_far, matrix, p.mounting)), 0, height))
    bottom = int(np.clip(math.ceil(floor_to_row(p.roi_near, matrix, p.mounting)), top, height))
    mask = np.zeros((height, width), np.uint8)
    mask[top:bottom] = 255
    if camera is not None:
        white = np.full((height, width), 255, np.uint8)
        filled = cv2.remap(white, *undistortion_maps(camera, width, height),
                           cv2.INTER_LINEAR) == 255
        filled = cv2.erode(filled.astype(np.uint8) * 255, np.ones((3, 3), np.uint8),
                           iterations=margin)
        mask = cv2.bitwise_and(mask, filled)
    return mask


def floor_segments(lines, matrix, p):
    """Segments projected onto the floor, sampled every 5 cm: a list of (x, y, weight, phi)."""
    lines = np.asarray(lines, float).reshape(-1, 4)
    if len(lines) == 0:
        return []
    lengths = np.hypot(lines[:, 2] - lines[:, 0], lines[:, 3] - lines[:, 1])
    lines = lines[np.argsort(-lengths)[:p.max_segments]]
    x, y, ok = pixels_to_floor(lines.reshape(-1, 2, 2), matrix, p.mounting)
    keep = ok.all(axis=1) & (x.max(axis=1) < p.roi_far + 1.0)
    out = []
    for (x0, x1), (y0, y1) in zip(x[keep], y[keep]):
        if x1 < x0:  # direction ambiguity: make every segment point ahead
            x0, x1, y0, y1 = x1, x0, y1, y0
        length, phi = math.hypot(x1 - x0, y1 - y0), math.atan2(y1 - y0, x1 - x0)
        if length < 0.04 or abs(phi) > math.radians(70):
            continue
        t = np.linspace(0.0, 1.0, max(2, int(length / 0.05) + 1))
        out.append((x0 + t * (x1 - x0), y0 + t * (y1 - y0), length / len(t), phi))
    return out


def fit_sides(segments, guess, half):
    """Sort segments to the left or right line of the centre line `guess` (a, b, c), move
    them half a lane towards the centre, refit; a few rounds. Returns (a, b, c), the sides
    and the weighted mean squared misfit of the lines to the fit."""
    a, b, c = guess
    w = np.concatenate([np.full(len(sx), wt) for sx, _, wt, _ in segments])
    for _ in range(4):
        sides = np.array([1.0 if np.mean(sy - (a + b * sx + c * sx ** 2)) > 0 else -1.0
                          for sx, sy, _, _ in segments])
        cx = np.concatenate([sx + side * half * math.sin(phi)
                             for (sx, _, _, phi), side in zip(segments, sides)])
        cy = np.concatenate([sy - side * half * math.cos(phi)
                             for (_, sy, _, phi), side in zip(segments, sides)])
        a, b, c = fit_centre(cx, cy, w)
    misfit = float(np.sum(w * (cy - (a + b * cx + c * cx ** 2)) ** 2) / w.sum())
    return (a, b, c), sides, misfit, (cx, cy, w)


def measure(lines, matrix, p, prior=None):
    """One frame's LaneEstimate from its segments, or None when they show no lane."""
    segments = floor_segments(lines, matrix, p)
    if not segments:
        return None
    guesses = [(0.0, 0.0, 0.0), (0.0, 0.0, 0.4), (0.0, 0.0, -0.4)]
    if prior is not None:
        guesses.insert(0, (prior.a, prior.b, prior.c))
    half = p.lane_width / 2
    fits = [fit_sides(segments, g, half) for g in guesses]

    def score(i):
        (a, _, _), _, misfit, _ = fits[i]
        if prior is not None:  # the prediction wins unless a guess explains the lines better
            return misfit * (0.5 if i == 0 else 1.0)
        # with no history, one line fits as well on either side: take the robot in its lane
        return misfit + max(0.0, abs(a) - half) ** 2

    best = min(range(len(fits)), key=score)
    (a, b, c), sides, _, points = fits[best]
    total = sum(len(sx) * wt for sx, _, wt, _ in segments)
    left, right = int(np.sum(sides > 0)), int(np.sum(sides < 0))
    confidence = min(1.0, total / 1.0) * (1.0 if left and right else 0.7)
    reach = sum(float(np.sum(sx)) * wt for sx, _, wt, _ in segments) / total
    return LaneEstimate(a, b, c, confidence, left, right, reach, points)


def fit_centre(x, y, w, ridge=0.05):
    """Weighted least squares y = a + b x + c x^2, with c pulled towards 0 on short spans."""
    columns = [np.ones_like(x), x, x ** 2]
    A = np.stack(columns, axis=1) * np.sqrt(w)[:, None]
    rhs = y * np.sqrt(w)
    reg = np.diag([0.0, 1e-4, ridge]) * w.sum()
    coef = np.linalg.solve(A.T @ A + reg, A.T @ rhs)
    return float(coef[0]), float(coef[1]), float(coef[2])


def predict(est, v, omega, dt):
    """The centre line as seen after driving `dt` seconds at (v, omega)."""
    ds, dtheta = v * dt, omega * dt
    a = est.a + est.b * ds + est.c * ds ** 2
    b = est.b + 2 * est.c * ds - dtheta * (1 + est.b ** 2)
    return replace(est, a=a, b=b, confidence=est.confidence * 0.8)


def blend(pred, meas, weight):
    return LaneEstimate(pred.a + weight * (meas.a - pred.a), pred.b + weight * (meas.b - pred.b),
                        pred.c + weight * (meas.c - pred.c),
                        pred.confidence + weight * (meas.confidence - pred.confidence),
                        meas.left, meas.right, meas.reach)


def steer(est, p):
    """(linear.x, angular.z) for a lane estimate: PD at the look-ahead, see the module doc."""
    x = float(np.clip(est.reach, p.lookahead_min, p.lookahead))
    return drive(est.a + est.b * x + est.c * x ** 2, est.b + 2 * est.c * x, x, est, p)


def drive(y, slope, x, est, p):
    """(linear.x, angular.z) towards the centre line at y with `slope`, x metres ahead."""
    k = p.lateral_gain * 2 * y / x ** 2 + (1 - p.lateral_gain) * slope / x  # [1/m]
    v = p.v_max / (1 + p.curve_slowdown * abs(k)) * (0.5 + 0.5 * est.confidence)
    v = float(np.clip(v, p.v_min, p.v_max))
    return v, float(np.clip(v * k, -p.omega_max, p.omega_max))


class LaneMemory:
    """The centre-line points seen in the last `seconds`, kept in the frame the robot started
    in (dead reckoning on the commanded motion), so that the lane is known between the robot
    and the nearest floor the camera sees."""

    def __init__(self, seconds):
        self.seconds = seconds
        self.pose = np.zeros(3)  # x, y, yaw of the robot in the start frame
        self.t = 0.0
        self.chunks = []  # (time, X, Y, weight)

    def move(self, v, omega, dt):
        self.pose = np.array(arc_step(*self.pose, v, omega, dt))
        self.t += dt
        self.chunks = [c for c in self.chunks if self.t - c[0] <= self.seconds]

    def add(self, x, y, w):
        px, py, yaw = self.pose
        cos, sin = math.cos(yaw), math.sin(yaw)
        self.chunks.append((self.t, px + cos * x - sin * y, py + sin * x + cos * y, w))

    def local(self):
        """All remembered points in the robot's frame now: x, y, weight."""
        if not self.chunks:
            return np.empty(0), np.empty(0), np.empty(0)
        px, py, yaw = self.pose
        X = np.concatenate([c[1] for c in self.chunks]) - px
        Y = np.concatenate([c[2] for c in self.chunks]) - py
        w = np.concatenate([c[3] for c in self.chunks])
        cos, sin = math.cos(yaw), math.sin(yaw)
        return cos * X + sin * Y, -sin * X + cos * Y, w

    def clear(self):
        self.chunks = []

    def centre_line(self, near, far, min_span, outlier=None):
        """(a, b, c) of the remembered centre line fitted between near and far metres ahead,
        or None with fewer than 6 points there or spanning less than min_span. With
        `outlier` [m], two more rounds drop the points that far off the fit (points sorted to
        the wrong line, a lane width off)."""
        x, y, w = self.local()
        keep = (x > near) & (x < far)
        if np.count_nonzero(keep) < 6 or np.ptp(x[keep]) < min_span:
            return None
        x, y, w = x[keep], y[keep], w[keep]
        coef = fit_centre(x, y, w)
        for _ in range(2 if outlier else 0):
            keep = np.abs(y - (coef[0] + coef[1] * x + coef[2] * x ** 2)) < outlier
            if np.count_nonzero(keep) < 6:
                break
            coef = fit_centre(x[keep], y[keep], w[keep])
        return coef


def steer_memory(memory, est, p):
    """(linear.x, angular.z) from the remembered centre line around p.memory_lookahead, or
    None when too little of it is remembered there."""
    L, half = p.memory_lookahead, p.memory_window
    coef = memory.centre_line(L - half, L + half, half, outlier=0.08)
    if coef is None:
        return None
    a, b, c = coef
    return drive(a + b * L + c * L ** 2, b + 2 * c * L, L, est, p)


class ImprovedController:
    """Perceive -> estimate -> steer, one frame at a time; drop-in for kobuki_lane.LectureRule.

    lane_params: the lecture's settings (blur, Canny, rate); reference: kobuki_lane.detect,
    which the fast pipeline hands what it cannot speed up; p: ImprovedParams; camera: the
    calibration (None: frames as they come, with the lecture camera's geometry scaled to them).
    """

    name = 'improved'

    def __init__(self, lane_params, reference, p=None, camera=LECTURE_CAMERA):
        self.p = p or ImprovedParams()
        self.camera = camera
        self.dt = 1.0 / lane_params.rate
        self.detect_params = replace(  # the lecture's blur and Canny settings stay
            lane_params, hough_rho=self.p.hough_rho_improved, hough_theta=math.pi / 180,
            hough_threshold=self.p.hough_threshold_improved,
            min_line_length=self.p.min_line_length_improved,
            max_line_gap=self.p.max_line_gap_improved)
        self.estimate = None
        self.lost_for = math.inf  # [s] since the lane was last seen
        self.last = (0.0, 0.0)  # the last command (v, omega)
        self.cluttered = False  # the last frame had too many edges to read
        self.matrix = None  # the undistorted frame's camera matrix
        self._roi = {}  # mask per (camera, width, height)
        self.pipeline = FastPipeline(self.detect_params, reference,
                                     max_edge_fraction=self.p.max_edge_fraction)
        self.memory = LaneMemory(self.p.memory) if self.p.memory > 0 else None

    def roi(self, width, height):
        """The floor band's mask for this camera and frame size."""
        key = (id(self.camera), width, height)
        if key not in self._roi:
            self._roi[key] = floor_roi(width, height, self.p, self.camera)
        return self._roi[key]

    def perceive(self, frame, keep_stages=False):
        h, w = frame.shape[:2]
        # with no calibration the pixels are taken as the lecture camera's, scaled to the frame
        self.matrix = (self.camera or LECTURE_CAMERA).scaled_to(w, h).matrix
        return self.pipeline(frame, self.camera, keep_stages, roi=self.roi(w, h))

    def __call__(self, detection):
        p = self.p
        self.cluttered = detection.cluttered
        prior = predict(self.estimate, *self.last, self.dt) if self.estimate else None
        guide = prior  # the centre line the segments are sorted to left and right against
        if self.memory is not None:
            self.memory.move(*self.last, self.dt)
            remembered = self.memory.centre_line(0.2, 1.2, 0.3)
            if remembered is not None and prior is not None:
                guide = replace(prior, a=remembered[0], b=remembered[1], c=remembered[2])
        meas = measure(detection.lines, self.matrix, p, guide)
        if meas is not None:
            self.lost_for = 0.0
            self.estimate = blend(prior, meas, p.smoothing * meas.confidence) if prior else meas
        else:
            self.lost_for += self.dt
            self.estimate = prior
        if self.memory is not None and meas is not None:
            self.memory.add(*meas.points)
        if self.estimate is None or self.lost_for > p.lost_timeout:
            self.last = (0.0, 0.0)
            if self.memory is not None:
                self.memory.clear()
            return STOP
        steered = steer_memory(self.memory, self.estimate, p) if self.memory else None
        v, omega = steered or steer(self.estimate, p)
        self.last = (v, omega)
        decision = ('left' if omega > p.dead_band else
                    'right' if omega < -p.dead_band else 'straight')
        return Command(decision, v, omega)

    def extra(self):
        """The estimate, for the decision records."""
        e = self.estimate
        if e is None:
            return dict(offset_m=None, heading_rad=None, curvature=None, confidence=0.0,
                        lane_lost_s=None, cluttered=self.cluttered)
        return dict(offset_m=round(e.offset, 4), heading_rad=round(e.heading, 4),
                    curvature=round(e.curvature, 4), confidence=round(e.confidence, 3),
                    lane_lost_s=round(min(self.lost_for, 1e6), 3), cluttered=self.cluttered)
