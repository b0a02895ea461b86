"""The node's loop with the headless stand-in for rospy and a fake clock."""

import io
import json

import cv2
import numpy as np
import pytest

from kobuki_lane import LaneFollower, LaneParams, LectureRule
from lanelib.outputs import Outputs
from lanelib.robot import STOP, Command, within_limits
from lanelib.rospy_standin import SimClock, StandInRospy, Twist
from lanelib.safety import SafeBase
from lanelib.sources import ListSource


class ScriptedSource(ListSource):
    """Frames from memory; `on_read(i)` runs before frame i is handed out."""

    def __init__(self, frames, on_read=None, live=False):
        super().__init__(frames)
        self.live = live
        self._on_read = on_read or (lambda i: None)

    def read(self):
        self._on_read(self._next)
        return super().read()

    def reopen(self):
        return False


class Scripted(LectureRule):
    """The lecture's perception with commands chosen by the test."""

    def __init__(self, decide):
        super().__init__(LaneParams(), camera=None)
        self.decide = decide

    def __call__(self, detection, t=None):
        return self.decide(detection)


def blank_frames(n):
    return [np.full((480, 640, 3), 90, np.uint8) for _ in range(n)]


def make(source, controller=None, **params):
    """The loop on `source` with the stand-in on a simulated clock; decisions kept in memory."""
    ros = StandInRospy(SimClock(), quiet=True)
    p = LaneParams(**params)
    outputs = Outputs(p, decisions=io.StringIO())
    follower = LaneFollower(ros, source, controller or LectureRule(p, camera=None),
                            SafeBase(ros, Twist), outputs, p.rate)
    return ros, follower


def records(follower):
    """The decision records the loop wrote."""
    return [json.loads(line) for line in follower.outputs.decisions.getvalue().splitlines()]


def twists(ros):
    return [(t, m.linear.x, m.angular.z) for t, _, m in ros.published]


def test_one_command_per_frame_at_4hz_then_a_zero():
    ros, follower = make(ListSource(blank_frames(6)))
    assert follower.run() == 'end of input'
    out = twists(ros)
    assert len(out) == 7
    assert np.allclose(np.diff([t for t, _, _ in out[:6]]), 0.25)
    assert out[-1][1:] == (0.0, 0.0)
    assert all(topic == '/mobile_base/commands/velocity' for _, topic, _ in ros.published)


def test_every_branch_keeps_the_pace():
    # left, right, straight and none in turn: the lecture slept only after straight
    decisions = iter(['left', 'right', 'straight', 'none'] * 2)
    ros, follower = make(ListSource(blank_frames(8)),
                         Scripted(lambda d: Command(next(decisions), 0.01, 0.0)))
    follower.run()
    times = [t for t, _, _ in twists(ros)[:8]]
    assert np.allclose(np.diff(times), 0.25)


def test_slow_frames_do_not_slow_the_rate_and_a_stall_is_caught_up_like_rospy():
    clock_holder = {}

    def slow(i):
        clock_holder['ros'].clock.sleep(0.6 if i == 3 else 0.1)

    ros, follower = make(ScriptedSource(blank_frames(8), on_read=slow),
                         Scripted(lambda d: Command('straight', 0.05, 0.0)))
    clock_holder['ros'] = ros
    follower.run()
    times = np.array([t for t, x, _ in twists(ros) if x == 0.05])
    # each read takes 0.1 s, so frame k is published at 0.25 k + 0.1 while on schedule
    assert np.allclose(times[:3], [0.1, 0.35, 0.6])
    assert times[3] == pytest.approx(1.35)  # the 0.6 s stall
    assert np.allclose(np.diff(times[3:6]), 0.1)  # no sleep while behind: catching up
    assert times[7] == pytest.approx(0.25 * 7 + 0.1)  # back on the original schedule
    # during the stall the watchdog stopped the robot 0.4 s after the last command
    stops = [t for t, x, _ in twists(ros) if x == 0.0 and 0.6 < t < 1.35]
    assert stops and stops[0] == pytest.approx(1.0, abs=0.11)


