"""What keeps the robot safe while the node runs: one small module, to audit in one sitting.

The lecture's code had none of this. Every command to the wheels goes through SafeBase:

    limits     each command is clipped to the Kobuki's 0.7 m/s and pi rad/s; NaN is a stop
    hold       while held (the ROS master lost), every command is a stop
    latch      after stop() (Ctrl-C, SIGTERM, rosnode kill, end of input, any error) a zero Twist
               has been sent and nothing moves the robot again
    watchdog   a timer publishes a stop whenever `watchdog` seconds pass without a command (a
               slow frame or camera), well inside the Kobuki driver's 0.6 s timeout

The loop adds two more (kobuki_lane.LaneFollower): a frame whose result comes later than the
watchdog is answered with a stop, and a lost camera is stopped for at once and reopened for
`camera_retry` seconds (camera_back below). Signals end the run through the loop, so the stop
is sent before the process exits (install_signal_handlers).
"""

import contextlib
import math
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass

from lanelib.robot import STOP, VELOCITY_TOPIC, within_limits
from lanelib.settings import between, positive, setting

WATCHDOG_MAX = 0.5  # [s] 0.1 s inside the Kobuki driver's 0.6 s (robot.COMMAND_TIMEOUT)


def below_kobuki_timeout(x):
    return math.isfinite(x) and 0 < x <= WATCHDOG_MAX


@dataclass
class Safety:
    """How the loop protects the robot. Not the lecture's (it had none), so not in LaneParams."""

    watchdog: float = setting(0.4, 'no command for this long (a slow frame or camera): publish '
                              'a stop, and again as long as it lasts; a frame that took longer '
                              'to process is acted on with a stop. At most 0.5, below the '
                              "Kobuki driver's 0.6 s command timeout", 's', below_kobuki_timeout)
    watchdog_check: float = setting(0.1, 'how often the watchdog looks', 's',
                                    below_kobuki_timeout)
    camera_retry: float = setting(5.0, 'a live camera that stops giving frames is reopened for '
                                  'this long before the run ends (exit status 1)', 's',
                                  between(0, 3600))
    max_errors: int = setting(5, 'this many frames in a row failing in the pipeline end the run '
                              '(exit status 1)', 'frames', positive)


def make_twist(twist_type, command):
    thrust = twist_type()
    thrust.linear.x = float(command.linear_x)
    thrust.angular.z = float(command.angular_z)
    return thrust


class SafeBase:
    """The only way to the wheels: a publisher on the Kobuki's velocity topic with the limits,
    the hold, the stop latch and the watchdog described above.

    ros: the rospy module or a rospy_standin.StandInRospy; twist_type: the matching Twist;
    record: called with (time, linear.x, angular.z) for every command sent (a bag)."""

    def __init__(self, ros, twist_type, safety=None, record=None, topic=VELOCITY_TOPIC):
        self.ros, self.twist_type, self.topic = ros, twist_type, topic
        self.safety = safety or Safety()
        self.record = record
        self.held = None  # while set (e.g. 'ROS master lost'), every command is a stop
        self.watchdog_stops = 0
        self._lock = threading.Lock()
        self._stopped = False
        self._last_sent = None  # ros time of the last command published
        self._stalled = False
        self._timer = None
        self._pub = ros.Publisher(topic, twist_type, queue_size=1)
        ros.on_shutdown(self.stop)

    def _send(self, command):
        """Publish (and record); the caller holds the lock."""
        self._pub.publish(make_twist(self.twist_type, command))
        if self.record is not None:
            self.record(self.ros.get_time(), command.linear_x, command.angular_z)

    def publish(self, command):
        """Send `command` within the Kobuki's limits, unless the stop has been sent."""
        with self._lock:
            if self._stopped:
                return  # never move again once the stop has been sent
            self._send(within_limits(command))
            self._last_sent = self.ros.get_time()

    def hold(self, reason):
        """Stop the robot now and answer every frame with a stop until resume()."""
        self.held = reason
        self.publish(STOP)

    def resume(self):
        self.held = None

    def stop(self):
        """Publish a zero Twist once; later commands are refused. Safe from any thread."""
        with self._lock:
            if self._stopped:
                return
            self._stopped = True
            try:
                self._send(STOP)
            except self.ros.ROSException as e:  # topic already closed by a ROS shutdown
                self.ros.logwarn('could not publish the final stop: %s', e)

    def start_watchdog(self):
        period = self.ros.Duration(self.safety.watchdog_check)
        self._timer = self.ros.Timer(period, self._watchdog)

    def stop_watchdog(self):
        if self._timer is not None:
            self._timer.shutdown()

    def _watchdog(self, _event):
        """Runs on a timer: a stop whenever nothing has been published for too long."""
        now = self.ros.get_time()
        with self._lock:
            if self._stopped or self._last_sent is None:
                return
            if now - self._last_sent < self.safety.watchdog:
                self._stalled = False
                return
            self._send(STOP)
            self._last_sent = now
            self.watchdog_stops += 1
            first = not self._stalled
            self._stalled = True
        if first:
            self.ros.logwarn('no command for %.1f s (slow frame or camera): robot stopped',
                             self.safety.watchdog)

    def wait_for_subscriber(self, seconds, stopping=lambda: False):
        """Wait up to `seconds` for the base to subscribe; warn if it has not. Returns early,
        saying nothing, once `stopping()` is true (Ctrl-C, rosnode kill)."""
        deadline = time.monotonic() + seconds
        while self._pub.get_num_connections() == 0 and time.monotonic() < deadline:
            if stopping() or self.ros.is_shutdown():
                return
            time.sleep(0.05)
        if self._pub.get_num_connections() == 0 and seconds > 0:
            self.ros.logwarn('nothing subscribes to %s yet (is minimal.launch running?); '
                             'publishing anyway', self.topic)


