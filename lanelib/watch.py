"""What a ROS run shows while it drives: its decisions and lane estimate on topics of its own
(for rqt_plot and rosbag record), and its health on /diagnostics (for rqt_robot_monitor).

Topics, in the node's private namespace (/kobuki_lane/... for a node named kobuki_lane), one
message per frame:

    ~decision         std_msgs/String    left, right, straight, none or search
    ~theta            std_msgs/Float64   the lecture's summed angles [rad]
    ~lines            std_msgs/Int32     Hough segments seen
    ~linear_x         std_msgs/Float64   the command sent [m/s]
    ~angular_z        std_msgs/Float64   the command sent [rad/s]
    ~lane/offset      std_msgs/Float64   the improved controller's lane estimate: the robot's
    ~lane/heading     std_msgs/Float64     offset from the lane's centre [m] (+ left of it),
    ~lane/curvature   std_msgs/Float64     heading to it [rad], curvature [1/m] and confidence
    ~lane/confidence  std_msgs/Float64     (0 to 1); NaN while there is no estimate

Diagnostics: one status, 'kobuki_lane: loop' (the node's name first), once a second: the
loop's rate against the one asked for, frames, late and failed frames, the camera (when the
last frame came), the master, and whether the robot is held stopped; WARN for late frames or
a slow loop, ERROR while the camera gives nothing or the robot is held.
"""

import math
import threading
import time
from collections import deque

LANE = (('offset', 'offset_m'), ('heading', 'heading_rad'), ('curvature', 'curvature'),
        ('confidence', 'confidence'))


class EstimateTopics:
    """The per-frame topics above; publish(record) with a decision record."""

    def __init__(self, rospy, lane=False):
        from std_msgs.msg import Float64, Int32, String

        self.Float64, self.Int32, self.String = Float64, Int32, String
        pub = rospy.Publisher
        self.decision = pub('~decision', String, queue_size=10)
        self.numbers = {key: pub('~' + key, Float64, queue_size=10)
                        for key in ('theta', 'linear_x', 'angular_z')}
        self.lines = pub('~lines', Int32, queue_size=10)
        self.lane = {key: pub('~lane/' + name, Float64, queue_size=10)
                     for name, key in LANE} if lane else {}

    def publish(self, record):
        self.decision.publish(self.String(record['decision']))
        self.lines.publish(self.Int32(int(record['lines'])))
        for key, publisher in list(self.numbers.items()) + list(self.lane.items()):
            value = record.get(key)
            publisher.publish(self.Float64(math.nan if value is None else float(value)))


class Health:
    """/diagnostics for one run. follower: kobuki_lane.LaneFollower; master: a ros.MasterWatch
    (None: not watched); rate: the rate asked for [Hz]."""

    def __init__(self, rospy, follower, master=None, period=1.0):
        import diagnostic_updater

        self.rospy, self.follower, self.master = rospy, follower, master
        self.lock = threading.Lock()
        self.times = deque(maxlen=40)  # monotonic times of the last frames
        self.late = 0
        self.last_frame = None
        self.updater = diagnostic_updater.Updater()
        self.updater.setHardwareID(rospy.get_name())  # /robot1/kobuki_lane: which robot
        self.updater.add('loop', self._status)  # shown as 'kobuki_lane: loop'
        self.period = period
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='diagnostics', daemon=True)

    def start(self):
        self._thread.start()
        return self

    def stop(self):
        self._stop.set()

    def frame(self, record):
        """A frame was decided (the loop's thread)."""
        with self.lock:
            self.times.append(time.monotonic())
            self.last_frame = self.times[-1]
            self.late += bool(record.get('late'))

    def _run(self):
        while not self._stop.wait(self.period):
            try:
                self.updater.force_update()
            except Exception:  # the master gone: the next second tries again
                pass

    def rate(self):
        """Frames per second over the last frames, or None with fewer than two."""
        with self.lock:
            times = list(self.times)
        if len(times) < 2 or times[-1] == times[0]:
            return None
        return (len(times) - 1) / (times[-1] - times[0])

    def _status(self, stat):
        from diagnostic_msgs.msg import DiagnosticStatus

        f = self.follower
        asked, rate = f.rate, self.rate()
        with self.lock:
            since = None if self.last_frame is None else time.monotonic() - self.last_frame
            late = self.late
        held = f.base.held
        lost = self.master is not None and self.master.lost
        level, words = DiagnosticStatus.OK, []
        if since is None or since > 2.0 / asked + f.base.safety.watchdog:
            level = DiagnosticStatus.ERROR
            words.append('no frame from the camera' if since is None else
                         f'no frame for {since:.1f} s')
        if held or lost:
            level = DiagnosticStatus.ERROR
            words.append(f'robot held stopped: {held or "ROS master lost"}')
        if level == DiagnosticStatus.OK and (rate is not None and rate < 0.9 * asked):
            level = DiagnosticStatus.WARN
            words.append(f'loop at {rate:.1f} Hz, below the {asked:g} Hz asked')
        if level == DiagnosticStatus.OK and late:
            level = DiagnosticStatus.WARN
            words.append(f'{late} late frames (robot stopped for each)')
        stat.summary(level, '; '.join(words) or f'driving at {rate or 0:.1f} Hz')
        stat.add('rate asked [Hz]', f'{asked:g}')
        stat.add('rate measured [Hz]', 'none yet' if rate is None else f'{rate:.2f}')
        stat.add('frames', f.frames)
        stat.add('late frames', late)
        stat.add('failed frames', f.failed)
        stat.add('camera', f.source.name)
        stat.add('last frame [s ago]', 'none yet' if since is None else f'{since:.2f}')
        stat.add('ROS master', 'lost' if lost else 'online')
        stat.add('robot held stopped', held or 'no')
        stat.add('controller', f.controller.name)
        return stat