def gaps(ros):
    times = [t for t, _, _ in twists(ros)]
    return np.diff(times)


def test_the_watchdog_keeps_commands_coming_while_the_camera_stalls():
    holder = {}
    ros, follower = make(ScriptedSource(
        blank_frames(6), on_read=lambda i: holder['ros'].clock.sleep(3.0 if i == 2 else 0.0)),
        Scripted(lambda d: Command('left', 0.05, 0.5)))
    holder['ros'] = ros
    follower.run()
    safety = follower.base.safety
    assert gaps(ros).max() <= safety.watchdog + safety.watchdog_check + 1e-9
    during = [(x, z) for t, x, z in twists(ros) if 0.5 < t < 3.5]
    assert len(during) >= 6 and all(c == (0.0, 0.0) for c in during)  # stopped, not turning
    assert follower.base.watchdog_stops == len(during)
    assert any('no command for' in text for _, text in ros.log_lines)


def test_the_controller_is_told_what_went_to_the_wheels():
    """A held robot, a late frame, a failed frame: the controller asked for motion, a stop was
    sent, and it is told so (the improved controller dead-reckons on it)."""
    told = []

    class Listening(Scripted):
        def sent(self, command):
            told.append(command)

    def decide(detection):
        if len(told) == 3:
            raise RuntimeError('a bad frame')
        return Command('left', 0.05, 9.0)

    ros, follower = make(ListSource(blank_frames(5)), Listening(decide))
    follower.base.hold('ROS master lost')
    follower.step(blank_frames(1)[0], 'held')
    follower.base.resume()
    follower.step(blank_frames(1)[0], 'late', read_at=ros.get_time() - 1.0)
    follower.step(blank_frames(1)[0], 'clipped to the Kobuki')
    follower.run()  # its first frame raises
    assert told[:2] == [STOP, STOP]
    assert told[2] == within_limits(Command('left', 0.05, 9.0)) and told[2].angular_z < 9.0
    assert told[3] == STOP


def test_what_the_controller_has_to_tell_is_logged_as_a_warning_when_it_says_it():
    """A controller's notice (the improved controller's pitch correction held at its limit)
    goes to the log as a warning, on the frame it comes, and only then."""
    class Telling(Scripted):
        def notice(self):
            return 'the camera is pitched off' if self.frames == 3 else None

        def __call__(self, detection, t=None):
            self.frames = getattr(self, 'frames', 0) + 1
            return super().__call__(detection, t)

    ros, follower = make(ListSource(blank_frames(6)), Telling(lambda d: STOP))
    follower.run()
    warned = [(level, text) for level, text in ros.log_lines if 'pitched off' in text]
    assert warned == [('WARN', 'the camera is pitched off')]


def test_a_frame_that_takes_too_long_is_acted_on_with_a_stop():
    holder = {}

    class Slow(Scripted):
        def perceive(self, frame, keep_stages=False):
            if holder['f'].frames == 2:
                holder['ros'].clock.sleep(1.0)  # a pathological frame
            return super().perceive(frame, keep_stages)

    ros, follower = make(ListSource(blank_frames(5)), Slow(lambda d: Command('right', 0.05, -0.5)))
    holder.update(f=follower, ros=ros)
    follower.run()
    written = records(follower)
    assert [r.get('late', False) for r in written] == [False, False, True, False, False]
    assert written[2]['decision'] == 'none' and written[2]['angular_z'] == 0.0
    assert gaps(ros).max() <= 0.5 + 1e-9


class Flaky(ScriptedSource):
    """A live camera whose reads fail from frame `fail_at` until it is reopened `after` times."""

    def __init__(self, frames, fail_at, reopen_ok_after):
        super().__init__(frames, live=True)
        self.fail_at, self.reopen_ok_after, self.reopens = fail_at, reopen_ok_after, 0

    def read(self):
        if self._next == self.fail_at and self.reopens < self.reopen_ok_after:
            return False, None, self._next
        return super().read()

    def reopen(self):
        self.reopens += 1
        return self.reopens >= self.reopen_ok_after


