"""Live ROS topics the node reads: a camera driver's images and camera_info, and odometry.

    --source ros:/camera/rgb/image_raw             sensor_msgs/Image (TopicSource)
    --source ros:image image:=/camera/image_raw    a relative name, resolved in the node's
                                                   namespace and remapped as ROS nodes are
    --source ros:/usb_cam/image_raw/compressed     sensor_msgs/CompressedImage (a topic ending
                                                   in /compressed, as image_transport names it)
    --calibration topic                            the camera_info beside the image topic
    --odom /odom                                   nav_msgs/Odometry for the lane memory

Each takes the rospy module (real, or the stand-in for odometry in the simulator) and imports
the message types only when called, so nothing here needs ROS until it is used.
"""

import math
import re
import threading
import time

import numpy as np

from lanelib.imagemsg import ImageMessageError, decode_image
from lanelib.robot import could_move

PREFIX = 'ros:'
BUFFER = 2 ** 26  # [bytes] rospy's receive buffer: a whole 1920x1080 bgr8 frame, and then some
WARN_EVERY = 5.0  # [s] a warning that repeats (a bad frame, refused odometry) is said this seldom


def topic_of(spec):
    """The topic a --source names (ros:TOPIC), or None for any other source."""
    spec = str(spec)
    return spec[len(PREFIX):] if spec.startswith(PREFIX) else None


# a ROS graph resource name: words of letters, digits and _, each starting with a letter,
# joined by /; global with a leading /, else relative (resolved in the node's namespace, and
# remapped: ros:image with image:=/camera/rgb/image_raw)
TOPIC_NAME = re.compile(r'^/?[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*$')


def topic_problem(topic):
    """Why `topic` (what follows ros:) is not a ROS topic the node can subscribe to, or None."""
    if TOPIC_NAME.match(topic):
        return None
    return (f"'{PREFIX}{topic}' does not name a ROS topic: give a name after ros:, words of "
            "letters, digits and _ joined by /, e.g. ros:/camera/rgb/image_raw, or ros:image "
            "remapped (image:=/camera/rgb/image_raw)")


def info_topic(image_topic):
    """The camera_info beside an image topic: /camera/rgb/image_raw -> /camera/rgb/camera_info,
    /usb_cam/image_raw/compressed -> /usb_cam/camera_info."""
    topic = image_topic.rstrip('/')
    if topic.endswith('/compressed'):
        topic = topic[:-len('/compressed')]
    return topic.rsplit('/', 1)[0] + '/camera_info'


def published(rospy):
    """What the master has, for the messages that say a topic is silent."""
    try:
        topics = rospy.get_published_topics()
    except Exception as e:  # the master went away: say so instead
        return f'(the master could not be asked: {e})'
    return ', '.join(f'{t} ({m})' for t, m in sorted(topics)) or 'nothing at all'


