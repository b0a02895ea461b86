"""The improved controller (--controller improved): the lecture's answer to its own closing
remark, "you have to do continuous estimation of the angle how much to turn".

Each frame, in the order the data flows, a module each:

    perceive   lanelib/perception.py: the floor band undistorted, colour masks in the frame's own
               light, the pieces of tape on the floor (camera matrix and mounting)
    estimate   lanelib/estimate.py: the lane predicted from the last frames with the robot's
               motion, the robot's own lane found among the lines in view, the two blended
    memory     lanelib/memory.py: the centre line seen in the last seconds, moved with the robot
    steer      lanelib/steering.py: one law, at the centre line a look-ahead away (the middle of
               the floor between the tapes: ImprovedController.shift)
    pictures   lanelib/lanedraw.py: what it saw and decided, drawn

and here what to do with them (command). The estimate and the memory guide each frame's search
for the lane: the lines are sorted to left and right against the lane expected (the memory's
centre line, else the prediction), and the lane found is pulled towards where the memory has it
at the robot (lines seen far ahead place it there only through a long lever); a lane found
turned at the robot more than `turn_gate` from the prediction, or further than `shift_gate`
across from it, is not the lane (estimate.follows; off by default, the duckiebot preset's 0.5 rad
and 0.5 lane widths), and the frame counts as one without it; but a lane only just found
(fewer than CONFIRMED frames' lanes have followed it) is not defended so: the lane found
replaces it. With
`bend_belief`, the search weighs each lane by how far its curvature lies from the prediction's.
While the lane is seen the robot steers at the remembered centre line `memory_lookahead` ahead
(else at the estimate, as near as it is seen); not seen, it follows the lane remembered round
any turn (an arc through the robot); lost for `lost_timeout`, it follows that while it lasts,
then turns in place towards where the lane went, up to `search_angle`, then stops. A lane found
after that must be the one lost: the robot has not left its lane, so it lies within 3/4 of a
lane width of it.

The robot's motion comes from odometry while it comes (topics.Odometry), else from the commands
sent, for as long as they were sent. Distances and speeds are in lane widths
(ImprovedParams.LANE_WIDTHS), so that one table drives a Kobuki on a 0.35 m lane and a Duckiebot
on a 0.24 m one.
"""

import contextlib
import copy
import math
from dataclasses import dataclass, replace

import numpy as np

from lanelib.camera import LECTURE_CAMERA
from lanelib.estimate import blend, follows, measure, predict
from lanelib.floorpitch import PitchFromMotion
from lanelib.geometry import Mounting
from lanelib.lanedraw import draw_lane, stage_pictures
from lanelib.lanefit import LaneFit
from lanelib.lanes import load_lane
from lanelib.memory import LaneMemory
from lanelib.mounting import BOUNDS as MOUNTING
from lanelib.perception import FloorView, perceive, repitched_pieces
from lanelib.robot import (
    MAX_ANGULAR,
    MAX_LINEAR,
    STOP,
    Command,
    TurnResponse,
    could_move,
    seen_from,
)
from lanelib.settings import between, finite, fraction, non_negative, positive, setting
from lanelib.steering import steer