def test_a_camera_that_comes_back_is_reopened_and_driving_resumes():
    source = Flaky(blank_frames(8), fail_at=3, reopen_ok_after=2)
    ros, follower = make(source, Scripted(lambda d: Command('straight', 0.05, 0.0)))
    assert follower.run() == 'camera lost'  # the frames run out at the end; live, so lost
    out = twists(ros)
    # frames 0-2, a stop at once (same time as the failed read), then frames 3.. after reopening
    assert [x for _, x, _ in out[:4]] == [0.05, 0.05, 0.05, 0.0]
    assert out[3][0] - out[2][0] <= 0.25 + 1e-9
    assert source.reopens >= 2
    assert sum(1 for _, x, _ in out if x == 0.05) == 8


def test_a_camera_that_stays_lost_ends_the_run_after_the_retry_time():
    source = Flaky(blank_frames(8), fail_at=2, reopen_ok_after=10**6)
    ros, follower = make(source, Scripted(lambda d: Command('straight', 0.05, 0.0)))
    assert follower.run() == 'camera lost'
    out = twists(ros)
    failed_at = out[2][0]
    assert all(x == 0.0 for _, x, _ in out[2:])  # never moves again
    assert out[-1][0] - failed_at >= follower.base.safety.camera_retry
    assert gaps(ros).max() <= 0.5 + 1e-9  # stops kept coming while it retried


def test_camera_loss_ends_with_a_stop():
    ros, follower = make(ScriptedSource(blank_frames(3), live=True))
    assert follower.run() == 'camera lost'
    assert twists(ros)[-1][1:] == (0.0, 0.0)


def test_a_stop_request_ends_the_loop_and_nothing_moves_after_the_zero():
    holder = {}
    source = ScriptedSource(blank_frames(10),
                            on_read=lambda i: i == 4 and holder['f'].request_stop('SIGINT'))
    ros, follower = make(source, Scripted(lambda detection: Command('straight', 0.2, 0.0)))
    holder['f'] = follower
    assert follower.run() == 'SIGINT'
    out = twists(ros)
    # the request came during the read of frame 4: that frame is finished, then the stop
    assert len(out) == 6 and out[-1][1:] == (0.0, 0.0)
    assert all(x == 0.2 for _, x, _ in out[:5])
    follower.base.publish(Command('straight', 0.2, 0.0))  # a late command is refused
    assert len(twists(ros)) == 6


def test_ros_shutdown_mid_run_publishes_the_stop_from_the_hook():
    holder = {}
    source = ScriptedSource(blank_frames(10),
                            on_read=lambda i: i == 3 and holder['ros'].signal_shutdown('kill'))
    ros, follower = make(source)
    holder['ros'] = ros
    assert follower.run() == 'ROS shutdown'
    out = twists(ros)
    assert len(out) == 4 and out[-1][1:] == (0.0, 0.0)


def test_an_exception_on_one_frame_stops_the_robot_and_the_loop_goes_on():
    frames_done = {}

    def broken(detection):
        if frames_done['follower'].frames == 2:
            raise RuntimeError('boom')
        return Command('straight', 0.05, 0.0)

    ros, follower = make(ListSource(blank_frames(5)), Scripted(broken))
    frames_done['follower'] = follower
    assert follower.run() == 'end of input'
    assert [x for _, x, _ in twists(ros)] == [0.05, 0.05, 0.0, 0.05, 0.05, 0.0]
    written = records(follower)
    assert written[2]['error'] == 'RuntimeError: boom' and written[2]['decision'] == 'none'
    assert any('RuntimeError: boom' in text for level, text in ros.log_lines if level == 'ERROR')