class TopicSource:
    """The newest frame of an image topic, one per loop tick. The subscription keeps one
    message (queue_size 1, a receive buffer for a whole frame), so no backlog of stale views
    builds up; a frame received more than `fresh` seconds ago, or one already used, is not
    handed out: read() waits up to `wait` seconds for a new one, and otherwise reports the
    camera lost (the loop then stops the robot and waits for it, see safety.camera_back).
    Labels are the messages' header stamps [s]."""

    live = True
    total = None

    def __init__(self, rospy, topic, fresh=0.4, wait=0.4, warn=None):
        from sensor_msgs.msg import CompressedImage, Image

        self.rospy, self.topic = rospy, topic
        self.name = PREFIX + topic
        self.fresh, self.wait = fresh, wait
        self.compressed = topic.rstrip('/').endswith('/compressed')
        self.frame_id = ''  # the last frame's header.frame_id
        self.skipped = 0
        self._warn = warn or rospy.logwarn
        self._lock = threading.Lock()
        self._arrived = threading.Event()
        self._newest = None  # (monotonic time received, message)
        self._used = None
        self.bad = None  # (how many frames could not be decoded, the last one's reason)
        self._said = -math.inf  # when a bad frame was last said (at most one a WARN_EVERY)
        self._sub = rospy.Subscriber(topic, CompressedImage if self.compressed else Image,
                                     self._received, queue_size=1, buff_size=BUFFER)

    def _received(self, msg):
        with self._lock:
            self._newest = (time.monotonic(), msg)
        self._arrived.set()

    def _new(self, item):
        """Whether a (received, message) item is fresh and not used yet."""
        return (item is not None and item is not self._used and
                time.monotonic() - item[0] <= self.fresh)

    def _take(self):
        """The newest message if it is fresh and not used yet (then it is used), else None."""
        with self._lock:
            item = self._newest
            if not self._new(item):
                self._arrived.clear()
                return None
            self._used = item
            return item[1]

    def read(self):
        deadline = time.monotonic() + self.wait
        while True:
            msg = self._take()
            if msg is not None:
                try:
                    frame = decode_image(msg, self.compressed, f"'{self.topic}'")
                except ImageMessageError as e:  # one bad message: skipped, said, counted
                    self._skip(e)
                    continue
                self.frame_id = msg.header.frame_id  # the debug image's, beside its stamp
                return True, frame, round(msg.header.stamp.to_sec(), 6)
            left = deadline - time.monotonic()
            if left <= 0:
                return False, None, None
            self._arrived.wait(left)

    def _skip(self, error):
        """A frame that cannot be decoded: counted, and said at most once a WARN_EVERY seconds
        (a driver publishing 200 bad frames a second would fill the log)."""
        self.skipped += 1
        count = (self.bad[0] if self.bad else 0) + 1
        self.bad = (count, str(error))
        now = time.monotonic()
        if now - self._said >= WARN_EVERY:
            self._said = now
            self._warn('skipped a frame: %s (%d skipped so far; said at most every %g s)',
                       error, count, WARN_EVERY)

    def reopen(self):
        """True once a fresh frame has come (nothing to reopen: the driver publishes or not)."""
        with self._lock:
            return self._new(self._newest)

    def silence(self):
        """Why there is no frame, for the last word of a run that lost its camera."""
        with self._lock:
            newest = self._newest
        if newest is not None and time.monotonic() - newest[0] <= self.fresh + 1.0 and self.bad:
            return (f'frames come on {self.topic}, but they cannot be decoded ({self.bad[0]} '
                    f'skipped; the last: {self.bad[1]})')
        return f'nothing fresh is published on {self.topic}; the master has {published(self.rospy)}'

    def release(self):
        self._sub.unregister()


class TopicError(Exception):
    """A topic that gives nothing usable; the message names it and what is published."""


def camera_from_topic(rospy, image_topic, timeout):
    """A lanelib.camera.Camera from the first camera_info message beside `image_topic`, waited
    for up to `timeout` seconds; TopicError if none comes, or it holds no calibration or one
    that a camera_info YAML would be refused for (the same checks: lanelib.camera)."""
    from sensor_msgs.msg import CameraInfo

    topic = info_topic(image_topic)
    try:
        info = rospy.wait_for_message(topic, CameraInfo, timeout=timeout)
    except rospy.ROSException:
        raise TopicError(f'--calibration topic: no sensor_msgs/CameraInfo on {topic} within '
                         f'{timeout:g} s (--open-timeout: a camera driver slow to start needs '
                         f'longer); the master has {published(rospy)}') from None
    return camera_from_info(info, f'the camera_info on {topic}', topic)


def camera_from_info(info, where, name):
    """A lanelib.camera.Camera from a sensor_msgs/CameraInfo (rospy's, or a bag's as rosbags
    reads it: the same fields), `where` it came from for the messages, `name` when its header
    names no camera; TopicError if it holds no calibration or one that a camera_info YAML
    would be refused for (the same checks: lanelib.camera)."""
    from lanelib.camera import CalibrationError, checked_camera

    k = np.array(info.K, float).reshape(3, 3)
    if k[0, 0] == 0 or k[1, 1] == 0 or info.width <= 0 or info.height <= 0:
        raise TopicError(f'--calibration topic: {where} holds no calibration '
                         f'(fx {k[0, 0]:g}, fy {k[1, 1]:g}, {info.width}x{info.height}): '
                         'calibrate the camera (ROS camera_calibration, or calibration.py '
                         '--images) and give --calibration FILE')
    try:
        return checked_camera(info.header.frame_id or name, k, np.asarray(info.D, float),
                              (info.width, info.height), info.distortion_model or 'plumb_bob',
                              f'--calibration topic: {where}', ('K', 'D', 'distortion_model'))
    except CalibrationError as e:
        raise TopicError(f'{e}; calibrate the camera, or give --calibration FILE') from None