# where in the memory [lane widths ahead] the lane expected is read: (near, far, least span)
GUIDE = (0.57, 3.43, 0.86)  # the lines are sorted against the centre line remembered here
ANCHOR = (-0.57, 1.14, 0.57)  # about the robot: where the lane is at the robot, no lever
FOLLOW = 2.86  # [lane widths] the lane remembered within this of the robot is followed blind
ARC_OUTLIER = 0.17  # [lane widths] remembered points this far off the arc followed are dropped
TRUSTED = 0.25  # [lane widths] the remembered lane is followed only if the robot is this near it
NEAR_TARGET = 0.29  # [lane widths] and only if something is remembered this near the point
MEMORY_OUTLIER = 0.23  # [lane widths] remembered points this far off the fit are dropped
REGAINED = 0.75  # [lane widths] a lane found after driving blind is the one lost within this
# with pitch_tolerance, each frame with both lines in view moves the pitch correction this
# share of the way to what their splay says: it settles within a second or two at 8 Hz (taken
# only from straight lanes, as the median of 24 of them, it came too late: in gym-duckietown,
# told 2.85 degrees off, loop_empty left its lane within 17 s, 6 of 10 episodes passed against
# 8), and one frame's misfit (a few dashes, a far line's end: a degree or two) moves it a fifth
# as much
REPITCH = 0.2
FLOOR_LAG = 0.3  # [s] with odometry, each frame is compared with the one this long before it
# [s] the pitch correction held at its limit (pitch_tolerance) this long says the camera is
# further off its mounting than the correction may go, and the controller says so, once
# (notice). In the project's simulator, told the camera's pitch, the correction reached its 4
# degree limit for at most 1.6 s on end (the splay's drift in tight corners); told 6 degrees
# off, it sat there from the first seconds, for 5 to 18 s on end (docs/benchmarks.md,
# forty-third session)
PITCH_NOTICE = 5.0
# the gates (turn_gate, shift_gate) defend a lane once this many frames' lanes have followed it
# since it was found: until then a lane found elsewhere replaces it. A first frame, or the first
# after driving blind, can take the wrong lines for the lane (one frame's view of a corner);
# defended at once, it refused the true lane for a whole lost_timeout, and the robot drove on
# the wrong one. gym-duckietown with domain rand, 40 episodes: 35 passed against 34 (loop_empty
# seed 4 passed, where it had left its lane at 9.1 s); with frames read at 320 x 240, 35 against
# 33 (small_loop seeds 6, 13 and 16 had left their lane within 4.5 s of the start)
CONFIRMED = 2


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
    pitch_tolerance: float = setting(0.0, "how far the camera's pitch may be off the mounting "
                                     'given, which draws the floor stretched (or squeezed) the '
                                     'more the further ahead, so that lines parallel on it '
                                     'splay (or close): the lane is fitted with its lines as '
                                     'splayed as this makes them, and the pitch corrected, '
                                     'frame after frame, by what pitch_from says (the '
                                     "correction: pitch_error_deg in the decision records; "
                                     'held at this limit for 5 s, a warning that the camera is '
                                     'further off); 0: the mounting as given, the lines '
                                     'parallel', 'deg',
                                     between(0, 30))
    pitch_from: str = setting('splay', 'what the pitch correction (pitch_tolerance) is read '
                              "from: 'splay' (how far the lane's two lines splay, each frame "
                              "with both in view) or 'motion' (while odometry comes, how the "
                              "floor's tape moves between frames 0.3 s apart: it reads corners "
                              'as well as straights, where the splay takes a corner ahead for '
                              'a pitch, and the lines are fitted parallel; without odometry, '
                              'the splay)',
                              choices=('splay', 'motion'))
    turn_gain: str = setting('assumed', "how much of a turn asked for the base turns: "
                             "'assumed' (all of it, as a base that controls its wheels' speed "
                             "does) or 'measured' (while odometry comes, the ratio of the turns "
                             'it reports to the turns asked for, over blocks of a second, and '
                             'each turn asked for divided by it: a base that turns less than '
                             "asked, as gym-duckietown's Duckiebot turns 0.6 of it, is asked "
                             'for more; at most omega_max)',
                             choices=('assumed', 'measured'))
    read_width: int = setting(0, 'frames wider than this are shrunk to this width (the height '
                              'in proportion, the camera matrix with them) before they are '
                              'read, and the pictures are drawn at that size: a quarter of the '
                              "pixels at half the width, and a tape still several pixels wide "
                              "at the floor band's far end; 0: as they come", 'px',
                              non_negative)
    column_binning: int = setting(2, 'frames (as read_width leaves them) are read with this '
                                  'many columns taken as one, every row kept (binned across by '
                                  'the undistortion itself, the camera matrix with it; the '
                                  "pictures stretched back to the frame's width): the rows say "
                                  'how far ahead the tape lies, and a level camera sees its '
                                  'floor band in few; half the pixels at 2, a tape still '
                                  'several pixels wide; 1: every column', 'columns', positive)
    roi_near: float = setting(0.857, 'floor mask starts this far ahead (clipped to the view)',
                              'lane widths', positive)
    roi_far: float = setting(3.43, 'floor mask ends this far ahead', 'lane widths', positive)
    seen_within: float = setting(0.0, "a lane is started (none confirmed to follow) only by "
                                 "its lines within this far ahead (at least MIN_SEEN lane "
                                 'widths of them, lanelib/estimate.py): far up the view a few '
                                 "pixels span a long stretch of floor, where a glint or a wall's "
                                 'foot can pass for a line; a lane followed is seen by all its '
                                 'lines; 0: the whole floor band always', 'lane widths',
                                 non_negative)
    max_pieces: int = setting(60, 'at most this many pieces of line used per frame (the '
                              'longest); bounds the work on cluttered frames, which are marked '
                              "'cluttered' in the decision records", '', positive)
    smoothing: float = setting(0.6, 'weight of a full-confidence measurement against the '
                               'prediction', '', fraction)
    one_line_width: str = setting('profile', "with one line in view the lane lies half this "
                                  "width beside it: 'profile' (the lane profile's, or "
                                  "lane_width) or 'measured' (the width last measured with "
                                  'both lines in view, which a camera pitched a little off '
                                  'makes more or less than the profile says)',
                                  choices=('profile', 'measured'))
    turn_gate: float = setting(0.0, 'a lane found turned more than this at the robot from the '
                               'lane predicted there is not taken, and the frame counts as one '
                               'without a lane (estimate.follows); 0: off', 'rad',
                               between(0, math.pi))
    shift_gate: float = setting(0.0, 'a lane found further than this across from the lane '
                                'predicted (beside the robot) is not taken, and the frame '
                                'counts as one without a lane (estimate.follows); 0: off',
                                'lane widths', between(0, 10))
    bend_belief: float = setting(0.0, 'with a lane predicted, each lane found is weighed by '
                                 "how far its curvature lies from the prediction's, as a "
                                 'normal distribution this wide: a lane bent the other way is '
                                 'not taken for the longer line it rests on (lanefit.find_lane); '
                                 '0: off', '1/lane width', between(0, 10))
    start_belief: str = setting('centred', 'where the lane is expected until the first lane is '
                                f"confirmed (found in {CONFIRMED} frames running): 'none' "
                                "(wherever the pieces put it) or 'centred' (its centre under the "
                                "robot, running along the robot's heading, where a robot is set "
                                'down: each lane found is pulled a little towards that, and '
                                'lanes found far beside it are weighed down, as later with the '
                                'lane predicted)', choices=('none', 'centred'))
    memory_anchor: str = setting('parabola', 'how the lane at the robot (which each frame\'s '
                                 'search is pulled towards) is read from the memory: '
                                 "'parabola' (the centre line as a parabola in the distance "
                                 f'ahead, fitted {ANCHOR[0]:g} to {ANCHOR[1]:g} lane widths '
                                 "ahead, its points' distances taken across the robot's "
                                 "heading) or 'line' (the straight line nearest the points "
                                 f'within {ANCHOR[1]:g} lane widths of the robot, distances '
                                 'taken square to it: where the lane runs across the view, '
                                 "in a corner tighter than that, those points' distances "
                                 "across the robot's heading are long and pull the parabola "
                                 'aside)', choices=('parabola', 'line'))
    lost_timeout: float = setting(1.0, 'the lane unseen this long: lost (the robot follows the '
                                  'lane remembered while it lasts, then searches, then stops)',
                                  's', positive)
    v_max: float = setting(1.0, 'forward speed on a straight, confident lane',
                           'lane widths/s', positive)
    v_min: float = setting(0.229, 'forward speed never drops below this while driving',
                           'lane widths/s', positive)
    curve_slowdown: float = setting(1.143, 'speed divided by (1 + this x |curvature|)',
                                    'lane widths', finite)
    slow_ahead: float = setting(0.0, "slow down for the bend ahead, not only the turn asked: "
                                'the speed divided by (1 + curve_slowdown x the largest '
                                "|curvature| of the lane found within this far ahead); 0: "
                                'the turn asked only', 'lane widths', non_negative)
    unsure_slowdown: float = setting(0.5, 'the share of the speed taken off when the estimate is '
                                     'unsure (times 1 - confidence): the speed is multiplied '
                                     'by 1 - this x (1 - confidence)', '', fraction)
    lookahead: float = setting(2.571, 'steer at the centre line this far ahead, or nearer where '
                               'the lane is seen nearer', 'lane widths', positive)
    lookahead_min: float = setting(1.714, 'the look-ahead never comes closer than this',
                                   'lane widths', positive)
    lateral_gain: float = setting(3.0, 'alpha: weight of the look-ahead offset against its '
                                  'direction (1 = pure pursuit; lanelib/steering.py)', '',
                                  positive)
    direction: str = setting('slope', "how the steering law reads the centre line's direction "
                             "at the point it steers at: 'slope' (dy/dx, exact for a parabola; "
                             'where that point lies nearly as far round a bend as its radius, '
                             'the slope grows without bound and turns the robot against the '
                             "bend) or 'angle' (its angle, atan(dy/dx): the same on gentle "
                             'lanes, bounded on tight bends; lanelib/steering.py)',
                             choices=('slope', 'angle'))
    omega_max: float = setting(1.5, 'turn rate limit', 'rad/s', positive)
    latency: float = setting(0.0, 'steer on the lane where it will be when the command acts: '
                             'the estimate and the memory moved on by the last command for '
                             "this long (a frame's time from the camera to the wheels); 0: off",
                             's', between(0, 1))
    memory: float = setting(4.0, "remember the centre line seen this long (moved with the "
                            "robot's motion: odometry, else the commands) and steer on it; "
                            '0: steer on the latest estimate only', 's', non_negative)
    memory_points: int = setting(200, "with memory: keep at most this many of a frame's "
                                 'centre-line points (a frame gives about a thousand), evenly '
                                 'spread and carrying the weight of all (each fit on the memory '
                                 'costs time in proportion); 0: every one',
                                 'points', non_negative)
    memory_lookahead: float = setting(1.571, 'with memory: steer at the remembered centre line '
                                      'this far ahead', 'lane widths', positive)
    memory_window: float = setting(0.714, 'with memory: fit the points this far either side of '
                                   'the look-ahead', 'lane widths', positive)
    search_angle: float = setting(45.0, 'lane lost and nothing remembered ahead: turn in place '
                                  'towards where it was last seen going, up to this angle, then '
                                  'stop; 0: no search, stop at once', 'deg', between(0, 360))
    search_rate: float = setting(0.5, 'turn rate while searching', 'rad/s', positive)
    search_time: float = setting(6.0, 'the search gives up after this long whatever the angle',
                                 's', positive)
    turn_offset: float = setting(0.5, "the decision recorded: 'left' or 'right' when the lane's "
                                 'centre lies more than this many lane widths to that side at '
                                 'the look-ahead distance (going straight, the robot would be '
                                 'out of its lane there), or the lane seen beyond it bends that '
                                 "far away from the line it starts along; 'straight' otherwise",
                                 'lane widths',
                                 positive)

    # the settings given in lane widths (and lane widths per second): the Kobuki's numbers
    # divided by the lecture's 0.35 m lane, so that a narrower lane scales them all
    LANE_WIDTHS = ('roi_near', 'roi_far', 'v_max', 'v_min', 'curve_slowdown', 'lookahead',
                   'lookahead_min', 'memory_lookahead', 'memory_window', 'shift_gate',
                   'seen_within', 'slow_ahead')

    def in_metres(self, lane_width):
        """The same settings with those in lane widths in metres and m/s, for a lane
        `lane_width` [m] wide; lane_width itself set to it."""
        return replace(self, lane_width=lane_width,
                       **{name: getattr(self, name) * lane_width for name in self.LANE_WIDTHS})

    @property
    def mounting(self):
        return Mounting(self.camera_height, self.camera_pitch, self.camera_forward,
                        self.camera_roll)

    def clipped(self, lane_width):
        """Warnings for settings the Kobuki's limits will cut down (every command is clipped
        to them, and recorded as sent), on a lane `lane_width` [m] wide."""
        said = []
        m = self.in_metres(lane_width)
        for name, value, limit, unit in (('v_max', m.v_max, MAX_LINEAR, 'm/s'),
                                         ('v_min', m.v_min, MAX_LINEAR, 'm/s'),
                                         ('omega_max', m.omega_max, MAX_ANGULAR, 'rad/s')):
            if value > limit:
                given = '' if unit == 'rad/s' else f' ({getattr(self, name):g} lane widths/s)'
                said.append(f'{name} = {value:g} {unit}{given} is above the Kobuki\'s '
                            f'{limit:.2f} {unit}: commands are clipped to it')
        return said


