#!/usr/bin/env python3
"""Lane following for a Kobuki, as in IISc "Advanced IoT Applications", Lecture 14.

Each frame: undistort with the lecture's camera (calibration_camera), gray, GaussianBlur 5x5,
Canny 85/85, mask to the region_of_interest triangle (0,h) (w/2,h/2) (w,h) (algorithm 1.1),
HoughLinesP, then theta = sum of atan2 over every segment. theta > 6: turn left,
theta < -6: turn right, else straight; a geometry_msgs/Twist ("thrust") goes to
/mobile_base/commands/velocity at 4 Hz. Where the lecture's code had defects this node fixes
them (see README): no segments, or |theta| == 6 exactly, stops the robot (decision "none"),
and every way of ending the run publishes a zero Twist first.

usage:
    python kobuki_lane.py                              the robot: camera 0, beside
                                                       roslaunch kobuki_node minimal.launch
    python kobuki_lane.py --source samples/track --dry-run --decisions d.jsonl --video d.avi
    python kobuki_lane.py --source run.bag --image-topic /camera/rgb/image_raw --dry-run \\
        --bag commands.bag --stages stages/
    roslaunch kobuki_lane kobuki_lane.launch           the same node with launch parameters

default values: the lecture's numbers (--help lists each with its unit). Each setting can come
from a flag, a private ROS parameter (_threshold:=8 or <param> in a launch file), or the
default, in that order of precedence.

safety: a watchdog publishes a stop whenever --watchdog seconds pass without a command; a lost
camera is stopped for at once and reopened for --camera-retry seconds; a frame the pipeline
fails on is answered with a stop; while the ROS master is gone the robot is held stopped.

exit status: 0 input ended or the node was shut down, 1 camera lost, repeated pipeline
errors or an input file cut short, 2 bad arguments, an unopenable source, no frame at all, or
no ROS master, 130 Ctrl-C, 143 SIGTERM, 129 SIGHUP (the terminal or ssh session gone).

This file is the lecture: its settings, its pipeline (detect), its rule, its loop. The rest
lives in lanelib/ (the speed-up, the improved controller, safety, outputs, ROS plumbing).
"""

import os

# numpy's BLAS one thread, set before numpy loads it. The lane memory's sums run through
# OpenBLAS, which splits a long one across the cores and waits for them spinning: with one
# other busy process on two cores (a camera driver, a simulator) a frame's 95th percentile went
# from 13 to 100 ms. One thread also makes the sums, so the commands, the same on every machine.
# A value the user has set stands.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import argparse
import math
import sys
from dataclasses import dataclass

import cv2
import numpy as np

from lanelib import node
from lanelib.camera import LECTURE_CAMERA
from lanelib.cli import check_arguments, fail
from lanelib.fast import FastPipeline
from lanelib.improved import ImprovedController, ImprovedParams
from lanelib.outputs import Outputs, decision_record
from lanelib.robot import MAX_ANGULAR, MAX_LINEAR, STOP, VELOCITY_TOPIC, Command, within_limits
from lanelib.ros import split_ros_args
from lanelib.safety import (
    SafeBase,
    Safety,
    camera_back,
    install_signal_handlers,
    signals_held,
)
from lanelib.settings import above, add_arguments, between, setting
from lanelib.sources import Prefetch
from lanelib.stages import (
    Detection,
    as_bgr,
    hough_lines,
    region_of_interest,
    region_of_interest_vertices,
    slope_sum,
)

PROG = 'kobuki_lane.py'


