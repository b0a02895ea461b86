#!/usr/bin/env python3
"""Soak: kobuki_lane's loop for 10,000+ frames in the simulator, with faults injected at random.

The node's own LaneFollower drives a simulated Kobuki lap after lap of a built-in track (a new
lap starts where the last one was completed) through the headless rospy stand-in on a
simulated clock, while faults are injected at random (seeded):

    camera outage   reads fail for 0.5-4 s (the node stops the robot and reopens the camera)
    slow read       a read takes 0.5-2 s (the watchdog must keep stops coming)
    covered camera  the frames show no lane for 1.5-4 s (once the lane has been lost for its
                    lost_timeout, the improved controller may only drive on along the lane it
                    remembers, then turn in place to search for it, never forward again, for
                    at most search_angle, then stop)
    slow frame      the pipeline takes 0.5-1 s on a frame (its result must become a stop)
    pipeline error  the pipeline raises on a frame (a stop, and the loop goes on)

It reports frames, commands, the longest gap between commands, the non-zero commands published
while the camera was out (target: 0), and while the camera was covered, after the lane had been
lost for lost_timeout: how far the robot drove on the remembered lane (at most the 1.2 m it
remembers), how far it turned in place searching (at most search_angle), and the forward
commands after a search had begun (target: 0); laps, departures, and RSS after 1,000 frames
and at the end.

With --ros the same loop runs in real time on Debian's ROS 1 instead of the stand-in: a real
roscore, the node's real rospy publisher, watchdog timer and master watch, and a subscriber in
a process of its own that logs every Twist it receives. On top of the faults above

    master restart  roscore is killed (SIGKILL, as in a crash) and started again 2-8 s later
                    (the node must hold the robot stopped, then register again and drive on)

and it also reports what the subscriber received: commands, the longest gap between them, the
non-zero commands published while the master was gone (after the master watch had had time
to notice), and how long after the master's return the robot drove again. The loop runs at
--rate 20 by default there, so 10,000 frames take about 9 minutes instead of 42.

usage (from the repository root):
    python -m tools.soak                     10,000 frames on the oval, improved controller
    python -m tools.soak --frames 2000 --track s_bend --json out/soak.json
    python -m tools.soak --ros --json out/soak_ros.json
"""

import argparse
import math
import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from dataclasses import replace

import numpy as np

from kobuki_lane import LaneFollower, LaneParams, make_controller
from lanelib.camera import LECTURE_CAMERA
from lanelib.cli import check_output
from lanelib.outputs import Outputs, Progress
from lanelib.ros import MasterWatch
from lanelib.rospy_standin import SimClock, StandInRospy, Twist
from lanelib.safety import SafeBase, install_signal_handlers
from lanelib.sim.simulator import TrackSimulator, improved_params
from lanelib.sim.tracks import BUILTIN, load_track
from tools.common import rss_mb, write_json
from tools.roslive import Listener, free_port, node_env, start_master, stop_master

FAULTS = {  # how often each starts, per second of running, and its duration range [s]
    'camera outage': (0.008, (0.5, 4.0)),
    'slow read': (0.012, (0.5, 2.0)),
    'covered camera': (0.008, (1.5, 4.0)),
    'slow frame': (0.012, (0.5, 1.0)),
    'pipeline error': (0.008, (0.0, 0.0)),
}
MASTER_RESTART = (0.02, (2.0, 8.0))  # --ros only: roscore killed, started again this much later
MASTER_SPACING = 15.0  # [s] a master restart starts at least this long after the last ended