class ImprovedController:
    """Perceive -> estimate -> steer, one frame at a time; drop-in for kobuki_lane.LectureRule.

    lane_params: the lecture's settings (its rate); p: ImprovedParams (lane widths); camera:
    the calibration (None: frames as they come, with the lecture camera's geometry scaled to
    them); profile: a lanes.LaneProfile instead of the one p.lane names; mark: called with each
    stage's name as it ends ('start', 'undistort', 'colour', 'pieces', then 'lane' and 'steer'
    in the call), for tools/bench.py; odometry: a topics.Odometry, followed while it comes.
    """

    name = 'improved'

    def __init__(self, lane_params, p=None, camera=LECTURE_CAMERA, profile=None, mark=None,
                 odometry=None):
        p = p or ImprovedParams()
        self.mark = mark or (lambda stage: None)
        self.profile = profile or load_lane(p.lane)
        self.params = p  # as given: distances in lane widths
        self.p = p.in_metres(p.lane_width or self.profile.lane_width)  # what the code uses
        # lines are cut into pieces this long [m]: a quarter lane, and three times as long as
        # the widest tape is wide, so that a piece's direction is along the line
        self.piece_length = max(0.25 * self.p.lane_width,
                                3 * max(self.profile.left.width, self.profile.right.width))
        # the robot drives along the middle of the floor between the tapes, not between their
        # centres: with a wider tape on the right (Duckietown's white, 5 cm, against the yellow's
        # 2.5) that lies this far [m] to the left of the centre line the lines are fitted with,
        # as dt-core's lane filter reads the lane (its offset is to the tapes' inner edges)
        self.shift = (self.profile.right.width - self.profile.left.width) / 4
        self.camera = camera
        self.odometry = odometry
        self.dt = 1.0 / lane_params.rate
        self.view = None  # the FloorView of the frames' size
        self.cluttered = False  # the last frame had more than max_pieces pieces of line
        self.ever_seen = False  # a lane has been seen since the start (reset() keeps it)
        self.placed = False  # a lane has been confirmed since the start (reset() keeps it)
        self.width = None  # [m] between the lines, last measured with both in view
        # [deg] the camera looks this much further down than the mounting says, as the lane's
        # lines say (pitch_tolerance); a property of the camera, so kept when the lane is lost
        self.pitch_error = 0.0
        # pitch_from 'motion', with odometry: the correction from the floor's motion
        self.floor_pitch = (PitchFromMotion(self.p.mounting, self.p.pitch_tolerance, FLOOR_LAG)
                            if (self.p.pitch_tolerance and self.p.pitch_from == 'motion' and
                                odometry is not None) else None)
        self.at_limit = 0.0  # [s] the correction has been at its limit, on end
        self.pitch_notice = None  # what notice() said about it, once said
        # turn_gain 'measured', with odometry: how much of a turn asked for the base turns (a
        # property of the base, so kept when the lane is lost)
        self.turning = (TurnResponse() if self.p.turn_gain == 'measured' and odometry is not None
                        else None)
        self.asked = 0.0  # [rad/s] the turn rate last sent to the wheels
        self.reset()

    def tuned_settings(self):
        """The settings live tuning may change (lanelib/tuning.py): as given, in lane widths."""
        return self.params

    def retune(self, p):
        """Gains and speeds changed while the node runs (the lane and the camera's view stay):
        from the next frame on."""
        self.params = p
        self.p = p.in_metres(self.p.lane_width)

    def warnings(self):
        """What to say at start about these settings (speeds above the Kobuki's)."""
        return self.params.clipped(self.p.lane_width)

    def notice(self):
        """What to tell the user now, once, or None: that the pitch correction has been at its
        limit for PITCH_NOTICE seconds (the camera is pitched further off its mounting than
        pitch_tolerance lets the controller correct: the lane it finds is drawn wrongly)."""
        if self.pitch_notice is not None or self.at_limit < PITCH_NOTICE:
            return None
        p, e = self.p, self.pitch_error
        self.pitch_notice = (
            f"the camera's pitch correction has been at its limit ({e:+g} deg, "
            f"pitch_tolerance) for {self.at_limit:.0f} s: the camera looks {abs(e):g} degrees or "
            f"more {'further down' if e > 0 else 'less far down'} than the mounting's "
            f"{p.mounting.pitch_deg:g} degrees, and the lane is drawn on the floor wrongly; "
            'measure the mounting (python calibration.py --ground) and give it with '
            '--mounting, or allow more with --pitch-tolerance')
        return self.pitch_notice

    def reset(self):
        """Forget the lane: the next frame is read as if it were the first."""
        self.estimate, self.lost_for, self.last = None, math.inf, (0.0, 0.0)
        self.t = None  # when the last frame was read
        self.odom_pose = None  # the odometry's pose at the last frame, while it comes
        self.search = None  # while searching: [direction, angle turned [rad], time [s]]
        self.sides = None  # each piece's side in the last frame's lane (pictures)
        self.held = False  # the last frame's lane was the one predicted (find_lane's prior)
        self.confirmed = 0  # frames since the estimate (re)started whose lane followed it
        self.memory = (LaneMemory(self.p.memory, self.p.memory_points) if self.p.memory > 0
                       else None)

    @property
    def matrix(self):
        """The undistorted frame's camera matrix."""
        return None if self.view is None else self.view.matrix

    @property
    def mounting(self):
        """The camera's mounting as the controller now takes it (the lane is drawn on the
        frame with it): the pitch corrected by what the lane's lines say (pitch_tolerance)."""
        return self.p.mounting.looking_down(self.pitch_error)

    def perceive(self, frame, keep_stages=False):
        w, h, source = FloorView.size_for(frame, self.p)
        if self.view is None or self.view.key != (id(self.camera), w, h, source):
            self.view = FloorView(self.camera, w, h, self.p, source)
        self.mark('start')  # the shrinking is the frame's work, timed with the undistortion
        return perceive(self.view.read(frame), self.view, self.profile, self.p,
                        self.piece_length, keep_stages, self.mark, self.pitch_error)

    def elapsed(self, t):
        """Seconds since the last frame: from the frames' times `t` when the loop gives them
        (on a loaded robot frames come later than the rate says, and the memory must move as
        far as the robot did), else one loop period."""
        last, self.t = self.t, t
        if t is None or last is None:
            return self.dt
        dt = max(0.0, t - last)
        return self.dt if abs(dt - self.dt) < 1e-6 else dt  # a clock's rounding is no motion

    def moved(self, t, dt):
        """How odometry says the robot moved since the last frame, `dt` seconds ago, in the
        robot's frame then: (ahead [m], left [m], turned [rad]); None while it does not come,
        or when it moved further than the robot can (then the controller dead-reckons on the
        command sent)."""
        pose = self.odometry.pose(t) if (self.odometry is not None and t is not None) else None
        last, self.odom_pose = self.odom_pose, pose
        if pose is None or last is None:
            return None
        ahead, left, turned = seen_from(last, pose)
        turned = math.atan2(math.sin(turned), math.cos(turned))
        if not could_move(math.hypot(ahead, left), turned, dt):
            return None  # odometry took a new origin since the last frame: not a motion
        return ahead, left, turned

    def __call__(self, detection, t=None):
        """The command for one frame's detection; t: when the frame was read [s] (ROS time)."""
        p, w = self.p, self.p.lane_width
        dt = self.elapsed(t)
        self.cluttered = detection.cluttered
        moved = self.moved(t, dt)  # by odometry: (ahead, left, turned); else dead reckoning
        if self.turning is not None and moved is not None:
            self.turning.update(moved[2], self.asked * dt, dt)
        if moved is None:
            ds, dtheta = self.last[0] * dt, self.last[1] * dt
        else:
            ds, dtheta = math.copysign(math.hypot(moved[0], moved[1]), moved[0]), moved[2]
        prior = predict(self.estimate, ds, dtheta) if self.estimate else None
        # the arc the pieces are sorted to left and right against, and where the lane is at
        # the robot: the prior's, or the memory's
        guide, anchor = (prior.arc if prior else None), None
        if self.memory is not None:
            if moved is None:
                self.memory.move(*self.last, dt)
            else:
                self.memory.move_by(*moved, dt)
            remembered = self.memory.centre_line(*(v * w for v in GUIDE))
            if remembered is not None and prior is not None:
                guide = replace(prior, a=remembered[0], b=remembered[1], c=remembered[2]).arc
            anchor = self.anchored()
            if prior is not None and self.lost_for > p.lost_timeout:
                found = self.memory.arc(prior.arc, FOLLOW * w, ARC_OUTLIER * w)  # even a U-turn
                if found is not None:
                    # lines are sorted against the remembered arc, but the lane at the robot
                    # is the estimate's, moved with the robot: an arc fitted to the memory of
                    # a bend's entry (straight, then bending) is turned the wrong way there
                    guide, anchor = found[0], prior.arc[:2]
        # one_line_width 'measured': with one line in view, the lane lies half the width last
        # measured with both beside it (the profile's half, with the camera's pitch a little
        # off and the lines looking further apart, moved the lane sideways as a line left view)
        # perceive() puts the pieces on the floor with the pitch corrected as it then was; a
        # detection made otherwise (or before a change) is moved by what it lacks (moving
        # every point of every piece took as long as the colour stage)
        made = getattr(detection, 'pitch', 0.0)  # (pieces made by hand: on the mounting's)
        pieces = detection.pieces
        if self.pitch_error != made:
            pieces = repitched_pieces(pieces, p.mounting.looking_down(made),
                                      self.pitch_error - made)
        if p.start_belief == 'centred' and not self.placed:
            # before its first lane, the robot stands where it was set down: in its lane and
            # along it, as dt-core's lane filter starts its belief (offset 0, heading 0)
            anchor = (0.0, 0.0)
        blind = self.lost_for > p.lost_timeout  # the estimate from before is stale
        current = prior is not None and not blind  # the prediction stands for this frame
        expected = (prior.curvature, p.bend_belief / w) if p.bend_belief and current else None
        # with the pitch read from the floor's motion the lines are fitted parallel, as they lie
        # on the floor: a splay allowed too took part of a corner ahead for one (the project's
        # simulator, inner loop: docs/benchmarks.md, forty-third session)
        from_motion = self.floor_pitch is not None and moved is not None
        # a confirmed lane followed: the gates defend it, and all its lines see it; a lane
        # started needs its lines near (far up the view a glint or a wall's foot passes for one)
        defended = current and self.confirmed >= CONFIRMED
        meas, fit = measure(pieces, self.profile, p, guide, anchor, self.held,
                            self.width if p.one_line_width == 'measured' else None, expected,
                            splay=not from_motion, within=0.0 if defended else p.seen_within)
        self.mark('lane')
        if meas is not None and current and not follows(prior, meas, p.turn_gate, p.shift_gate):
            if defended:
                meas, fit = None, None  # turned or moved further than it can have since
            else:
                current = False  # a lane not yet confirmed gives way to the one found now
        self.sides = None if fit is None else fit.sides
        self.held = fit is not None and fit.predicted
        # a lane found after one was lost must be the one lost (the robot cannot have left it
        # without a departure); before any lane was seen there is none to lose
        if blind and self.ever_seen and meas is not None and abs(meas.across) > REGAINED * w:
            meas = None  # another lane (the far leg of a U-turn): keep searching
        if meas is not None:
            self.ever_seen = True
            if meas.left and meas.right:  # one line's fit gives no width, only the one given
                self.width = meas.width
                if p.pitch_tolerance and not from_motion:
                    self.learn_pitch(meas)
            self.lost_for, self.search = 0.0, None
            self.confirmed = self.confirmed + 1 if current else 0
            self.placed = self.placed or self.confirmed >= CONFIRMED
            self.estimate = (blend(prior, meas, p.smoothing * meas.confidence) if current
                             else meas)
        else:
            self.lost_for += dt
            self.estimate = prior
            if self.search is not None:
                self.search[1] += abs(self.last[1]) * dt
                self.search[2] += dt
        if self.memory is not None and meas is not None:
            self.memory.add(*meas.points)
        if self.floor_pitch is not None:
            self.pitch_error = self.floor_pitch.read(detection.pieces, made, moved, dt,
                                                     self.pitch_error)
        limited = p.pitch_tolerance and abs(self.pitch_error) >= p.pitch_tolerance - 1e-9
        self.at_limit = self.at_limit + dt if limited else 0.0
        command = self.command()
        if self.turning is not None:  # a base that turns less than asked is asked for more
            command = replace(command, angular_z=float(np.clip(
                command.angular_z / self.turning.gain, -p.omega_max, p.omega_max)))
        self.sent(command)
        self.mark('steer')
        return command

    def anchored(self):
        """(offset [m], heading [rad]) of the lane at the robot as the memory has it, from the
        points about the robot (no lever), or None where too little is remembered there
        (memory_anchor)."""
        w = self.p.lane_width
        if self.p.memory_anchor == 'line':
            return self.memory.line_about(ANCHOR[1] * w, ANCHOR[2] * w)
        under = self.memory.centre_line(*(v * w for v in ANCHOR))
        return None if under is None else (under[0], math.atan(under[1]))

    def learn_pitch(self, meas):
        """The pitch correction from a frame with both lines in view: lines parallel on the
        floor drawn splayed say the pitch is still off (geometry.repitched), by
        atan(height x spread / width); the correction moves REPITCH of the way there."""
        p = self.p
        off = math.degrees(math.atan(p.camera_height * meas.spread / meas.width))
        self.pitch_error = float(np.clip(self.pitch_error + REPITCH * off, -p.pitch_tolerance,
                                         p.pitch_tolerance))

    def followed(self):
        """(linear.x, angular.z) along the lane remembered while it is out of view: pure
        pursuit of the point memory_lookahead away on the arc fitted to the memory (exact on
        an arc), or None when the memory does not reach that point, or the robot is not where
        the memory has the lane."""
        p, w = self.p, self.p.lane_width
        found = (self.memory.arc(self.estimate.arc, FOLLOW * w, ARC_OUTLIER * w)
                 if self.memory else None)
        if found is None:
            return None
        arc, (x, y) = found
        if abs(arc[0]) > TRUSTED * w:
            return None
        ax, ay, heading = LaneFit(arc, None, 0, 0, None).point_at(p.memory_lookahead)
        if ax <= 0 or np.min(np.hypot(x - ax, y - ay)) > NEAR_TARGET * w:
            return None
        if self.shift:  # the point `shift` to the left of the centre line (__init__)
            ax, ay = ax - self.shift * math.sin(heading), ay + self.shift * math.cos(heading)
        return steer(ax, ay, 0.0, self.estimate.confidence, p, alpha=1.0,
                     bend=self.bend_ahead())

    def remembered(self):
        """(linear.x, angular.z) at the remembered centre line memory_lookahead ahead, or None
        when too little is remembered there."""
        p, w = self.p, self.p.lane_width
        L, half = p.memory_lookahead, p.memory_window
        coef = self.memory.centre_line(L - half, L + half, half,
                                       outlier=MEMORY_OUTLIER * w) if self.memory else None
        if coef is None:
            return None
        a, b, c = coef
        return self.steer(L, a + b * L + c * L ** 2, b + 2 * c * L, self.estimate.confidence)

    def seen(self):
        """(linear.x, angular.z) at the estimate's centre line, as near as it is seen, between
        lookahead_min and lookahead."""
        e, p = self.estimate, self.p
        x = float(np.clip(e.reach, p.lookahead_min, p.lookahead))
        return self.steer(x, e.a + e.b * x + e.c * x ** 2, e.b + 2 * e.c * x, e.confidence)

    def steer(self, x, y, slope, confidence):
        """steering.steer at the point of the centre line (x, y) with `slope` there, moved
        `shift` to its left (the middle of the floor between the tapes)."""
        if self.shift:
            y += self.shift * math.hypot(1.0, slope)  # the parallel line, at the same x
        return steer(x, y, slope, confidence, self.p, bend=self.bend_ahead())

    def bend_ahead(self):
        """[1/m] the largest |curvature| of the lane found within slow_ahead (0: off)."""
        return self.estimate.bent_within(self.p.slow_ahead) if self.p.slow_ahead else 0.0

    def command(self):
        """What to do with the estimate (module doc)."""
        p = self.p
        if self.estimate is None:
            return self.give_up()
        if self.lost_for <= p.lost_timeout:
            with self.ahead(p.latency):
                steered = self.followed() if self.lost_for > 0 else None
                return Command(self.decision(), *(steered or self.remembered() or self.seen()))
        if not p.search_angle:
            return self.give_up()  # the plain stop
        if self.search is None:
            steered = self.followed()
            if steered is not None:
                return Command(self.decision(), *steered)
            self.search = [self.search_direction(), 0.0, 0.0]
        direction, turned, spent = self.search
        if turned >= math.radians(p.search_angle) or spent >= p.search_time:
            return self.give_up()
        return Command('search', 0.0, direction * p.search_rate)

    @contextlib.contextmanager
    def ahead(self, seconds):
        """Within it, the estimate and the memory are where they will be `seconds` on, the
        robot driving as last commanded: a command acts only after the frame's trip from the
        camera to the wheels, and by then the robot has moved on (0.13 s at 0.2 m/s: 2.6 cm)."""
        if not seconds:
            yield
            return
        estimate, memory = self.estimate, self.memory
        v, omega = self.last
        self.estimate = predict(estimate, v * seconds, omega * seconds) or estimate
        if memory is not None:
            self.memory = copy.copy(memory)  # moving it rebinds its own fields: the kept
            # one stays (their buffer is shared, and only the kept one adds to it)
            self.memory.move(v, omega, seconds)
        try:
            yield
        finally:
            self.estimate, self.memory = estimate, memory

    def search_direction(self):
        """+1 (left) or -1: where the lane was last seen going, the way the estimate's centre
        line lies at the look-ahead (on a bend too tight to reach it, the point half way round:
        LaneFit.point_at)."""
        return 1.0 if self.estimate.lateral_at(self.p.lookahead) >= 0 else -1.0

    def sent(self, command):
        """The command that went to the wheels: a stop when the loop held the robot (the ROS
        master lost, a late frame, a lost camera) or a frame failed. The lane memory and the
        prediction move with it, not with what this controller asked for (with turn_gain
        'measured', with as much of its turn as the base turns)."""
        self.asked = command.angular_z
        gain = 1.0 if self.turning is None else self.turning.gain
        self.last = (command.linear_x, command.angular_z * gain)  # as the base will move

    def give_up(self):
        """No lane, nothing remembered ahead, the search done (or off): stop and forget."""
        self.estimate, self.search = None, None
        if self.memory is not None:
            self.memory.clear()
        return STOP

    def decision(self):
        """'left' or 'right' when, going straight, the robot would leave its lane to that side:
        the lane's centre lies more than turn_offset lane widths that side at the look-ahead
        distance, or, seen beyond it (up to the floor band's far end), the lane bends that far
        away from the line it starts along at the robot (a bend ahead: estimate.bent_away);
        else 'straight'."""
        e, p = self.estimate, self.p
        y, turn = e.lateral_at(p.lookahead), p.turn_offset * p.lane_width
        if abs(y) <= turn and e.seen > p.lookahead:
            y = e.bent_away(min(e.seen, p.roi_far))
        return 'left' if y > turn else 'right' if y < -turn else 'straight'

    def draw(self, detection, command, lane_params=None):
        """The undistorted frame, the colour masks tinted, the lane and what was decided."""
        return draw_lane(self, detection, command)

    def pictures(self, detection, command, lane_params=None):
        """(key, title, BGR image) of every stage (lanelib/lanedraw.py)."""
        return stage_pictures(self, detection, command)

    def extra(self):
        """The estimate, for the decision records."""
        e = self.estimate
        # with or without a lane: turn_gain 'measured''s share of the turn asked that the base
        # turns (1 until odometry has shown enough turning), else None
        always = dict(cluttered=self.cluttered, pitch_error_deg=round(self.pitch_error, 2),
                      turn_gain=None if self.turning is None else round(self.turning.gain, 3))
        if e is None:
            return dict(offset_m=None, heading_rad=None, curvature=None, confidence=0.0,
                        bend_m=None, bend_curvature=None, seen_m=None, lane_width_m=None,
                        lane_lost_s=None, **always)
        width = None if e.width is None or self.lost_for > 0 else round(e.width, 4)
        bend = (None, None) if e.bend is None else (round(e.bend[0], 4), round(e.bend[1], 4))
        return dict(offset_m=round(e.offset, 4), heading_rad=round(e.heading, 4),
                    curvature=round(e.curvature, 4), confidence=round(e.confidence, 3),
                    bend_m=bend[0], bend_curvature=bend[1], seen_m=round(e.seen, 4),
                    lane_width_m=width, lane_lost_s=round(min(self.lost_for, 1e6), 3), **always)