@dataclass
class LaneParams:
    """Every number the node uses, with its unit and its place in the lecture."""

    algorithm: str = setting('1.1', "'1.1' masks the Canny edges with the ROI triangle "
                             "before Hough; '1.0' does not (the lecture's first demo)",
                             choices=('1.0', '1.1'))
    blur_kernel: int = setting(5, 'GaussianBlur kernel size, odd (lecture: (5, 5), sigma 0)',
                               'px', between(1, 31, odd=True))
    canny_low: float = setting(85.0, 'Canny lower hysteresis threshold (lecture: 85)', '',
                               between(0, 2040))
    canny_high: float = setting(85.0, 'Canny upper hysteresis threshold (lecture: 85)', '',
                                between(0, 2040))
    hough_rho: float = setting(6.0, 'HoughLinesP distance resolution (lecture: rho=6)', 'px',
                               above(0, 100))
    hough_theta: float = setting(math.pi / 60, 'HoughLinesP angle resolution '
                                 '(lecture: theta=pi/60)', 'rad', above(0, math.pi))
    hough_threshold: int = setting(160, 'HoughLinesP accumulator votes (lecture: 160)', 'votes',
                                   between(1, 100000))
    min_line_length: float = setting(40.0, 'HoughLinesP minLineLength (lecture: 40)', 'px',
                                     between(0, 10000))
    max_line_gap: float = setting(25.0, 'HoughLinesP maxLineGap (lecture: 25)', 'px',
                                  between(0, 10000))
    slope_min: float = setting(0.5, 'segments with |slope| below this join neither slope group '
                               '(lecture: 0.5)', '', between(0, 1000))
    threshold: float = setting(6.0, 'theta above +threshold turns left, below -threshold right '
                               '(lecture: threshold = 6)', 'rad, summed', between(0, 10000))
    # speeds: forward only, and no faster than the Kobuki goes (lanelib/robot.py)
    turn_linear: float = setting(0.01, 'forward speed while turning (lecture: 0.01)', 'm/s',
                                 between(0, MAX_LINEAR))
    turn_angular: float = setting(0.06, 'turn rate; left +, right - (lecture: 0.06)', 'rad/s',
                                  between(0, MAX_ANGULAR))
    straight_linear: float = setting(0.05, 'forward speed going straight (lecture: 0.05)', 'm/s',
                                     between(0, MAX_LINEAR))
    # at 2.5 Hz and below the commands come as far apart as the watchdog's 0.4 s or further,
    # and it would stop the robot between every two of them
    rate: float = setting(4.0, 'loop and publish rate (lecture: rospy.Rate(4)); not below 3, '
                          "where the watchdog's stops would come between the commands", 'Hz',
                          between(3, 100))


# ---------------------------------------------------------------- the lecture's pipeline

def calibration_camera(seeimg, camera=LECTURE_CAMERA):
    """Undistort one frame (slide 18:57; the slide's mtx and dist are LECTURE_CAMERA, digit for
    digit). camera None: no calibration, the frame as it is."""
    if camera is None:
        return seeimg
    h, w = seeimg.shape[:2]
    cam = camera.scaled_to(w, h)
    # same call as the slide: the new camera matrix is the old one
    return cv2.undistort(seeimg, cam.matrix, cam.distortion, None, cam.matrix)


def detect(frame, camera, p, keep_stages=False):
    """One frame through the slides' calls, in the slides' order; a Detection.

    keep_stages: keep every intermediate image, for pictures. On a live camera the node runs
    this on every frame; over files it runs the same stages faster (lanelib/fast.py), with
    identical segments (--pipeline).
    """
    raw = as_bgr(frame)
    image = calibration_camera(raw, camera)  # 21:15
    # fixed: the slide takes gray from the raw frame, so undistortion had no effect
    gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)  # 21:40
    blurred = cv2.GaussianBlur(gray, (p.blur_kernel, p.blur_kernel), 0)  # 21:44
    edged = cv2.Canny(blurred, p.canny_low, p.canny_high)  # 21:44
    height, width = edged.shape
    if p.algorithm == '1.1':  # the triangle (21:44), with the lecture's function (20:44)
        masked = region_of_interest(edged, region_of_interest_vertices(width, height))
    else:  # algorithm 1.0: the whole frame
        masked = edged
    lines = hough_lines(masked, p)  # 21:44 to 22:22
    slopes = slope_sum(lines, p.slope_min)  # 22:22 to 23:14
    stages = None
    if keep_stages:
        stages = dict(raw=raw, undistorted=image, gray=gray, blurred=blurred, edges=edged,
                      roi=roi_picture(edged, p), masked=masked)
    return Detection(lines, slopes, image, stages)


def roi_picture(edged, p):
    """The mask detect() applied, as a picture: 255 where edges are kept."""
    everything = np.full_like(edged, 255)
    if p.algorithm == '1.0':
        return everything
    return region_of_interest(everything, region_of_interest_vertices(*edged.shape[::-1]))


