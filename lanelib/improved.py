"""The improved controller: the lane's offset, heading and curvature from the lines on the
floor, and a PD steering law on them. The lecture's answer to its own closing remark: "you have
to do continuous estimation of the angle how much to turn".

Perception looks at the floor band `roi_near`..`roi_far` metres ahead (from the camera model),
undistorted the fast pipeline's way. The lane profile (`lane`, lanelib/lanes.py) says what
its lines look like: their colours (white, yellow, or any colour lighter than the floor) and
the tapes' width. Pixels of those colours, judged in the light of each frame
(lanelib/colour.py), are cut into nearly straight pieces and projected onto the floor (camera
matrix + mounting); a piece not as wide as the tape is not a line (a seam, a glint, a sheet of
paper), nor is red (stop lines). lanelib/lanefit.py then chooses, among all the lines in view,
the robot's own lane, the one whose left and right lines the pieces best support with the
colours allowed on each side (a neighbouring lane, a centre line being crossed, the other
colour on a side are not its lines), as an arc (a Duckietown bend turns 90 degrees within half
a metre). One line is enough, since the lane width is known. The estimate is blended over time
with a prediction from the commanded motion, weighted by a confidence. No lane for
`lost_timeout` seconds: stop.

Lane memory (`memory` seconds, 0 for none): the camera sees the floor from about 0.6 m ahead,
so the lane between the robot and there is only known from earlier frames. The centre-line
points of each frame are kept in the frame the robot started in, moved by dead reckoning on the
commanded motion; they guide the next frame's choice of lane (where the latest
estimate, extrapolated, can be a lane off at a gap or an S-bend), the points about the robot
give the offset and heading each new fit is pulled towards (lanefit.find_lane's anchor: the
lines seen far ahead fix them only through a long lever), and steering looks at the
remembered centre line `memory_lookahead` ahead instead of the latest fit. With too little
remembered there (the first frames) it steers on the latest estimate as below. After
`lost_timeout` without a lane in view it follows the remembered lane while that lasts, then
turns in place towards where the lane went (`search_angle`), then stops (ImprovedController.
command); a lane found after that is pulled towards the estimate moved with the robot, not
towards the memory's points (an arc fitted to the memory of a bend's entry is turned the wrong
way under the robot).

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
from lanelib.colour import colour_masks, floor_boxes, tape_pieces, view_sides
from lanelib.fast import Layout
from lanelib.geometry import Mounting, floor_to_pixels, floor_to_row
from lanelib.lanefit import LaneFit, find_lane, fit_lanes, signed_distance
from lanelib.lanes import load_lane
from lanelib.mounting import BOUNDS as MOUNTING
from lanelib.outputs import draw_curve, text_band, tint
from lanelib.robot import MAX_ANGULAR, MAX_LINEAR, STOP, Command, arc_step, could_move
from lanelib.settings import between, finite, fraction, non_negative, positive, setting
from lanelib.stages import Detection, as_bgr, slope_sum


def lane_spec(spec):
    """A lane profile that loads; lanes.LaneError (a ValueError) says why not."""
    load_lane(spec)
    return True


@dataclass
class ImprovedParams:
    """The improved controller's settings: perception, estimate, steering."""

    camera_height: float = setting(0.20, 'camera lens above the floor', 'm',
                                   MOUNTING['height'])
    camera_pitch: float = setting(0.0, 'camera optical axis below horizontal', 'deg',
                                  MOUNTING['pitch_deg'])
    camera_forward: float = setting(0.10, 'camera lens ahead of the robot centre', 'm',
                                    MOUNTING['forward'])
    camera_roll: float = setting(0.0, "camera turned about its optical axis, + when its right "
                                 'side is lower', 'deg', MOUNTING['roll_deg'])
    lane: str = setting('lecture', 'what the lane looks like: lecture (two tapes of any colour, '
                        '0.35 m), duckietown (yellow dashed left, white right), autorace (yellow '
                        'left, white right), or a lane profile YAML (lanelib/lanes.py)',
                        check=lane_spec)
    lane_width: float = setting(0.0, "between the tape centres; 0: the lane profile's", 'm',
                                non_negative)
    width_tolerance: float = setting(0.3, 'with both lines in view, the width between them is '
                                     'measured, within this fraction of lane_width (a camera '
                                     'pitched a little off makes them look further apart or '
                                     'closer); 0: always lane_width', '', fraction)
    roi_near: float = setting(0.3, 'floor mask starts this far ahead (clipped to the view)', 'm',
                              positive)
    roi_far: float = setting(1.2, 'floor mask ends this far ahead', 'm', positive)
    max_pieces: int = setting(60, 'at most this many pieces of line used per frame (the '
                              'longest); bounds the work on cluttered frames, which are marked '
                              "'cluttered' in the decision records", '', positive)
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
    search_angle: float = setting(45.0, 'lane lost and nothing remembered ahead: turn in place '
                                  'towards where it was last seen going, up to this angle, then '
                                  'stop; 0: no search, stop at once', 'deg', between(0, 360))
    search_rate: float = setting(0.5, 'turn rate while searching', 'rad/s', positive)
    search_time: float = setting(6.0, 'the search gives up after this long whatever the angle',
                                 's', positive)
    turn_offset: float = setting(0.5, "the decision recorded: 'left' or 'right' when the lane's "
                                 'centre lies more than this many lane widths to that side at '
                                 'the look-ahead distance (going straight, the robot would be '
                                 "out of its lane there), 'straight' otherwise", 'lane widths',
                                 positive)

    @property
    def mounting(self):
        return Mounting(self.camera_height, self.camera_pitch, self.camera_forward,
                        self.camera_roll)

    def clipped(self):
        """Warnings for settings the Kobuki's limits will cut down (every command is clipped
        to them, and recorded as sent)."""
        said = []
        for name, value, limit, unit in (('v_max', self.v_max, MAX_LINEAR, 'm/s'),
                                         ('v_min', self.v_min, MAX_LINEAR, 'm/s'),
                                         ('omega_max', self.omega_max, MAX_ANGULAR, 'rad/s')):
            if value > limit:
                said.append(f'{name} = {value:g} {unit} is above the Kobuki\'s {limit:.2f} '
                            f'{unit}: commands are clipped to it')
        return said


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
    width: float = None  # [m] between the lines, as measured

    @property
    def offset(self):  # robot left of the lane centre [m]
        return -self.a

    @property
    def heading(self):  # robot turned left of the lane direction [rad]
        return -math.atan(self.b)

    @property
    def curvature(self):  # the lane bends left [1/m]
        return 2 * self.c / (1 + self.b ** 2) ** 1.5

    @property
    def arc(self):  # (e, psi, k) of the arc it starts as, lanefit's shape
        return self.a, math.atan(self.b), self.curvature

    def lateral_at(self, distance):
        """How far to the left [m] the centre line lies `distance` metres from the robot,
        following it as the arc it starts as (a polynomial in x cannot turn 90 degrees)."""
        return LaneFit((self.a, math.atan(self.b), self.curvature), None, 0, 0,
                       None).point_at(distance)[1]


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


