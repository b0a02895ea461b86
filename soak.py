#!/usr/bin/env python3
"""Soak: kobuki_lane's loop for 10,000+ frames in the simulator, with faults injected at random.

The node's own LaneFollower drives a simulated Kobuki lap after lap of a built-in track (a new
lap starts where the last one was completed) through the headless rospy stand-in on a
simulated clock, while faults are injected at random (seeded):

    camera outage   reads fail for 0.5-4 s (the node stops the robot and reopens the camera)
    slow read       a read takes 0.5-2 s (the watchdog must keep stops coming)
    covered camera  the frames show no lane for 1.5-4 s (the controller must stop once the lane
                    has been lost for its lost_timeout)
    slow frame      the pipeline takes 0.5-1 s on a frame (its result must become a stop)
    pipeline error  the pipeline raises on a frame (a stop, and the loop goes on)

It reports frames, commands, the longest gap between commands, the non-zero commands published
while the camera was out or after the lane had been lost for lost_timeout (target: 0 each),
laps, departures, and RSS after 1,000 frames and at the end. The ROS master restart is not
simulated here; tests/test_ros_real.py kills and restarts a real roscore.

usage:
    python soak.py                           10,000 frames on the oval, improved controller
    python soak.py --frames 2000 --track s_bend --json out/soak.json
"""

import argparse
import json
import math
import os
import sys

import numpy as np

from bench import rss_mb
from calibration import LECTURE_CAMERA
from kobuki_lane import LaneFollower, LaneParams
from rospy_standin import SimClock, StandInRospy, Twist
from simulate import TrackSimulator, make_controller
from tracks import BUILTIN, load_track

FAULTS = {  # chance per frame, and duration range [s]
    'camera outage': (0.002, (0.5, 4.0)),
    'slow read': (0.003, (0.5, 2.0)),
    'covered camera': (0.002, (1.5, 4.0)),
    'slow frame': (0.003, (0.5, 1.0)),
    'pipeline error': (0.002, (0.0, 0.0)),
}


class FaultySimulator:
    """Laps of a track as one live camera, with faults. Records what happened when."""

    live = True  # a failed read is a lost camera, as on the robot
    skipped = 0
    total = None

    def __init__(self, track, ros, rng, frames):
        self.track, self.ros, self.rng, self.limit = track, ros, rng, frames
        self.name = f'simulated {track}'
        self.commands = []  # (t, linear.x, angular.z) of every Twist published
        self.outages, self.covered = [], []  # [start, end] in simulated seconds
        self.injected = dict.fromkeys(FAULTS, 0)
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
            return
        self.laps += self.sim.ended == 'completed'
        self.departures += len(self.sim.departure_points)
        self.sim.restart(self.ros.get_time())

    def _starts(self, fault):
        chance, (low, high) = FAULTS[fault]
        if self.rng.random() >= chance:
            return None
        self.injected[fault] += 1
        return self.rng.uniform(low, high)

    def read(self):
        now = self.ros.get_time()
        if self.frames >= self.limit:
            self.live = False  # the end of the soak, not a lost camera
            return False, None, None
        if self.outages and now < self.outages[-1][1]:
            return False, None, self.frames
        # outages are spaced out: two back to back are one long loss, which ends the run
        spaced = not self.outages or now > self.outages[-1][1] + 10.0
        length = spaced and self._starts('camera outage')
        if length:
            self.outages.append([now, now + length])
            return False, None, self.frames
        delay = self._starts('slow read')
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
        length = self._starts('covered camera')
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

    def perceive(self, frame, camera):
        delay = self.source._starts('slow frame')
        if delay:
            self.source.ros.clock.sleep(delay)
        if self.source._starts('pipeline error'):
            raise RuntimeError('injected pipeline error')
        return self.inner.perceive(frame, camera)

    def __call__(self, detection):
        return self.inner(detection)

    def extra(self):
        return self.inner.extra()


def moving(commands, intervals, grace=0.0):
    """Non-zero commands published inside any interval, `grace` seconds after its start."""
    count = 0
    for start, end in intervals:
        count += sum(1 for t, x, z in commands
                     if start + grace < t <= end and (x != 0.0 or z != 0.0))
    return count


def soak(track='oval', controller='improved', frames=10000, seed=0, progress=True):
    ros = StandInRospy(SimClock(), quiet=True, keep=100)
    rng = np.random.default_rng(seed)
    source = FaultySimulator(track, ros, rng, frames)
    params = LaneParams()
    inner = make_controller(controller, load_track(track), params)
    follower = LaneFollower(ros, Twist, source, params, LECTURE_CAMERA,
                            controller=FaultyController(inner, source))
    if progress:
        follower.progress.enabled, follower.progress.total = True, frames
    ended = follower.run()
    source._new_lap()  # count the lap in progress
    times = np.array([t for t, _, _ in source.commands])
    lost_timeout = getattr(getattr(inner, 'p', None), 'lost_timeout', 0.0)
    return dict(
        track=track, controller=controller, seed=seed, ended=ended, frames=follower.frames,
        simulated_s=round(ros.get_time(), 1), commands=len(source.commands),
        longest_gap_s=round(float(np.diff(times).max()), 3),
        faults=source.injected, laps_completed=source.laps, departures=source.departures,
        lap_ends={why: sum(1 for _, w in source.lap_ends if w == why)
                  for why in sorted({w for _, w in source.lap_ends})},
        watchdog_stops=follower.watchdog_stops,
        moving_while_camera_out=moving(source.commands, source.outages),
        moving_after_lane_lost=moving(source.commands, source.covered,
                                      lost_timeout + 1.0 / params.rate),
        moving_within_lost_timeout=(moving(source.commands, source.covered) -
                                    moving(source.commands, source.covered,
                                           lost_timeout + 1.0 / params.rate)),
        rss_1000_mb=round(source.rss.get(1000, math.nan), 1),
        rss_end_mb=round(source.rss.get(frames, math.nan), 1),
        rss_growth_mb=round(source.rss.get(frames, math.nan) - source.rss.get(1000, math.nan),
                            2))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--track', default='oval', choices=sorted(BUILTIN))
    parser.add_argument('--controller', default='improved', choices=('lecture', 'improved'))
    parser.add_argument('--frames', type=int, default=10000, help='default: 10000')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--json', metavar='FILE', help='write the figures as JSON')
    args = parser.parse_args(argv)
    if args.frames < 1000:
        parser.error('--frames must be at least 1000 (RSS is compared with frame 1,000)')
    if args.json and not os.path.isdir(os.path.dirname(os.path.abspath(args.json))):
        parser.error(f"--json '{args.json}': folder does not exist")
    result = soak(args.track, args.controller, args.frames, args.seed, sys.stderr.isatty())
    for key, value in result.items():
        print(f'{key}: {value}')
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump(result, f, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
