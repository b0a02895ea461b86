"""The node's loop with the headless stand-in for rospy and a fake clock."""

import numpy as np
import pytest

from frames import ListSource
from kobuki_lane import Command, LaneFollower, LaneParams, LectureRule
from rospy_standin import SimClock, StandInRospy, Twist


class ScriptedSource(ListSource):
    """Frames from memory; `on_read(i)` runs before frame i is handed out."""

    def __init__(self, frames, on_read=None, live=False):
        super().__init__(frames)
        self.live = live
        self._on_read = on_read or (lambda i: None)

    def read(self):
        self._on_read(self._next)
        return super().read()


class Scripted(LectureRule):
    """The lecture's perception with commands chosen by the test."""

    def __init__(self, decide):
        super().__init__(LaneParams())
        self.decide = decide

    def __call__(self, detection):
        return self.decide(detection)


def blank_frames(n):
    return [np.full((480, 640, 3), 90, np.uint8) for _ in range(n)]


def make(source, **params):
    ros = StandInRospy(SimClock(), quiet=True)
    follower = LaneFollower(ros, Twist, source, LaneParams(**params), camera=None)
    return ros, follower


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


def test_every_branch_keeps_the_pace(monkeypatch):
    # left, right, straight and none in turn: the lecture slept only after straight
    decisions = iter(['left', 'right', 'straight', 'none'] * 2)
    ros, follower = make(ListSource(blank_frames(8)))
    follower.controller = Scripted(lambda d: Command(next(decisions), 0.01, 0.0))
    follower.run()
    times = [t for t, _, _ in twists(ros)[:8]]
    assert np.allclose(np.diff(times), 0.25)


def test_slow_frames_do_not_slow_the_rate_and_a_stall_is_caught_up_like_rospy():
    clock_holder = {}

    def slow(i):
        clock_holder['ros'].clock.sleep(0.6 if i == 3 else 0.1)

    ros, follower = make(ScriptedSource(blank_frames(8), on_read=slow))
    clock_holder['ros'] = ros
    follower.run()
    times = np.array([t for t, _, _ in twists(ros)[:8]])
    # each read takes 0.1 s, so frame k is published at 0.25 k + 0.1 while on schedule
    assert np.allclose(times[:3], [0.1, 0.35, 0.6])
    assert times[3] == pytest.approx(1.35)  # the 0.6 s stall
    assert np.allclose(np.diff(times[3:6]), 0.1)  # no sleep while behind: catching up
    assert times[7] == pytest.approx(0.25 * 7 + 0.1)  # back on the original schedule


def test_camera_loss_ends_with_a_stop():
    ros, follower = make(ScriptedSource(blank_frames(3), live=True))
    assert follower.run() == 'camera lost'
    assert twists(ros)[-1][1:] == (0.0, 0.0)


def test_a_stop_request_ends_the_loop_and_nothing_moves_after_the_zero():
    holder = {}
    source = ScriptedSource(blank_frames(10),
                            on_read=lambda i: i == 4 and holder['f'].request_stop('SIGINT'))
    ros, follower = make(source)
    follower.controller = Scripted(lambda detection: Command('straight', 0.2, 0.0))
    holder['f'] = follower
    assert follower.run() == 'SIGINT'
    out = twists(ros)
    # the request came during the read of frame 4: that frame is finished, then the stop
    assert len(out) == 6 and out[-1][1:] == (0.0, 0.0)
    assert all(x == 0.2 for _, x, _ in out[:5])
    follower._publish(Command('straight', 0.2, 0.0))  # a late command is refused
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


def test_an_exception_in_the_pipeline_still_stops_the_robot():
    ros, follower = make(ListSource(blank_frames(5)))

    def broken(detection):
        if follower.frames == 2:
            raise RuntimeError('boom')
        return Command('straight', 0.05, 0.0)

    follower.controller = Scripted(broken)
    with pytest.raises(RuntimeError):
        follower.run()
    out = twists(ros)
    assert len(out) == 3 and out[-1][1:] == (0.0, 0.0)


def test_decision_records_have_the_documented_keys():
    ros, follower = make(ListSource(blank_frames(2)))
    record = follower.step(blank_frames(1)[0], 'x.png')
    for key in ('frame', 'source', 'lines', 'theta', 'value', 'decision', 'linear_x',
                'angular_z'):
        assert key in record
    assert record['source'] == 'x.png' and record['decision'] == 'none'
    assert record['linear_x'] == 0.0 and record['lines'] == 0