def camera_back(ros, source, base, since, retry, stopping):
    """After a failed read from a live source: stop, then reopen it until it gives frames
    again or `retry` seconds have passed since the first failure (False: give up). Returns
    True at once when `stopping()` says the loop is ending for another reason."""
    base.publish(STOP)
    if ros.get_time() - since > retry:
        return False
    ros.logwarn("no frame from '%s': robot stopped; reopening it (for up to %.0f s)",
                source.name, retry)
    while ros.get_time() - since <= retry:
        if stopping():
            return True
        ros.sleep(1.0)
        if source.reopen():
            ros.loginfo("reopened '%s'", source.name)
            return True
    return False


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # Ctrl-C, kill, the ssh gone


def install_signal_handlers(request_stop, base=None, running=None, grace=2.0):
    """SIGINT, SIGTERM and SIGHUP (the terminal or ssh session to the robot gone) ask the loop
    to end (it then stops the robot). A second signal while the loop is still `running()` is
    not ignored: SIGINT raises KeyboardInterrupt (main ends the run without a traceback), the
    others end the process; once the loop has ended and only the outputs are being closed,
    it is ignored, so that a bag is not left half written.

    Python runs a signal handler only once the main thread is back from what it is doing, and
    an OpenCV call can take seconds (an 8000x6000 frame takes 7.5). So with `base` the signal is
    also heard at once on a thread of its own (signal.set_wakeup_fd): the robot is stopped then
    and there (base.stop(), the latch), and if the loop is still `running()` `grace` seconds
    later the process exits (128 + the signal's number), saying why."""
    heard = set()

    def handler(signum, _frame):
        if running is not None and not running():
            return  # the loop has ended: the outputs are being closed
        if signum not in heard:
            heard.add(signum)
            request_stop(signal.Signals(signum).name)
        elif signum == signal.SIGINT:
            raise KeyboardInterrupt  # the loop ends at once (LaneFollower.run)
        else:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)

    for signum in STOP_SIGNALS:
        signal.signal(signum, handler)
    if base is None:
        return
    read, write = os.pipe()
    os.set_blocking(write, False)
    signal.set_wakeup_fd(write, warn_on_full_buffer=False)

    def hear():
        signum = 0
        while signum not in STOP_SIGNALS:
            signum = os.read(read, 1)[0]
        base.stop()  # the robot stops now, whatever the main thread is doing
        time.sleep(grace)
        if running is None or running():  # (once the loop has ended, its outputs close)
            say(f'kobuki_lane: the frame in progress had not ended {grace:g} s after '
                f'{signal.Signals(signum).name}; the robot was stopped at once; exiting now')
            os._exit(128 + signum)

    threading.Thread(target=hear, name='signal-watch', daemon=True).start()


@contextlib.contextmanager
def signals_held():
    """Ctrl-C, SIGTERM and SIGHUP wait while the loop is being put together (outputs opened, a
    bag begun, threads started) and are raised again on leaving, where the handlers that
    install_signal_handlers put in meanwhile hear them: they end the run the usual way, the
    bag complete (before: a traceback from wherever the signal fell)."""
    heard = []

    def defer(signum, _frame):
        heard.append(signum)

    before = {signum: signal.signal(signum, defer) for signum in STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, handler in before.items():
            if signal.getsignal(signum) is defer:  # nothing was installed meanwhile
                signal.signal(signum, handler)
        for signum in heard:
            os.kill(os.getpid(), signum)


def say(text):
    """A line on stderr, if there is still a stderr to write to (the ssh session may be gone)."""
    try:
        print(text, file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass
