"""A thin stand-in for rospy and geometry_msgs/Twist, so the node's loop runs with no ROS at all.

It offers only the calls kobuki_lane.py makes (init_node, Publisher, Subscriber, Rate, Timer,
Duration, is_shutdown, on_shutdown, signal_shutdown, get_param, get_time, sleep,
logdebug/loginfo/logwarn/logerr, ROSInterruptException) with rospy's semantics, on a clock you
choose (the message types it carries, Twist and Odometry, are in lanelib/standin_msgs.py and
importable from here):

    SimClock()   simulated time: Rate.sleep() advances it instantly, firing timers on the way
                 (tests, fast dry runs, the simulator)
    WallClock()  real time: Rate.sleep() really sleeps (dry runs with --realtime)

Published messages are recorded in `StandInRospy.published` as (time_s, topic, message)
instead of being sent, and handed to any `listeners` (the simulator's robot base) and to the
Subscribers of their topic (the lane memory's odometry in the simulator); log lines
in `log_lines`. keep=N remembers only the last N of each, so a long dry run does not grow.
tests/test_ros_real.py runs the same loop against Debian's real rospy and checks that what a
real subscriber receives matches, so the two cannot drift apart.
"""

import os
import sys
import threading
import time
from collections import deque

from lanelib.standin_msgs import Odometry, Pose, Quaternion, Twist, Vector3  # noqa: F401


class ROSException(Exception):
    """rospy.ROSException: e.g. publishing to a topic closed by shutdown."""


class ROSInterruptException(ROSException, KeyboardInterrupt):
    """Raised by Rate.sleep() once shutdown has been signalled, as in rospy."""


class Duration:
    """rospy.Duration, as far as Timer needs it."""

    def __init__(self, secs):
        self.secs = float(secs)

    def to_sec(self):
        return self.secs


class SimClock:
    """Simulated time in seconds; sleeping advances it at once, firing any timers due on the
    way, in time order (so a slow read or frame can be simulated with clock.sleep)."""

    def __init__(self, start=0.0):
        self.t = start
        self.timers = []

    def now(self):
        return self.t

    def sleep(self, seconds):
        if seconds <= 0:
            return
        end = self.t + seconds
        while True:
            due = [timer for timer in self.timers if timer.due <= end and not timer.stopped]
            if not due:
                break
            timer = min(due, key=lambda tm: tm.due)
            self.t = max(self.t, timer.due)
            timer.due += timer.period
            timer.callback(None)
        self.t = end

    def start_timer(self, timer):
        timer.due = self.t + timer.period
        self.timers.append(timer)


class WallClock:
    """Real monotonic time; timers run on their own threads, as rospy's do."""

    def now(self):
        return time.monotonic()

    def sleep(self, seconds):
        if seconds > 0:
            time.sleep(seconds)

    def start_timer(self, timer):
        def run():
            while not timer.stopped:
                time.sleep(timer.period)
                if not timer.stopped:
                    timer.callback(None)

        threading.Thread(target=run, name='timer', daemon=True).start()


class Timer:
    """rospy.Timer: callback(event) every period (a Duration) on the stand-in's clock."""

    def __init__(self, clock, period, callback):
        self.period = period.to_sec()
        self.callback = callback
        self.stopped = False
        self.due = None
        clock.start_timer(self)

    def shutdown(self):
        self.stopped = True


class Rate:
    """rospy.Rate: sleep so that a loop runs at `hz`, catching up after a late iteration."""

    def __init__(self, ros, hz):
        self._ros = ros
        self.sleep_dur = 1.0 / hz
        self.last_time = ros.clock.now()

    def remaining(self):
        return self.last_time + self.sleep_dur - self._ros.clock.now()

    def sleep(self):
        if self._ros.is_shutdown():
            raise ROSInterruptException('ROS shutdown request')
        now = self._ros.clock.now()
        self._ros.clock.sleep(self.last_time + self.sleep_dur - now)
        self.last_time += self.sleep_dur
        # rospy resets its schedule when more than two periods behind
        if now - self.last_time > self.sleep_dur * 2:
            self.last_time = now


class Publisher:
    def __init__(self, ros, topic, data_class, queue_size):
        if queue_size is None:
            raise ValueError('queue_size must be given, as rospy warns')
        self._ros = ros
        self.name = topic
        self.data_class = data_class
        self.queue_size = queue_size

    def publish(self, msg):
        if self._ros.is_shutdown():
            raise ROSException('publish() to a closed topic')
        now = self._ros.clock.now()
        self._ros.published.append((now, self.name, msg))
        for listener in self._ros.listeners:
            listener(now, self.name, msg)
        for callback in list(self._ros.subscribers.get(self.name, ())):
            callback(msg)

    def get_num_connections(self):
        return 1  # the recorder always listens

    def unregister(self):
        pass


class Subscriber:
    """Messages published through the same StandInRospy on `topic` reach `callback` at once,
    on the publisher's thread."""

    def __init__(self, ros, topic, data_class, callback, queue_size=None, buff_size=None):
        self._ros, self.name, self.callback = ros, topic, callback
        ros.subscribers.setdefault(topic, []).append(callback)

    def unregister(self):
        callbacks = self._ros.subscribers.get(self.name, [])
        if self.callback in callbacks:
            callbacks.remove(self.callback)


class StandInRospy:
    """An object with the rospy module's API, for one headless run."""

    ROSException = ROSException
    ROSInterruptException = ROSInterruptException

    def __init__(self, clock=None, params=None, quiet=False, keep=None):
        self.clock = clock if clock is not None else SimClock()
        self.params = dict(params or {})
        self.published = deque(maxlen=keep)
        self.listeners = []  # callables (time, topic, message): a simulated robot listens here
        self.subscribers = {}  # topic: [callback]: Subscriber's
        self.log_lines = deque(maxlen=keep)
        self._quiet = quiet
        self._shutdown_reason = None
        self._hooks = []
        self.node_name = None

    # node life cycle
    def init_node(self, name, anonymous=False, disable_signals=False):
        self.node_name = '/' + name

    def is_shutdown(self):
        return self._shutdown_reason is not None

    def on_shutdown(self, hook):
        self._hooks.append(hook)

    def signal_shutdown(self, reason):
        if self._shutdown_reason is not None:
            return
        # hooks run before the flag is raised, as in rospy, so they can still publish
        for hook in self._hooks:
            hook()
        self._hooks.clear()
        self._shutdown_reason = reason

    # communication and time
    def Publisher(self, topic, data_class, queue_size=None):
        return Publisher(self, topic, data_class, queue_size)

    def Subscriber(self, topic, data_class, callback, queue_size=None, buff_size=None):
        return Subscriber(self, topic, data_class, callback, queue_size, buff_size)

    def Rate(self, hz):
        return Rate(self, hz)

    Duration = Duration

    def Timer(self, period, callback):
        return Timer(self.clock, period, callback)

    def get_time(self):
        return self.clock.now()

    def sleep(self, seconds):
        self.clock.sleep(seconds)

    def get_param(self, name, default=KeyError):
        """rospy's: the value, else `default` if one is given (None too), else KeyError."""
        key = name.lstrip('~')
        if key in self.params:
            return self.params[key]
        if default is KeyError:
            raise KeyError(name)
        return default

    # logging, formatted like rospy's: INFO to stdout (unless quiet), WARN and ERROR to stderr
    def _emit(self, level, msg, args):
        text = msg % args if args else msg
        self.log_lines.append((level, text))
        stream = sys.stdout if level == 'INFO' else sys.stderr
        if level != 'INFO' or not self._quiet:
            try:
                print(f'[{level}] [{self.clock.now():.3f}]: {text}', file=stream, flush=True)
            except (OSError, ValueError):  # a closed pipe (| head), the terminal gone
                _to_null(stream)

    def logdebug(self, msg, *args):
        self.log_lines.append(('DEBUG', msg % args if args else msg))

    def loginfo(self, msg, *args):
        self._emit('INFO', msg, args)

    def logwarn(self, msg, *args):
        self._emit('WARN', msg, args)

    def logerr(self, msg, *args):
        self._emit('ERROR', msg, args)


def _to_null(stream):
    """What is still written to `stream` (its reader gone: | head, a closed ssh session) goes
    to /dev/null instead: not a failure of the run, and no error at exit."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, stream.fileno())
        os.close(null)
    except (OSError, ValueError):
        pass