class FaultySimulator:
    """Laps of a track as one live camera, with faults. Records what happened when."""

    live = True  # a failed read is a lost camera, as on the robot
    skipped = 0
    total = None

    def __init__(self, track, ros, rng, frames, rate, master=None, faults=FAULTS):
        self.track, self.ros, self.rng, self.limit = track, ros, rng, frames
        self.rate, self.master, self.faults = rate, master, faults
        self.name = f'simulated {track}'
        self.commands = []  # (t, linear.x, angular.z) of every Twist published
        self.outages, self.covered = [], []  # [start, end] in the clock's seconds
        self.injected = dict.fromkeys(faults, 0)
        self.laps = self.departures = self.frames = 0
        self.lap_ends = []  # (time, why)
        self.rss = {}
        self.sim = None
        self._new_lap()

    def _record(self, t, topic, msg):
        self.commands.append((t, msg.linear.x, msg.angular.z))

    def _new_lap(self):
        if self.sim is None:
            self.ros.listeners.append(self._record)
            self.sim = TrackSimulator(load_track(self.track), self.ros,
                                      seed=int(self.rng.integers(1e9)))
            self.sim.restart(self.ros.get_time())
            return
        self.laps += self.sim.ended == 'completed'
        self.departures += len(self.sim.departure_points)
        self.sim.restart(self.ros.get_time())

    def chance(self, per_second, span):
        """A fault starting at this frame? Its duration if so (0.0 for an instant), else None."""
        if self.rng.random() >= per_second / self.rate:
            return None
        return self.rng.uniform(*span)

    def starts(self, fault):
        length = self.chance(*self.faults[fault])
        if length is not None:
            self.injected[fault] += 1
        return length

    def read(self):
        now = self.ros.get_time()
        if self.frames >= self.limit:
            self.live = False  # the end of the soak, not a lost camera
            return False, None, None
        if self.master is not None:
            self.master.maybe_restart(self, now)
        if self.outages and now < self.outages[-1][1]:
            return False, None, self.frames
        # outages are spaced out: two back to back are one long loss, which ends the run
        spaced = not self.outages or now > self.outages[-1][1] + 10.0
        length = spaced and self.starts('camera outage')
        if length:
            self.outages.append([now, now + length])
            return False, None, self.frames
        delay = self.starts('slow read')
        if delay:
            self.ros.clock.sleep(delay)
        ok, frame, _ = self.sim.read()
        if not ok:  # lap completed (or departed): the next lap starts here
            self.lap_ends.append((round(now, 2), self.sim.ended))
            self._new_lap()
            ok, frame, _ = self.sim.read()
            if not ok:
                self.lap_ends.append((round(now, 2), 'restart failed: ' + self.sim.ended))
                return False, None, self.frames
        length = self.starts('covered camera')
        if length:
            self.covered.append([self.ros.get_time(), self.ros.get_time() + length])
        if self.covered and self.ros.get_time() < self.covered[-1][1]:
            frame = np.full_like(frame, int(frame.mean()))
        self.frames += 1
        if self.frames in (1000, self.limit):
            self.rss[self.frames] = rss_mb()
        return True, frame, self.frames - 1

    def reopen(self):
        return not self.outages or self.ros.get_time() >= self.outages[-1][1]

    def release(self):
        pass


class FaultyController:
    """The controller, with slow frames and exceptions injected into its perception."""

    def __init__(self, inner, source):
        self.inner, self.source = inner, source
        self.name = inner.name

    def perceive(self, frame, keep_stages=False):
        delay = self.source.starts('slow frame')
        if delay:
            self.source.ros.clock.sleep(delay)
        if self.source.starts('pipeline error') is not None:  # (its duration is 0.0)
            raise RuntimeError('injected pipeline error')
        return self.inner.perceive(frame, keep_stages)

    def __call__(self, detection, t=None):
        return self.inner(detection, t)

    def extra(self):
        return self.inner.extra()

    def notice(self):
        return self.inner.notice()

    def sent(self, command):
        self.inner.sent(command)


def blind(commands, intervals, grace, rate):
    """After `grace` seconds of each interval (the lane lost that long): the largest forward
    distance [m] and in-place turn [deg] commanded in one interval, each command acting for one
    loop period, and the forward commands that came after an in-place turn (a search) had
    begun in it."""
    forward, turned, after_search = 0.0, 0.0, 0
    for start, end in intervals:
        inside = [(x, z) for t, x, z in commands if start + grace < t <= end]
        forward = max(forward, sum(x for x, _ in inside if x > 0) / rate)
        turns = [i for i, (x, z) in enumerate(inside) if x == 0.0 and z != 0.0]
        turned = max(turned, math.degrees(sum(abs(inside[i][1]) for i in turns) / rate))
        if turns:
            after_search += sum(1 for x, _ in inside[turns[0]:] if x > 0)
    return round(forward, 3), round(turned, 1), after_search


def moving(commands, intervals, grace=0.0):
    """Non-zero commands published inside any interval, `grace` seconds after its start."""
    count = 0
    for start, end in intervals:
        count += sum(1 for t, x, z in commands
                     if start + grace < t <= end and (x != 0.0 or z != 0.0))
    return count


# ---------------------------------------------------------------- the ROS variant

class WallTime:
    """The simulator's clock on real ROS: wall time, as rospy.get_time() without sim time."""

    @staticmethod
    def now():
        return time.time()

    @staticmethod
    def sleep(seconds):
        if seconds > 0:
            time.sleep(seconds)


class TappedPublisher:
    """A rospy Publisher that also hands each message to TappedRospy's listeners."""

    def __init__(self, pub, topic, ros):
        self._pub, self._topic, self._ros = pub, topic, ros

    def publish(self, msg):
        for listener in self._ros.listeners:
            listener(time.time(), self._topic, msg)
        self._pub.publish(msg)

    def __getattr__(self, name):
        return getattr(self._pub, name)


class TappedRospy:
    """rospy itself, except that every message the node publishes is also handed to
    `listeners`: the simulated base drives on the Twists as they are published, while a real
    subscriber in another process measures what ROS delivers."""

    def __init__(self, rospy):
        self._rospy, self.listeners, self.clock = rospy, [], WallTime()

    def __getattr__(self, name):
        return getattr(self._rospy, name)

    def Publisher(self, topic, data_class, **kwargs):
        return TappedPublisher(self._rospy.Publisher(topic, data_class, **kwargs), topic, self)


class RealRos:
    """A roscore that the soak kills and restarts at random, this process as the node, and a
    subscriber process logging what it receives."""

    def __init__(self, restart=MASTER_RESTART, spacing=MASTER_SPACING):
        self.restarts, self.spacing = restart, spacing  # see MASTER_RESTART, MASTER_SPACING
        self.port = free_port()
        self.home = tempfile.mkdtemp(prefix='kobuki_lane_soak_')
        uri = f'http://localhost:{self.port}'
        self.env = node_env(uri, self.home)
        os.environ.update(ROS_MASTER_URI=uri, ROS_HOSTNAME='localhost', ROS_HOME=self.home,
                          ROS_LOG_DIR=self.home)
        os.environ.pop('ROS_IP', None)
        self.master = start_master(self.port, self.env)
        self.outages = []  # [killed at, answering again at] (wall time)
        self._restarting = None  # the thread starting roscore again
        self.listener = Listener(self.env, os.path.join(self.home, 'received.log'))
        deadline = time.monotonic() + 30
        while not self.listener.ready():
            if time.monotonic() > deadline:
                raise RuntimeError('the subscriber process did not start')
            time.sleep(0.1)
        import rospy
        from geometry_msgs.msg import Twist as RosTwist

        rospy.init_node('kobuki_lane', disable_signals=True)
        self.ros, self.twist_type = TappedRospy(rospy), RosTwist

    def maybe_restart(self, source, now):
        """Called on every frame: kill roscore now and then, and start it again later."""
        if self._restarting is not None and self._restarting.is_alive():
            return
        if self.outages and now < self.outages[-1][1] + self.spacing:
            return
        down_for = source.chance(*self.restarts)
        if down_for is None:
            return
        stop_master(self.master, signal.SIGKILL)
        self.outages.append([time.time(), math.inf])
        self._restarting = threading.Thread(target=self._restart, args=(down_for,),
                                            name='master-restart', daemon=True)
        self._restarting.start()

    def _restart(self, down_for):
        time.sleep(down_for)
        self.master = start_master(self.port, self.env)
        self.outages[-1][1] = time.time()

    def close(self):
        """Wait for a restart in progress, let the last Twist arrive, stop everything;
        returns what the subscriber received."""
        if self._restarting is not None:
            self._restarting.join()
        time.sleep(0.5)
        received = self.listener.messages()
        self.listener.close()
        self.ros.signal_shutdown('soak done')
        stop_master(self.master)
        shutil.rmtree(self.home, ignore_errors=True)  # roscore's logs
        return received


class TimedWatch(MasterWatch):
    """The node's master watch, unchanged, noting when it asked each question the master
    answered (wall time): a question asked after a kill and answered proves the new master (an
    answer received late to one asked before the kill proves nothing, so the asking is timed)."""

    def __init__(self, *args, clock=time.time, **kwargs):
        super().__init__(*args, **kwargs)
        self.clock, self.answered = clock, []

    def alive(self):
        asked = self.clock()
        answers = super().alive()
        if answers:
            self.answered.append(asked)
        return answers


def master_outages(world, watch):
    """[killed at, answering again at] for each restart. The restart's own check sees the new
    master late (it also looks for its process); when the node's watch heard it first, the
    master was back by then (by the time the watch asked, within a round trip), and a move
    after that is not one made while it was gone."""
    return [[killed, min([back] + [t for t in watch.answered if t > killed])]
            for killed, back in world.outages]


def master_figures(world, source, received, watch):
    """What the subscriber got, and how the node behaved while the master was gone.

    Driving again after the master's return is timed only where no camera fault (an outage
    or a covered camera, which stop the robot by themselves) fell between the return and the
    first move; those restarts are counted apart."""
    commands = source.commands
    grace = watch.period + watch.timeout  # the master watch notices within this
    outages = master_outages(world, watch)
    back_to_driving, other_fault = [], 0
    for i, (_, back) in enumerate(outages):
        later = outages[i + 1][0] if i + 1 < len(outages) else math.inf
        moves = [t for t, x, z in commands if back < t < later and (x != 0.0 or z != 0.0)]
        if not moves:
            continue
        if any(a < moves[0] and b > back for a, b in source.outages + source.covered):
            other_fault += 1
            continue
        back_to_driving.append(moves[0] - back)
    times = np.array([t for t, _, _ in received])
    return dict(
        master_restarts=len(outages),
        master_down_s=round(sum(b - a for a, b in outages), 1),
        moving_while_master_lost=moving(commands, outages, grace),
        moving_within_master_watch=(moving(commands, outages) -
                                    moving(commands, outages, grace)),
        driving_again_after_master_s=dict(
            median=round(float(np.median(back_to_driving)), 2) if back_to_driving else None,
            max=round(max(back_to_driving), 2) if back_to_driving else None,
            restarts=len(back_to_driving), camera_fault_meanwhile=other_fault),
        received=len(received),
        not_received=len(commands) - len(received),
        longest_gap_received_s=round(float(np.diff(times).max()), 3) if len(times) > 1 else None,
        last_received_is_stop=bool(received) and received[-1][1:] == (0.0, 0.0))


# ---------------------------------------------------------------- the soak