def slides_pipeline(p):
    """detect() itself on every frame (--pipeline slides), in the fast pipeline's shape."""
    return lambda frame, camera, keep_stages=False: detect(frame, camera, p, keep_stages)


class LectureRule:
    """The lecture's bang-bang rule on theta (23:04 to 23:26), its silent cases made explicit.

    pipeline: how frames become Detections; by default the speed-up proven identical to
    detect() (lanelib/fast.py, tests/test_pipeline.py)."""

    name = 'lecture'
    runs = 'the speed-up of detect(), the same segments'  # for the log line at start

    def __init__(self, p, camera=LECTURE_CAMERA, pipeline=None):
        self.p, self.camera = p, camera
        self.pipeline = pipeline or FastPipeline(p, detect)

    def perceive(self, frame, keep_stages=False):
        return self.pipeline(frame, self.camera, keep_stages)

    def extra(self):
        return {}

    def notice(self):
        """Something to tell the user while it runs (the rule has nothing to say)."""
        return None

    def tuned_settings(self):
        """The settings live tuning may change (lanelib/tuning.py)."""
        return self.p

    def retune(self, p):
        """Settings changed while the node runs: from the next frame on."""
        self.p = p
        if isinstance(self.pipeline, FastPipeline):
            self.pipeline.p = p
        else:
            self.pipeline = slides_pipeline(p)

    def sent(self, command):
        """What went to the wheels (the rule keeps no state)."""

    def __call__(self, detection, t=None):  # (t: the frame's time; the rule needs none)
        p, theta = self.p, detection.slopes.theta
        # fixed: with no segments the lecture published nothing; stop instead
        if len(detection.lines) == 0:
            return STOP
        if theta > p.threshold:
            return Command('left', p.turn_linear, p.turn_angular)
        if theta < -p.threshold:
            return Command('right', p.turn_linear, -p.turn_angular)
        if abs(theta) < p.threshold:
            return Command('straight', p.straight_linear, 0.0)
        # fixed: |theta| == threshold matched no branch in the lecture; stop instead
        return STOP


def make_controller(name, params, camera=LECTURE_CAMERA, improved=None, pipeline='fast',
                    odometry=None):
    """The lecture's rule (default) or the improved controller (lanelib/improved.py), whose
    lane memory follows `odometry` (lanelib/topics.py) while it comes."""
    if name == 'lecture':
        rule = LectureRule(params, camera, slides_pipeline(params) if pipeline == 'slides'
                           else None)
        rule.runs = ("detect(), the slides' calls" if pipeline == 'slides' else
                     'the speed-up of detect(), the same segments')
        return rule
    if name == 'improved':
        return ImprovedController(params, improved, camera, odometry=odometry)
    raise ValueError(f"controller must be lecture or improved, not '{name}'")


# ---------------------------------------------------------------- the loop

class LaneFollower:
    """The lecture's main loop (20:44 to 23:26): read a frame, detect, decide, publish the
    thrust, keep the rate; every way out stops the robot.

    ros: the rospy module or a rospy_standin.StandInRospy; source: a frame source
    (lanelib/sources.py); controller: LectureRule or ImprovedController, called with each
    Detection and its frame's time, and told (sent) the command that went out; base: the
    safety.SafeBase every command goes through; outputs: outputs.Outputs; rate [Hz]."""

    def __init__(self, ros, source, controller, base, outputs=None, rate=4.0, log_frames=True,
                 check=None):
        self.ros, self.source, self.controller, self.base = ros, source, controller, base
        self.check = check  # called with each frame: sources.FrameCheck, raises FrameError
        self.log_frames = log_frames  # a log line per frame (--quiet: at debug level only)
        self.outputs = outputs or Outputs(LaneParams())
        self.rate = rate
        self.counts = dict(left=0, right=0, straight=0, none=0, search=0)
        self.frames = 0
        self.errors = 0  # pipeline failures in a row
        self.failed = 0  # frames the pipeline failed on, in all
        self.last_error = None  # what the last of them failed with
        self.ended = None  # why the loop ended
        self.stop_requested = None
        self.tuning = None  # live tuning on ROS (lanelib/tuning.py), applied before each frame

    def request_stop(self, reason):
        """Ask the loop to end after this iteration (signal handlers call this)."""
        if self.stop_requested is None:
            self.stop_requested = reason

    def frame_time(self, label, read_at):
        """When the controller takes the frame to have been seen: when it was recorded, for a
        bag's frame (its label; the lane memory then moves as far as the robot could in the
        time between two recorded frames, not in one loop period), unless odometry comes on
        the loop's clock (live; the bag's own is on the bag's); else when it was read."""
        timed = getattr(self.source, 'timed', False) and isinstance(label, float)
        odometry = getattr(self.controller, 'odometry', None)
        return label if timed and getattr(odometry, 'timed', True) else read_at

    def step(self, frame, label, read_at=None):
        """Process one frame and publish its command; returns the decision record.

        read_at: ros time the frame arrived; a result ready more than watchdog seconds later
        is stale, and the robot is stopped instead."""
        ros = self.ros
        read_at = ros.get_time() if read_at is None else read_at
        if self.check is not None:
            self.check(frame)
        if self.tuning is not None:
            self.tuning.apply()  # a setting changed live (lanelib/tuning.py): from this frame
        detection = self.controller.perceive(frame, keep_stages=self.outputs.wants_stages())
        command = self.controller(detection, self.frame_time(label, read_at))
        notice = self.controller.notice()  # once, when there is something to tell the user
        if notice:
            ros.logwarn('%s', notice)
        late = ros.get_time() - read_at > self.base.safety.watchdog
        held = self.base.held
        if late or held:
            command = STOP
        command = within_limits(command)  # what goes to the wheels, and so what is recorded
        self.base.publish(command)  # the slides' pub.publish(thrust), through the safety layer
        self.controller.sent(command)  # what it steers on, not what it asked for
        record = decision_record(self.frames, label, detection, command, ros.get_time(),
                                 self.controller.extra())
        if late:
            record['late'] = True
        if held:
            record['held'] = held
        self.counts[command.decision] += 1
        self.frames += 1
        (ros.loginfo if self.log_frames else ros.logdebug)(
            'frame %d (%s): %d lines, theta %+.3f, value %+.3f -> %s (linear.x %.2f, '
            'angular.z %+.2f)%s', record['frame'], label, record['lines'],
            detection.slopes.theta, detection.slopes.value, command.decision, command.linear_x,
            command.angular_z, ' [late: stopped]' if late else f' [{held}: stopped]' if held
            else '')
        # a topic's frame carries its header stamp as its label (sources.TopicSource)
        header = ((label, getattr(self.source, 'frame_id', '') or 'camera')
                  if isinstance(label, float) else (read_at, 'camera'))
        if self.outputs.frame(record, detection, command, ros.get_time(), header):
            self.request_stop('q pressed')
        return record

    def _failed(self, label, error):
        """A frame the pipeline could not process: log it, stop the robot, go on."""
        self.errors += 1
        self.failed += 1
        self.last_error = f'{type(error).__name__}: {error}'
        self.base.publish(STOP)
        self.controller.sent(STOP)
        self.ros.logerr('frame %d (%s): %s: %s; robot stopped (%d in a row)', self.frames, label,
                        type(error).__name__, error, self.errors)
        self.outputs.write(dict(frame=self.frames, source=label, decision='none',
                                error=f'{type(error).__name__}: {error}',
                                t=round(self.ros.get_time(), 6)))
        self.counts['none'] += 1
        self.frames += 1

    def _stopping(self):
        return bool(self.stop_requested) or self.ros.is_shutdown()

    def run(self, wait_for_base=0.0):
        """The loop at a steady rate, ending with the robot stopped; returns why it ended."""
        ros, safety = self.ros, self.base.safety
        lost_since = None
        try:
            # the slides' wait (while VARIABLE is None ...: rospy.sleep(1)), here for the base
            self.base.wait_for_subscriber(wait_for_base, self._stopping)
            rate = ros.Rate(self.rate)  # the slides' rate = rospy.Rate(4)
            self.base.start_watchdog()
            while self.ended is None:
                if ros.is_shutdown():  # the slides' rospy.is_shutdown() check
                    self.ended = 'ROS shutdown'
                    break
                if self.stop_requested:
                    self.ended = self.stop_requested
                    break
                ok, frame, label = self.source.read()
                if not ok:
                    if not self.source.live:
                        self.ended = 'end of input'
                        break
                    lost_since = ros.get_time() if lost_since is None else lost_since
                    self.controller.sent(STOP)
                    if not camera_back(ros, self.source, self.base, lost_since,
                                       safety.camera_retry, self._stopping):
                        self.ended = 'camera lost'
                    continue
                lost_since = None
                try:
                    self.step(frame, label, ros.get_time())
                    self.errors = 0
                except ros.ROSInterruptException:
                    raise
                except Exception as e:  # one bad frame must not leave the robot moving
                    self._failed(label, e)
                    if self.errors >= safety.max_errors:
                        self.ended = 'pipeline errors'
                        break
                # fixed: the lecture sleeps only in its straight branch; every branch keeps 4 Hz
                rate.sleep()
        except ros.ROSInterruptException:
            self.ended = 'ROS shutdown'
        except KeyboardInterrupt:  # a second Ctrl-C while a frame would not end
            self.ended = 'SIGINT'
        finally:
            self.base.stop_watchdog()
            # fixed: nothing stopped the robot when the lecture's loop ended; always stop
            self.base.stop()
            self.outputs.progress.done()
        return self.ended