def arc_points(est, lengths, offset=0.0):
    """Points (x, y) of the estimate's centre line, as the arc it starts as, at arc lengths
    `lengths`, moved `offset` [m] to its left."""
    psi, k = math.atan(est.b), est.curvature
    h = psi + k * lengths
    if abs(k) < 1e-4:
        x, y = lengths * math.cos(psi), est.a + lengths * math.sin(psi)
    else:
        x = (np.sin(h) - math.sin(psi)) / k
        y = est.a + (math.cos(psi) - np.cos(h)) / k
    return x - offset * np.sin(h), y + offset * np.cos(h)


def measure_lane(pieces, profile, p, prior=None, anchor=None):
    """One frame's LaneEstimate from pieces of line with their colours (lanefit.find_lane),
    or None when less than a quarter lane width's length of the lane's lines is seen or the
    robot would be more than half a lane outside the lane found; and the lanefit.LaneFit it
    rests on (or None). prior: the arc (e, psi, k) of the lane expected; anchor: (offset,
    heading) of the lane expected at the robot, if known better than the prior's
    (lanefit.find_lane)."""
    fit = find_lane(pieces, profile, p.lane_width, prior, width_tolerance=p.width_tolerance,
                    anchor=anchor)
    if fit is None or fit.left + fit.right < 0.25 * p.lane_width or abs(fit.e) > fit.width:
        # too little line seen, or a lane the robot would be more than half a lane outside:
        # not the robot's lane
        return None, fit
    b = math.tan(fit.psi)
    confidence = (min(1.0, (fit.left + fit.right) / (2.9 * p.lane_width)) *
                  (1.0 if fit.left and fit.right else 0.7))
    cx, _, cw = fit.centre
    return LaneEstimate(fit.e, b, fit.k * (1 + b * b) ** 1.5 / 2, confidence,
                        int(np.sum(fit.sides == 1)), int(np.sum(fit.sides == -1)),
                        float(np.average(cx, weights=cw)), fit.centre, fit.width), fit