def soak(track='oval', controller='improved', frames=10000, seed=0, progress=True, rate=4.0,
         real_ros=False, handle_signals=False, faults=FAULTS, master_restart=MASTER_RESTART,
         master_spacing=MASTER_SPACING, tuned=None):
    """The soak; its figures as a dict. faults: the fault table (FAULTS); master_restart and
    master_spacing: how often roscore is killed with --ros (MASTER_RESTART, MASTER_SPACING);
    tuned: ImprovedParams fields to change (e.g. search_angle=0, the plain stop)."""
    rng = np.random.default_rng(seed)
    params = LaneParams(rate=rate)
    world = watch = None
    if real_ros:
        world = RealRos(master_restart, master_spacing)
        ros, twist_type = world.ros, world.twist_type
    else:
        ros, twist_type = StandInRospy(SimClock(), quiet=True, keep=100), Twist
    try:
        source = FaultySimulator(track, ros, rng, frames, rate, world, faults)
        spec = load_track(track)
        inner = make_controller(controller, params, LECTURE_CAMERA,
                                replace(improved_params(spec), **(tuned or {}))
                                if controller == 'improved' else None)
        base = SafeBase(ros, twist_type)
        follower = LaneFollower(ros, source, FaultyController(inner, source), base,
                                Outputs(params, progress=Progress(frames, progress)), rate)
        if handle_signals:  # Ctrl-C ends the soak with the robot stopped and its figures
            install_signal_handlers(follower.request_stop)
        if real_ros:
            watch = TimedWatch(base, ros).start()
        started = ros.get_time()
        ended = follower.run(10.0 if real_ros else 0.0)
        elapsed = ros.get_time() - started
    finally:
        if watch is not None:
            watch.stop()
        received = world.close() if world is not None else None
    source._new_lap()  # count the lap in progress
    times = np.array([t for t, _, _ in source.commands])
    lost_timeout = getattr(getattr(inner, 'p', None), 'lost_timeout', 0.0)
    result = dict(
        track=track, controller=controller, seed=seed, rate_hz=rate,
        ros='real roscore and rospy' if real_ros else 'stand-in, simulated clock',
        ended=ended, frames=follower.frames,
        seconds=round(elapsed, 1), commands=len(source.commands),
        longest_gap_s=round(float(np.diff(times).max()), 3),
        faults=source.injected, laps_completed=source.laps, departures=source.departures,
        lap_ends={why: sum(1 for _, w in source.lap_ends if w == why)
                  for why in sorted({w for _, w in source.lap_ends})},
        watchdog_stops=base.watchdog_stops, frames_failed=follower.failed,
        moving_while_camera_out=moving(source.commands, source.outages),
        moving_after_lane_lost=moving(source.commands, source.covered,
                                      lost_timeout + 1.0 / params.rate),
        moving_within_lost_timeout=(moving(source.commands, source.covered) -
                                    moving(source.commands, source.covered,
                                           lost_timeout + 1.0 / params.rate)),
        **dict(zip(('blind_forward_m', 'search_turn_deg', 'forward_after_search'),
                   blind(source.commands, source.covered, lost_timeout + 1.0 / params.rate,
                         params.rate))),
        rss_1000_mb=round(source.rss.get(1000, math.nan), 1),
        rss_end_mb=round(source.rss.get(frames, math.nan), 1),
        rss_growth_mb=round(source.rss.get(frames, math.nan) - source.rss.get(1000, math.nan),
                            2))
    if real_ros:
        result.update(master_figures(world, source, received, watch))
    return result


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--track', default='oval', choices=sorted(BUILTIN))
    parser.add_argument('--controller', default='improved', choices=('lecture', 'improved'))
    parser.add_argument('--frames', type=int, default=10000, help='default: 10000')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--ros', action='store_true',
                        help="real time on Debian's ROS 1 (a real roscore, restarted at random) "
                             'instead of the stand-in on a simulated clock')
    parser.add_argument('--rate', type=float, metavar='HZ',
                        help='loop rate (default: 4, as on the robot; 20 with --ros)')
    parser.add_argument('--json', metavar='FILE', help='write the figures as JSON')
    args = parser.parse_args(argv)
    if args.frames < 1000:
        parser.error('--frames must be at least 1000 (RSS is compared with frame 1,000)')
    rate = args.rate or (20.0 if args.ros else 4.0)
    if not (math.isfinite(rate) and 0 < rate <= 30):
        parser.error(f'--rate {args.rate}: must be above 0 and at most 30 Hz')
    if args.json:
        check_output('tools.soak', args.json, '--json')
    if args.ros:
        if shutil.which('roscore') is None:
            parser.error("--ros needs Debian's ros-core (roscore); 'bash setup.sh test' "
                         'installs it')
    result = soak(args.track, args.controller, args.frames, args.seed, sys.stderr.isatty(),
                  rate, args.ros, handle_signals=True)
    for key, value in result.items():
        print(f'{key}: {value}')
    write_json(args.json, result)
    return 0


if __name__ == '__main__':
    sys.exit(main())