# ---------------------------------------------------------------- wiring

EXIT_STATUS = {'end of input': 0, 'ROS shutdown': 0, 'q pressed': 0, 'camera lost': 1,
               'pipeline errors': 1, 'SIGINT': 130, 'SIGTERM': 143, 'SIGHUP': 129}


def build_parser():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    io = parser.add_argument_group('input and output')
    io.add_argument('--source', default='0',
                    help='camera index, video file, folder of images (name order), '
                         "image pattern like 'frames/%%04d.png', URL, ROS 1 bag, or a live "
                         "image topic 'ros:/camera/rgb/image_raw' (a topic ending in "
                         '/compressed is CompressedImage) (default: 0)')
    io.add_argument('--robot', metavar='NAME|FILE',
                    help="a robot preset: 'kobuki' (default: the lecture's Kobuki and webcam, "
                         "the tables' defaults), 'duckiebot' (a DB21 on a Duckietown track) or "
                         'a YAML file of settings by their names below; it sets the camera, its '
                         'mounting, the lane, the rate, whatever differs (config/*.yaml); flags '
                         'and private parameters outrank it (lanelib/robots.py)')
    io.add_argument('--calibration',
                    help="'lecture' (the lecture's camera matrix, default), 'duckiebot' "
                         "(Duckietown's default camera; 'duckiebot-rectified' for its frames "
                         "rectified already), 'none', a ROS camera_info YAML path, or 'topic': "
                         "the camera_info beside the --source ros: topic, or the first one "
                         "recorded beside the image topic of a --source bag (default: the robot "
                         "preset's, else lecture)")
    io.add_argument('--mounting', metavar='FILE',
                    help="the improved controller's camera mounting (height, pitch_deg, "
                         'roll_deg, forward), as calibration.py --ground writes it; '
                         '--camera-height and the like, and private parameters, override it')
    io.add_argument('--odom', metavar='TOPIC',
                    help="the improved controller's lane memory follows nav_msgs/Odometry on "
                         "this topic while it comes (default: /odom, kobuki_node's; in a dry "
                         "run over a bag, the bag's, as recorded), else dead-reckons on the "
                         "commands; 'none': always dead reckoning")
    io.add_argument('--dry-run', action='store_true',
                    help='no ROS: record the commands instead of publishing them; over files '
                         'this runs as fast as it can')
    io.add_argument('--realtime', action='store_true',
                    help='in a dry run, keep the real loop rate instead of running flat out')
    io.add_argument('--decisions', metavar='FILE',
                    help='write one JSON object per frame (JSON Lines), flushed per frame')
    io.add_argument('--video', metavar='FILE', help='write annotated frames (.avi or .mp4)')
    io.add_argument('--stages', metavar='DIR',
                    help='write every stage of every frame as pictures (raw, undistorted, gray, '
                         'blurred, Canny edges, ROI mask, masked edges, Hough segments with '
                         'theta and the decision) and one contact sheet per frame')
    io.add_argument('--bag', metavar='FILE',
                    help=f'record every command sent as geometry_msgs/Twist on {VELOCITY_TOPIC} '
                         'in a new ROS 1 bag (complete even after Ctrl-C)')
    io.add_argument('--force', action='store_true',
                    help='replace --decisions, --video and --bag files that exist already '
                         '(without it, an existing file is refused before anything runs)')
    io.add_argument('--bag-images', action='store_true',
                    help='also record the annotated frames in the bag, as '
                         'sensor_msgs/CompressedImage on /kobuki_lane/debug_image/compressed')
    io.add_argument('--image-topic', metavar='TOPIC',
                    help='with --source run.bag: the sensor_msgs/Image or CompressedImage '
                         'topic to play (needed when the bag has more than one)')
    io.add_argument('--show', action='store_true',
                    help='show annotated frames in a window (needs a display and an OpenCV '
                         'build with GUI); q quits')
    io.add_argument('--progress', choices=('auto', 'on', 'off'), default='auto',
                    help='progress line on stderr (auto: when stderr is a terminal)')
    io.add_argument('--quiet', action='store_true',
                    help='no per-frame log lines (on ROS they go to the debug level)')
    io.add_argument('--open-timeout', type=seconds, default=10.0, metavar='SECONDS',
                    help='a URL source that gives no stream within this long is given up (exit '
                         '2), and a read that long is a lost camera; --calibration topic waits '
                         'this long for the camera_info (default: 10)')
    io.add_argument('--wait-for-base', type=seconds, default=2.0, metavar='SECONDS',
                    help='on ROS, wait this long for a subscriber (the Kobuki base) before '
                         'the first command (default: 2)')
    io.add_argument('--controller', choices=('lecture', 'improved'), default=None,
                    help="'lecture': the lecture's rule on theta (default); 'improved': the "
                         "lane's offset, heading and curvature from the tape's colour on the "
                         'floor, and one steering law (lanelib/improved.py)')
    io.add_argument('--pipeline', choices=('auto', 'fast', 'slides'), default='auto',
                    help="how the lecture's controller runs the slides' stages: 'slides' "
                         'detect() in this file on every frame, as on the slides; '
                         "'fast' the speed-up with identical segments (lanelib/fast.py); "
                         "'auto' (default) slides on a live source (a camera, URL or ROS "
                         'topic), fast over files, where frames come as fast as they can')
    add_arguments(parser.add_argument_group("the lecture's settings (defaults are the "
                                            "lecture's)"), LaneParams)
    add_arguments(parser.add_argument_group('the improved controller (--controller improved)'),
                  ImprovedParams)
    add_arguments(parser.add_argument_group('safety'), Safety)
    return parser