def fit_centre(x, y, w, ridge=0.05, x0=0.0):
    """Weighted least squares y = a + b x + c x^2, with c pulled towards 0 on short spans.
    The pull acts on the curve written about x0 (put x0 amid the points): there a and b are
    what the points say, whatever becomes of c (written about 0, pulling c on a short span far
    ahead would tilt the line instead of bending it)."""
    u = x - x0
    A = np.stack([np.ones_like(u), u, u ** 2], axis=1) * np.sqrt(w)[:, None]
    reg = np.diag([0.0, 1e-4, ridge]) * w.sum()
    a, b, c = np.linalg.solve(A.T @ A + reg, A.T @ (y * np.sqrt(w)))
    return float(a - b * x0 + c * x0 ** 2), float(b - 2 * c * x0), float(c)


def predict(est, ds, dtheta):
    """The centre line as seen after the robot drove `ds` [m] and turned `dtheta` [rad]."""
    a = est.a + est.b * ds + est.c * ds ** 2
    b = est.b + 2 * est.c * ds - dtheta * (1 + est.b ** 2)
    return replace(est, a=a, b=b, confidence=est.confidence * 0.8)


def blend(pred, meas, weight):
    return LaneEstimate(pred.a + weight * (meas.a - pred.a), pred.b + weight * (meas.b - pred.b),
                        pred.c + weight * (meas.c - pred.c),
                        pred.confidence + weight * (meas.confidence - pred.confidence),
                        meas.left, meas.right, meas.reach, width=meas.width)


def steer(est, p):
    """(linear.x, angular.z, y) for a lane estimate: PD at the look-ahead (see the module
    doc); y [m] is where the centre line lies, to the left, at the point steered at."""
    x = float(np.clip(est.reach, p.lookahead_min, p.lookahead))
    return drive(est.a + est.b * x + est.c * x ** 2, est.b + 2 * est.c * x, x, est, p)


def drive(y, slope, x, est, p):
    """(linear.x, angular.z, y) towards the centre line at y with `slope`, x metres ahead."""
    k = p.lateral_gain * 2 * y / x ** 2 + (1 - p.lateral_gain) * slope / x  # [1/m]
    v = p.v_max / (1 + p.curve_slowdown * abs(k)) * (0.5 + 0.5 * est.confidence)
    v = float(np.clip(v, p.v_min, p.v_max))
    return v, float(np.clip(v * k, -p.omega_max, p.omega_max)), y