class Odometry:
    """The robot's pose from nav_msgs/Odometry (kobuki_node publishes /odom), for the lane
    memory: `pose(now)` is the newest (x, y, yaw) if it came less than `timeout` seconds ago,
    else None (then the memory dead-reckons on the commands). Each change between the two is
    logged. A message whose pose is not finite, or that jumps further than the robot can move
    since the last one (robot.could_move), is refused and said (at most every WARN_EVERY
    seconds); a jump the messages then keep to for `timeout` seconds is the odometry's new
    origin (a reset), and taken. clock: the loop's clock (ros.get_time, also in a dry run), so
    that `now` and the times messages came are on one clock. msg_type: nav_msgs.msg.Odometry by
    default (the simulator gives the stand-in's)."""

    def __init__(self, rospy, topic='/odom', timeout=0.5, msg_type=None, clock=None):
        if msg_type is None:
            from nav_msgs.msg import Odometry as msg_type
        self.rospy, self.topic, self.timeout = rospy, topic, timeout
        self.clock = clock or rospy.get_time
        self._lock = threading.Lock()
        self._newest = None  # (time received, (x, y, yaw))
        self._jumped = None  # (since, newest) of the messages refused for a jump
        self.refused = 0  # messages refused, in all
        self._said = -math.inf
        self.live = None  # None: nothing yet; then True or False, as last logged
        self._sub = rospy.Subscriber(topic, msg_type, self._received, queue_size=10)

    def _received(self, msg):
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        now = self.clock()
        if not all(map(math.isfinite, (p.x, p.y, q.x, q.y, q.z, q.w))):
            return self._refuse(now, 'its pose is not finite')
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        item = (now, (p.x, p.y, yaw))
        with self._lock:
            newest = self._newest
            ok = newest is None or _could_move(newest, item)
            if not ok:
                since, last = self._jumped or (now, None)
                if last is not None and _could_move(last, item):  # it keeps to the jump
                    ok = now - since >= self.timeout  # for long enough: a new origin
                    self._jumped = (since, item)
                else:
                    self._jumped = (now, item)
            if ok:
                self._newest, self._jumped = item, None
        if not ok:
            jump = math.hypot(p.x - newest[1][0], p.y - newest[1][1])
            self._refuse(now, f'it jumped {jump:.3g} m in {max(now - newest[0], 0.0):.2f} s, '
                              'further than the robot can move')

    def _refuse(self, now, why):
        self.refused += 1
        if now - self._said >= WARN_EVERY:
            self._said = now
            self.rospy.logwarn('odometry on %s refused: %s (%d refused so far); the lane memory '
                               'dead-reckons meanwhile', self.topic, why, self.refused)

    def pose(self, now):
        with self._lock:
            item = self._newest
        live = item is not None and now - item[0] <= self.timeout
        if live != self.live:
            if live:
                self.rospy.loginfo('odometry on %s: the lane memory follows it', self.topic)
            elif item is None:  # at the start: none has come yet
                self.rospy.logwarn('no odometry on %s yet: the lane memory dead-reckons on the '
                                   'commands sent until it comes', self.topic)
            elif self.live is not None:
                self.rospy.logwarn('no odometry on %s for %.1f s: the lane memory dead-reckons '
                                   'on the commands sent', self.topic, self.timeout)
            self.live = live
        return item[1] if live else None

    def release(self):
        self._sub.unregister()


def _could_move(a, b):
    """Whether the robot can have gone from pose item a to pose item b: (time, (x, y, yaw))."""
    (ta, (xa, ya, yawa)), (tb, (xb, yb, yawb)) = a, b
    turn = math.atan2(math.sin(yawb - yawa), math.cos(yawb - yawa))
    return could_move(math.hypot(xb - xa, yb - ya), turn, tb - ta)


def odometry_from(rospy, topic=None, default='/odom', clock=None):
    """The Odometry for --odom TOPIC (or ~odom, or /odom) when ROS is there, on the loop's
    `clock`; None without ROS or for 'none'."""
    if rospy is None:
        return None
    topic = topic or rospy.get_param('~odom', default)
    if topic in ('', 'none'):
        return None
    try:
        return Odometry(rospy, topic, clock=clock)
    except ImportError:
        rospy.logwarn("no odometry: nav_msgs is not installed (Debian's python3-nav-msgs); the "
                      'lane memory dead-reckons on the commands')
        return None