def seconds(text):
    """An argparse type: a time from 0 to an hour."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 <= value <= 3600:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number of seconds from 0 to 3600")
    return value


def parse_arguments(argv):
    """(args, private parameters from _name:=value); a mistake is exit status 2."""
    try:
        ours, private = split_ros_args(sys.argv[1:] if argv is None else argv)
    except ValueError as e:
        fail(PROG, str(e))
    args = build_parser().parse_args(ours)
    check_arguments(PROG, args)
    return args, private


def main(argv=None, make_controller=make_controller):
    args, private = parse_arguments(argv)
    # the slides' rospy.init_node("detection"): lanelib/ros.py connect (a stand-in for a dry run)
    ros, twist_type, topic_ros = node.connect_to_ros(PROG, args, private)
    params, safety, controller, source, check = node.set_up(PROG, args, ros, topic_ros,
                                                            LaneParams, make_controller)
    with signals_held():  # a signal now is heard once the loop can end the usual way
        outputs = node.open_outputs(PROG, args, params, ros, source, controller)
        # the slides' rospy.Publisher('/mobile_base/commands/velocity', Twist, queue_size=1)
        # and their Twist "thrust": SafeBase (lanelib/safety.py), the one way to the wheels
        base = SafeBase(ros, twist_type, safety,
                        record=outputs.record_twist if outputs.bag else None,
                        topic=node.base_topic(args, ros))
        # last, so that no early exit leaves its thread inside OpenCV (that aborts the process)
        if not source.live:
            source = Prefetch(source)  # decode the next frames on the second core
        follower = LaneFollower(ros, source, controller, base, outputs, params.rate,
                                not args.quiet, check)
        install_signal_handlers(follower.request_stop, base, lambda: follower.ended is None)
    node.started(ros, args, follower, params)
    return node.drive(PROG, args, follower, topic_ros)


if __name__ == '__main__':
    sys.exit(main())