class LaneMemory:
    """The centre-line points seen in the last `seconds`, kept in the frame the robot started
    in (dead reckoning on the commanded motion), so that the lane is known between the robot
    and the nearest floor the camera sees."""

    def __init__(self, seconds):
        self.seconds = seconds
        self.pose = np.zeros(3)  # x, y, yaw of the robot in the start frame
        self.t = 0.0
        self.chunks = []  # (time, X, Y, weight)
        self._local = None  # local()'s answer until the robot moves or points come or go

    def move(self, v, omega, dt):
        """Dead reckoning: `dt` seconds at (v, omega)."""
        self._moved_to(np.array(arc_step(*self.pose, v, omega, dt)), dt)

    def move_by(self, ahead, left, turned, dt):
        """The robot moved `ahead` and `left` [m] and turned `turned` [rad] (in its frame before
        the move) in `dt` seconds: from odometry."""
        px, py, yaw = self.pose
        c, s = math.cos(yaw), math.sin(yaw)
        self._moved_to(np.array([px + c * ahead - s * left, py + s * ahead + c * left,
                                 yaw + turned]), dt)

    def _moved_to(self, pose, dt):
        """The robot is at `pose` `dt` seconds later: points older than `seconds` are gone."""
        self.pose = pose
        self.t += dt
        self.chunks = [c for c in self.chunks if self.t - c[0] <= self.seconds]
        self._local = None

    def add(self, x, y, w):
        px, py, yaw = self.pose
        cos, sin = math.cos(yaw), math.sin(yaw)
        self.chunks.append((self.t, px + cos * x - sin * y, py + sin * x + cos * y, w))
        self._local = None

    def local(self):
        """All remembered points in the robot's frame now: x, y, weight (worked out once per
        pose and set of points: a frame asks for them up to three times)."""
        if self._local is None:
            if not self.chunks:
                return np.empty(0), np.empty(0), np.empty(0)
            px, py, yaw = self.pose
            X = np.concatenate([c[1] for c in self.chunks]) - px
            Y = np.concatenate([c[2] for c in self.chunks]) - py
            w = np.concatenate([c[3] for c in self.chunks])
            cos, sin = math.cos(yaw), math.sin(yaw)
            self._local = (cos * X + sin * Y, -sin * X + cos * Y, w)
        return self._local

    def clear(self):
        self.chunks = []
        self._local = None

    def centre_line(self, near, far, min_span, outlier=None):
        """(a, b, c) of the remembered centre line fitted between near and far metres ahead,
        or None with fewer than 6 points there or spanning less than min_span. With
        `outlier` [m], two more rounds drop the points that far off the fit (points sorted to
        the wrong line, a lane width off)."""
        x, y, w = self.local()
        keep = (x > near) & (x < far)
        if np.count_nonzero(keep) < 6 or np.ptp(x[keep]) < min_span:
            return None
        x, y, w, middle = x[keep], y[keep], w[keep], (near + far) / 2
        coef = fit_centre(x, y, w, x0=middle)
        for _ in range(2 if outlier else 0):
            keep = np.abs(y - (coef[0] + coef[1] * x + coef[2] * x ** 2)) < outlier
            if np.count_nonzero(keep) < 6:
                break
            coef = fit_centre(x[keep], y[keep], w[keep], x0=middle)
        return coef


def remembered_arc(memory, start, reach=1.0, outlier=0.06):
    """The remembered centre line within `reach` metres of the robot as an arc (e, psi, k)
    through the robot (lanefit's shape: it can turn any angle, which a polynomial in x, as in
    LaneMemory.centre_line, cannot), refined from `start` (e, psi, k), dropping points
    `outlier` metres off it; None with fewer than 6 points."""
    x, y, w = memory.local()
    keep = np.hypot(x, y) < reach
    if np.count_nonzero(keep) < 6:
        return None
    x, y, w = x[keep], y[keep], w[keep]
    arc = np.array([[*start, 0.0]], float)
    hold = ([1e-6 * w.sum()] * 3 + [0.0], [0.0] * 4)
    for _ in range(3):
        arc = fit_lanes(x, y, np.zeros((1, len(x))), w[None, :], arc, hold, (0.0, 0.0),
                        iterations=6)
        near = np.abs(signed_distance(x, y, *arc[0, :3])) < outlier
        if np.count_nonzero(near) < 6:
            return None
        x, y, w = x[near], y[near], w[near]
    return tuple(float(v) for v in arc[0, :3]), (x, y)