def test_repeated_exceptions_end_the_run():
    def broken(detection):
        raise ValueError('bad frame')

    ros, follower = make(ListSource(blank_frames(20)), Scripted(broken))
    assert follower.run() == 'pipeline errors'
    assert follower.frames == follower.base.safety.max_errors
    assert all(x == 0.0 for _, x, _ in twists(ros))


@pytest.mark.parametrize('command, expected', [
    (Command('left', float('nan'), 0.1), (0.0, 0.0)),
    (Command('left', 0.1, float('inf')), (0.0, 0.0)),
    (Command('left', 5.0, -10.0), (0.7, -np.pi)),
    (Command('right', -5.0, 10.0), (-0.7, np.pi)),
    (Command('straight', 0.05, 0.0), (0.05, 0.0)),
])
def test_commands_are_kept_within_the_kobuki_limits(command, expected):
    c = within_limits(command)
    assert (c.linear_x, c.angular_z) == pytest.approx(expected)


def test_decision_records_have_the_documented_keys():
    ros, follower = make(ListSource(blank_frames(2)))
    record = follower.step(blank_frames(1)[0], 'x.png')
    for key in ('frame', 'source', 'lines', 'theta', 'value', 'decision', 'linear_x',
                'angular_z'):
        assert key in record
    assert record['source'] == 'x.png' and record['decision'] == 'none'
    assert record['linear_x'] == 0.0 and record['lines'] == 0


def test_debug_images_are_built_only_while_someone_subscribes():
    class Debug:
        """A debug topic whose subscribers come and go: asked once per frame."""

        def __init__(self, connections):
            self.connections, self.sent = iter(connections), []

        def get_num_connections(self):
            return next(self.connections)

        def publish(self, msg):
            self.sent.append(msg)

    built = []

    def draw(detection, command, p):
        built.append(1)
        return detection.image

    debug = Debug([0, 0, 1, 1, 0, 0])
    ros = StandInRospy(SimClock(), quiet=True)
    p = LaneParams()
    outputs = Outputs(p, debug=(debug, lambda image, stamp, frame_id: image.shape), draw=draw)
    follower = LaneFollower(ros, ListSource(blank_frames(6)), LectureRule(p, camera=None),
                            SafeBase(ros, Twist), outputs)
    follower.run()
    assert len(built) == 2 and debug.sent == [(480, 640, 3)] * 2


def test_the_debug_image_shows_the_stage_asked_for_stamped_as_its_frame():
    """~debug_image edges: the Canny edges, not the annotated frame; each message carries its
    frame's stamp and frame_id (a topic's frames are labelled with their header stamps)."""
    class Debug:
        def __init__(self):
            self.sent = []

        def get_num_connections(self):
            return 1

        def publish(self, msg):
            self.sent.append(msg)

    class StampedSource(ListSource):
        frame_id = 'usb_cam'

        def read(self):
            ok, frame, label = super().read()
            return ok, frame, (None if label is None else 100.5 + label)

    debug = Debug()
    ros = StandInRospy(SimClock(), quiet=True)
    p = LaneParams()
    frames = [np.zeros((480, 640, 3), np.uint8) for _ in range(2)]
    for frame in frames:
        cv2.line(frame, (100, 470), (300, 250), (255, 255, 255), 5)
    outputs = Outputs(p, debug=(debug, lambda image, stamp, frame_id: (image, stamp, frame_id)),
                      debug_stage='edges')
    follower = LaneFollower(ros, StampedSource(frames), LectureRule(p, camera=None),
                            SafeBase(ros, Twist), outputs)
    follower.run()
    assert [(stamp, frame_id) for _, stamp, frame_id in debug.sent] == [(100.5, 'usb_cam'),
                                                                        (101.5, 'usb_cam')]
    edges = cv2.Canny(cv2.GaussianBlur(cv2.cvtColor(frames[0], cv2.COLOR_BGR2GRAY), (5, 5), 0),
                      85, 85)
    image = debug.sent[0][0]
    assert image.shape == (480, 640, 3) and np.array_equal(image[:, :, 0], edges)