def pursue_memory(memory, est, p):
    """(linear.x, angular.z) along the remembered centre line while no lane is in view: pure
    pursuit of the point memory_lookahead away on the arc fitted to it (exact on an arc), or
    None when the memory does not reach that point (nothing remembered near it)."""
    found = remembered_arc(memory, est.arc)
    if found is None:
        return None
    arc, (x, y) = found
    if abs(arc[0]) > p.lane_width / 4:
        return None  # the robot is not where the memory says the lane is: do not trust it
    L = p.memory_lookahead
    ax, ay, _ = LaneFit(arc, None, 0, 0, None).point_at(L)
    if np.min(np.hypot(x - ax, y - ay)) > 0.1 or ax <= 0:
        return None
    k = 2 * ay / L ** 2
    v = p.v_max / (1 + p.curve_slowdown * abs(k)) * (0.5 + 0.5 * est.confidence)
    v = float(np.clip(v, p.v_min, p.v_max))
    return v, float(np.clip(v * k, -p.omega_max, p.omega_max)), arc


def steer_memory(memory, est, p):
    """(linear.x, angular.z, y) from the remembered centre line around p.memory_lookahead, or
    None when too little of it is remembered there."""
    L, half = p.memory_lookahead, p.memory_window
    coef = memory.centre_line(L - half, L + half, half, outlier=0.08)
    if coef is None:
        return None
    a, b, c = coef
    return drive(a + b * L + c * L ** 2, b + 2 * c * L, L, est, p)


class ImprovedController:
    """Perceive -> estimate -> steer, one frame at a time; drop-in for kobuki_lane.LectureRule.

    lane_params: the lecture's settings (its rate); p: ImprovedParams; camera: the calibration
    (None: frames as they come, with the lecture camera's geometry scaled to them); profile: a
    lanes.LaneProfile instead of the one p.lane names; mark: called with each stage's name as
    it ends ('start', 'undistort', 'colour', 'pieces', then 'lane' and 'steer' in the call),
    for tools/bench.py.
    """

    name = 'improved'

    def __init__(self, lane_params, p=None, camera=LECTURE_CAMERA, profile=None,
                 mark=None, odometry=None):
        p = p or ImprovedParams()
        self.mark = mark or (lambda stage: None)
        self.profile = profile or load_lane(p.lane)
        # the lane width: the profile's, unless given
        self.p = replace(p, lane_width=p.lane_width or self.profile.lane_width)
        # lines are cut into pieces this long [m]: a quarter lane, and three times as long as
        # the widest tape is wide, so that a piece's direction is along the line
        self.piece_length = max(0.25 * self.p.lane_width,
                                3 * max(self.profile.left.width, self.profile.right.width))
        self.camera = camera
        self.odometry = odometry  # a topics.Odometry: the memory follows it while it comes
        self.dt = 1.0 / lane_params.rate
        self.cluttered = False  # the last frame had more than max_pieces pieces of line
        self.last_sides = None  # the side of each piece of the last frame (pictures)
        self.matrix = None  # the undistorted frame's camera matrix
        self._roi = {}  # mask per (camera, width, height)
        self.lane_params = lane_params
        self._layout = None  # the floor band's undistortion, the fast pipeline's way
        self._band = None  # (band key, view_sides and floor_boxes of the floor band)
        # the estimate, the time since the lane was last seen [s], the last command (v, omega)
        # and the lane memory
        self.reset()

    def reset(self):
        """Forget the lane: the next frame is read as if it were the first."""
        self.estimate, self.lost_for, self.last = None, math.inf, (0.0, 0.0)
        self.t = None  # when the last frame was read
        self.odom_pose = None  # the odometry's pose at the last frame, while it comes
        self.search = None  # while searching: [direction, angle turned [rad], time [s]]
        self.memory = LaneMemory(self.p.memory) if self.p.memory > 0 else None

    def layout(self, width, height, roi):
        """fast.Layout of the floor band: undistortion maps made once, only its rows done."""
        lay = self._layout
        if lay is None or not lay.matches(width, height, self.camera, roi, self.lane_params):
            self._layout = Layout(width, height, self.camera, roi, self.lane_params)
        return self._layout

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
        detection = Detection(np.empty((0, 4), np.int32), slope_sum(np.empty((0, 4))))
        self.colour_pieces(frame, self.roi(w, h), detection, keep_stages)
        return detection

    def colour_pieces(self, frame, roi, detection, keep_stages):
        """The colour masks of the floor band and the tape pieces they hold, on the detection
        (detection.pieces, detection.masks: the band's masks and its first row)."""
        h, w = frame.shape[:2]
        self.mark('start')
        raw = as_bgr(frame)
        lay = self.layout(w, h, roi)
        if keep_stages or lay.maps is None or not roi.any():  # (no floor in view: no band)
            image = lay.undistort(raw)
            first, band = 0, image
            if detection.image is None:
                detection.set_image(image)
            if keep_stages and detection.stages is None:
                detection.stages = dict(raw=raw, undistorted=image)
        else:
            first, band = lay.first, cv2.cvtColor(lay.undistort_band(raw), cv2.COLOR_BGRA2BGR)
            if detection.image is None:
                detection.set_image(None, lambda: lay.undistort(raw))
        floor = roi[first:first + len(band)]
        self.mark('undistort')
        key = (id(roi), first, len(band))  # the same for every frame of a size
        if self._band is None or self._band[0] != key:  # the band's edge and surroundings
            self._band = (key, view_sides(floor), floor_boxes(floor))
        _, side, surroundings = self._band
        masks = colour_masks(band, floor, self.profile.colours, surroundings)
        self.mark('colour')
        p, pieces = self.p, []
        for colour in self.profile.colours:
            tape = max(line.width for line in (self.profile.left, self.profile.right)
                       if line.colour == colour)
            pieces += tape_pieces(cv2.bitwise_and(masks[colour], floor), colour, self.matrix,
                                  p.mounting, tape, 0.1 * p.lane_width, self.piece_length,
                                  row0=first, side=side)
        pieces.sort(key=lambda piece: -piece.length)
        detection.cluttered = len(pieces) > p.max_pieces
        detection.pieces, detection.masks = pieces[:p.max_pieces], (masks, first)
        self.mark('pieces')

    def elapsed(self, t):
        """Seconds since the last frame: from the frames' times `t` when the loop gives them
        (on a loaded robot frames come later than the rate says, and the memory must move as
        far as the robot did), else one loop period."""
        last, self.t = self.t, t
        if t is None or last is None:
            return self.dt
        dt = max(0.0, t - last)
        return self.dt if abs(dt - self.dt) < 1e-6 else dt  # a clock's rounding is no motion

    def regained(self, meas):
        """Whether a lane found after the robot drove and turned blind is the one it lost: the
        robot has not left its lane (it would have been a departure), so it is inside the lane
        found (within three quarters of a lane width of its centre)."""
        return abs(meas.a) <= 0.75 * self.p.lane_width

    def moved(self, t, dt):
        """How odometry says the robot moved since the last frame, `dt` seconds ago, in the
        robot's frame then: (ahead [m], left [m], turned [rad]); None while it does not come,
        or when it moved further than the robot can (then the controller dead-reckons on the
        command sent)."""
        pose = self.odometry.pose(t) if (self.odometry is not None and t is not None) else None
        last, self.odom_pose = self.odom_pose, pose
        if pose is None or last is None:
            return None
        dx, dy = pose[0] - last[0], pose[1] - last[1]
        c, s = math.cos(last[2]), math.sin(last[2])
        turned = math.atan2(math.sin(pose[2] - last[2]), math.cos(pose[2] - last[2]))
        if not could_move(math.hypot(dx, dy), turned, dt):
            return None  # odometry took a new origin since the last frame: not a motion
        return c * dx + s * dy, -s * dx + c * dy, turned

    def __call__(self, detection, t=None):
        """The command for one frame's detection; t: when the frame was read [s] (ROS time)."""
        p = self.p
        dt = self.elapsed(t)
        self.cluttered = detection.cluttered
        moved = self.moved(t, dt)  # by odometry: (ahead, left, turned); else dead reckoning
        if moved is None:
            ds, dtheta = self.last[0] * dt, self.last[1] * dt
        else:
            ds, dtheta = math.copysign(math.hypot(moved[0], moved[1]), moved[0]), moved[2]
        prior = predict(self.estimate, ds, dtheta) if self.estimate else None
        # the arc the segments are sorted to left and right against, and where the lane is at
        # the robot: the prior's, or the memory's
        guide, anchor = (prior.arc if prior else None), None
        if self.memory is not None:
            if moved is None:
                self.memory.move(*self.last, dt)
            else:
                self.memory.move_by(*moved, dt)
            remembered = self.memory.centre_line(0.2, 1.2, 0.3)
            if remembered is not None and prior is not None:
                guide = replace(prior, a=remembered[0], b=remembered[1], c=remembered[2]).arc
            under = self.memory.centre_line(-0.2, 0.4, 0.2)  # about the robot: no lever
            if under is not None:
                anchor = (under[0], math.atan(under[1]))
            if prior is not None and self.lost_for > p.lost_timeout:
                found = remembered_arc(self.memory, prior.arc)  # any bend, even a U-turn
                if found is not None:
                    # lines are sorted against the remembered arc, but the lane at the robot
                    # is the estimate's, moved with the robot: an arc fitted to the memory of
                    # a bend's entry (straight, then bending) is turned the wrong way there
                    guide, anchor = found[0], prior.arc[:2]
        meas, fit = measure_lane(detection.pieces, self.profile, p, guide, anchor)
        self.mark('lane')
        self.last_sides = None if fit is None else fit.sides
        blind = self.lost_for > p.lost_timeout  # the estimate from before is stale
        if blind and meas is not None and not self.regained(meas):
            meas = None  # another lane (the far leg of a U-turn): keep searching
        if meas is not None:
            self.lost_for, self.search = 0.0, None
            self.estimate = blend(prior, meas, p.smoothing * meas.confidence) if (
                prior and not blind) else meas
        else:
            self.lost_for += dt
            self.estimate = prior
            if self.search is not None:
                self.search[1] += abs(self.last[1]) * dt
                self.search[2] += dt
        if self.memory is not None and meas is not None:
            self.memory.add(*meas.points)
        command = self.command()
        self.last = (command.linear_x, command.angular_z)
        self.mark('steer')
        return command

    def command(self):
        """What to do with the estimate: steer on it (or on the memory) while the lane is seen
        or lost for less than lost_timeout; then follow the remembered lane while it lasts,
        search, and stop when the search is done (see the module doc)."""
        p = self.p
        if self.estimate is None:
            return self.give_up()
        if self.lost_for <= p.lost_timeout:
            steered = None
            if self.memory and self.lost_for > 0:  # not seen now: the remembered arc
                steered = pursue_memory(self.memory, self.estimate, p)
            if self.memory and steered is None:
                steered = steer_memory(self.memory, self.estimate, p)
            v, omega = (steered or steer(self.estimate, p))[:2]
            return Command(self.decision(), v, omega)
        if not p.search_angle:
            return self.give_up()  # the plain stop
        if self.search is None:
            pursued = pursue_memory(self.memory, self.estimate, p) if self.memory else None
            if pursued is not None:
                return Command(self.decision(), *pursued[:2])
            self.search = [self.search_direction(), 0.0, 0.0]
        direction, turned, spent = self.search
        if turned >= math.radians(p.search_angle) or spent >= p.search_time:
            return self.give_up()
        return Command('search', 0.0, direction * p.search_rate)

    def search_direction(self):
        """+1 (left) or -1: where the lane was last seen going, the way the estimate's centre
        line lies at the look-ahead. (The remembered lane's bend was used first: an arc fitted
        to the memory of a U-turn bent the other way on wood's hairpin, and the search turned
        away from the lane and departed, seed 1. On a bend too tight to reach the look-ahead
        the point is the one half way round it: LaneFit.point_at.)"""
        return 1.0 if self.estimate.lateral_at(self.p.lookahead) >= 0 else -1.0

    def sent(self, command):
        """The command that went to the wheels: a stop when the loop held the robot (the ROS
        master lost, a late frame, a lost camera) or a frame failed. The lane memory and the
        prediction move with it, not with what this controller asked for."""
        self.last = (command.linear_x, command.angular_z)

    def give_up(self):
        """No lane, nothing remembered ahead, the search done (or off): stop and forget."""
        self.estimate, self.search = None, None
        if self.memory is not None:
            self.memory.clear()
        return STOP

    def decision(self):
        """'left' or 'right' when the lane's centre lies more than turn_offset lane widths to
        that side at the look-ahead distance (going straight, the robot would be out of its
        lane there), else 'straight'."""
        p = self.p
        y, turn = self.estimate.lateral_at(p.lookahead), p.turn_offset * p.lane_width
        return 'left' if y > turn else 'right' if y < -turn else 'straight'

    # ---------------------------------------------------------------- pictures

    def draw(self, detection, command, lane_params=None):
        """The undistorted frame with the colour masks tinted, the lane's centre (green), left
        (orange) and right (blue) lines on the floor, and what was decided."""
        masks, first = detection.masks
        shown = {c: m for c, m in masks.items() if c in self.profile.colours or c == 'red'}
        image = tint(detection.image, shown, first, alpha=0.35)
        e, p = self.estimate, self.p
        if e is not None and self.matrix is not None:
            s = np.linspace(0.0, p.roi_far, 40)
            for side, colour in ((0, (0, 255, 0)), (1, (0, 160, 255)), (-1, (255, 128, 0))):
                x, y = arc_points(e, s, side * p.lane_width / 2)
                draw_curve(image, x, y, self._to_pixels, colour)
        text = f'{command.decision}  v {command.linear_x:.2f} w {command.angular_z:+.2f}'
        if e is not None:
            text += (f'  offset {100 * e.offset:+.1f} cm  heading '
                     f'{math.degrees(e.heading):+.1f} deg  curvature {e.curvature:+.2f}/m  '
                     f'confidence {e.confidence:.2f}')
        return text_band(image, text)

    def _to_pixels(self, x, y):
        return floor_to_pixels(x, y, self.matrix, self.p.mounting)

    def pictures(self, detection, command, lane_params=None):
        """(key, title, BGR image) of every stage: the frame, undistorted, the floor band, each
        colour mask, the pieces of tape (the lane's by side, the rest grey), the lane."""
        stages = detection.stages or {}
        image = detection.image
        h, w = image.shape[:2]
        band = image.copy()
        band[self.roi(w, h) == 0] //= 3
        out = [('raw', 'raw frame', as_bgr(stages.get('raw', image))),
               ('undistorted', '1 undistorted', image),
               ('floor', f'2 floor {self.p.roi_near:g} to {self.p.roi_far:g} m ahead', band)]
        masks, first = detection.masks
        for name in self.profile.colours + ['red']:
            full = np.zeros((h, w), np.uint8)
            full[first:first + len(masks[name])] = masks[name]
            out.append((f'mask_{name}', f'3 {name} mask', cv2.cvtColor(full, cv2.COLOR_GRAY2BGR)))
        out.append(('pieces', "4 tape pieces: the lane's left, right; others grey",
                    self._pieces_picture(detection, image)))
        out.append(('lane', '5 the lane, the decision', self.draw(detection, command)))
        return out

    def _pieces_picture(self, detection, image):
        picture = (image // 2).copy()
        sides = self.last_sides if self.last_sides is not None else []
        colours = {1: (0, 160, 255), -1: (255, 128, 0), 0: (150, 150, 150)}
        for i, piece in enumerate(detection.pieces):
            side = int(sides[i]) if i < len(sides) else 0
            u, v, ok = self._to_pixels(piece.x, piece.y)
            for a, b in zip(u[ok], v[ok]):
                cv2.circle(picture, (int(a), int(b)), 2, colours[side], -1)
        return picture

    def extra(self):
        """The estimate, for the decision records."""
        e = self.estimate
        if e is None:
            return dict(offset_m=None, heading_rad=None, curvature=None, confidence=0.0,
                        lane_width_m=None, lane_lost_s=None, cluttered=self.cluttered)
        width = None if e.width is None or self.lost_for > 0 else round(e.width, 4)
        return dict(offset_m=round(e.offset, 4), heading_rad=round(e.heading, 4),
                    curvature=round(e.curvature, 4), confidence=round(e.confidence, 3),
                    lane_width_m=width, lane_lost_s=round(min(self.lost_for, 1e6), 3),
                    cluttered=self.cluttered)
