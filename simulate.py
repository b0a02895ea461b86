#!/usr/bin/env python3
"""Drive a simulated Kobuki round a taped track with kobuki_lane's real loop.

The simulator is the loop's frame source: each read renders the onboard camera view (the
world's camera, the track's mounting) from the robot's pose, after
moving the robot up to the current simulated time with the Twists the loop published, which
reach it through the headless rospy stand-in. One frame per loop iteration at 4 Hz, as on the
robot; nothing sleeps, and a run is deterministic for a given seed.

The base is Kobuki-like: unicycle kinematics, |linear.x| <= 0.7 m/s, |angular.z| <= pi rad/s,
an optional acceleration limit, commands reaching the wheels --latency seconds after they are
published, and the driver's timeout: no command for 0.6 s and the base stops.

Worlds (--world, or world: in the track file) are what the floor looks like: lecture (grey tape
on a grey floor, the lecture's level webcam), wood (white tape on wood planks, light and
shadows, a warm cast, a webcam pitched 15 degrees), duckietown (a two-lane road on foam mats:
yellow dashed centre line, white edges, red stop lines, a Duckiebot-like wide camera 0.1 m up
pitched 20 degrees) and autorace (yellow and white solid lines, TurtleBot3 AutoRace's lane).
The improved controller is given the world's lane profile (lanelib/lanes.py).

usage:
    python simulate.py --track lecture --controller improved --json out.json --plot out.png
    python simulate.py --track s_bend --world duckietown --controller improved --video run.avi
    python simulate.py --track my_track.yaml --controller lecture --video run.avi
    python simulate.py --track tools/tracks/duckietown_small_loop_cw.yaml --robot duckiebot \
        --controller improved                          a robot preset, as the node takes it
    python simulate.py --benchmark                     every built-in track and world
    python simulate.py --benchmark --tracks tools/tracks/s_*.yaml --seeds 0 1 2 3
                                                       the S-bends drawn after tuning, every world
    python simulate.py --list-tracks                   the built-in tracks and worlds

A run ends when the robot completes the track, departs the lane (its centre more than half a
lane width from the centre line; --continue drives on), stalls (no progress for 30 s), or
reaches --time-limit. Built-in tracks: lecture (A straight, B left, C right), oval, s_bend,
tight. Track files: see lanelib/sim/tracks.py.

exit status: 0 the run completed (--benchmark: every improved-controller run completed), 1 it
did not (a departure, a stall, the time limit), 2 bad arguments or track file.
"""

import os

# numpy's BLAS one thread, as the node runs it (see kobuki_lane.py): set before numpy loads.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import argparse
import functools
import json
import math
import sys
from dataclasses import replace

import cv2
import numpy as np

from kobuki_lane import LaneFollower, LaneParams, make_controller
from kobuki_lane import build_parser as node_parser
from lanelib.camera import CAMERAS
from lanelib.cli import check_output, check_outputs_apart, fail
from lanelib.mounting import MountingError, parse_pattern, read_mounting
from lanelib.node import settings_from
from lanelib.outputs import Outputs
from lanelib.robot import ODOM_TOPIC
from lanelib.rospy_standin import Odometry as OdometryMessage
from lanelib.rospy_standin import SimClock, StandInRospy, Twist
from lanelib.safety import SafeBase
from lanelib.sim.base import BaseLimits
from lanelib.sim.simulator import (
    VARIANTS,
    SideBySide,
    TopDown,
    TrackSimulator,
    apply_variant,
    improved_params,
)
from lanelib.sim.tracks import BUILTIN, TrackError, load_track, with_world
from lanelib.sim.world import WORLDS, chessboard_view
from lanelib.topics import Odometry

PROG = 'simulate.py'


# ---------------------------------------------------------------- runs

def robot_settings(robot, spec, controller='improved', mounting=None):
    """(lecture table, improved controller's settings or None) as kobuki_lane resolves
    `--robot ROBOT --controller CONTROLLER`: the preset's rate, lane profile, distances in lane
    widths, speeds, gates; told the track's lane width and the camera's mounting, the simulated
    one or `mounting` (what --mounting FILE tells the node). Raises ValueError (RobotError)
    for a preset that cannot be used."""
    args = node_parser().parse_args(['--robot', robot, '--controller', controller])
    params, _, _, improved, _ = settings_from(args, lambda name, default=None: default,
                                              LaneParams)
    if improved is not None:
        m = mounting or spec.mounting
        improved = replace(improved, camera_height=m.height, camera_pitch=m.pitch_deg,
                           camera_forward=m.forward, camera_roll=m.roll_deg,
                           lane_width=spec.track.lane_width)
    return params, improved


def preset_factory(improved):
    """A run's controller_factory that makes the controller with `improved` (robot_settings'),
    the world's camera."""
    def factory(name, spec, params, odometry=None):
        return make_controller(name, params, CAMERAS[spec.camera], improved, odometry=odometry)
    return factory


def controller_for(name, spec, params, mounting=None, odometry=None):
    """kobuki_lane's controller, told the track's camera; the improved one also its mounting
    (or `mounting`, e.g. from a --mounting file), lane and odometry."""
    return make_controller(name, params, CAMERAS[spec.camera],
                           improved_params(spec, mounting) if name == 'improved' else None,
                           odometry=odometry)


class ComparedFollower(LaneFollower):
    """kobuki_lane's loop, each frame's lane estimate (the improved controller's decision
    record) kept beside where the robot truly was in its lane when the frame was rendered
    (truth: TrackSimulator.truth)."""

    def __init__(self, *args, truth, **kwargs):
        super().__init__(*args, **kwargs)
        self.truth, self.readings = truth, []

    def step(self, frame, label, read_at=None):
        true = self.truth()  # the robot has not moved since the frame was rendered
        record = super().step(frame, label, read_at)
        self.readings.append((*true, record.get('offset_m'), record.get('heading_rad'),
                              record.get('curvature')))
        return record


def estimate_metrics(readings):
    """How well the lane estimate read the lane (ComparedFollower.readings), or None for a
    controller that keeps none (the lecture's): of the frames, how many had an estimate; the
    median and 90th percentile of its offset's and heading's errors; on the bends, the median
    share of the bend's curvature it read (1: all of it, 0.5: a bend read half as tight), and
    on the straights the median curvature it read [1/m]."""
    rows = [r for r in readings if r[3] is not None]
    if not rows:
        return None
    true_offset, true_heading, true_k, offset, heading, k = (np.array(c, float)
                                                             for c in zip(*rows))
    offset_error = np.abs(offset - true_offset) * 100
    heading_error = np.degrees(np.abs(heading - true_heading))
    bend = true_k != 0

    def pair(errors):
        return [round(float(np.percentile(errors, q)), 2) for q in (50, 90)]

    return dict(frames=len(rows), of=len(readings),
                offset_error_cm=pair(offset_error), heading_error_deg=pair(heading_error),
                bend_frames=int(bend.sum()),
                bend_curvature_read=(round(float(np.median(k[bend] / true_k[bend])), 3)
                                     if bend.any() else None),
                straight_curvature=(round(float(np.median(k[~bend])), 3)
                                    if (~bend).any() else None))


def describe_estimate(e):
    """The estimate_metrics line simulate.py prints."""
    line = (f"estimate on {e['frames']} of {e['of']} frames: offset error "
            f"{e['offset_error_cm'][0]:.1f} cm median ({e['offset_error_cm'][1]:.1f} at the 90th "
            'percentile), heading error '
            f"{e['heading_error_deg'][0]:.1f} deg ({e['heading_error_deg'][1]:.1f})")
    if e['bend_curvature_read'] is not None:
        line += (f"; in the bends it read {e['bend_curvature_read']:.0%} of their curvature "
                 f"(median of {e['bend_frames']} frames)")
    if e['straight_curvature'] is not None:
        line += f", on the straights {e['straight_curvature']:+.2f} /m"
    return line


def run(spec, controller='lecture', seed=0, video=None, plot=None, time_limit=None,
        keep_going=False, start_offset=0.0, start_yaw=0.0, limits=None,
        controller_factory=controller_for, odometry=False, params=None):
    """One closed-loop run; returns the metrics dict. controller_factory(name, spec,
    params): the controller to drive with (controller_for: kobuki_lane's, told the track).
    odometry: the base publishes /odom through the stand-in and the improved controller's lane
    memory follows it (factory called with odometry=topics.Odometry). params: the lecture's
    table (LaneParams; its rate is the loop's), default the lecture's defaults."""
    ros = StandInRospy(SimClock(), quiet=True)
    sim = TrackSimulator(spec, ros, seed, time_limit, keep_going, start_offset, start_yaw,
                         limits, odometry)
    params = params or LaneParams()
    topdown = TopDown(sim) if (video or plot) else None
    sink = SideBySide(video, params.rate, topdown) if video else None
    odom = Odometry(ros, ODOM_TOPIC, msg_type=OdometryMessage) if odometry else None
    ctl = controller_factory(controller, spec, params, **({'odometry': odom} if odom else {}))
    follower = ComparedFollower(ros, sim, ctl, SafeBase(ros, Twist),
                                Outputs(params, video=sink, draw=getattr(ctl, 'draw', None)),
                                params.rate, truth=sim.truth)
    try:
        follower.run()
    finally:
        if sink:
            sink.close()
    result = sim.metrics(controller)
    result['decisions'] = follower.counts
    result['estimate'] = estimate_metrics(follower.readings)
    if plot:
        outcome = 'completed' if result['completed'] else 'ended: ' + result['ended']
        title = (f"{spec.name} / {controller}: {outcome}"
                 f"\nprogress {result['progress']:.0%}  rms {result['rms_offset_m'] * 100:.1f} cm  "
                 f"max {result['max_offset_m'] * 100:.1f} cm  {result['mean_speed_mps']:.2f} m/s  "
                 f"departures {result['departures']}")
        cv2.imwrite(plot, topdown.draw(title))
    return result


# ---------------------------------------------------------------- command line

def _bench_job(job):
    track, world, controller, variant, seed, (offset, yaw) = job
    spec = apply_variant(with_world(load_track(track), WORLDS[world]), variant)
    result = run(spec, controller, seed=seed, start_offset=offset, start_yaw=math.radians(yaw))
    result.update(variant=variant, start_offset_m=offset, start_yaw_deg=yaw)
    return result


def benchmark(jobs=2, seed=0, stream=None, worlds=None, tracks=None, seeds=None,
              start=(0.0, 0.0)):
    """Every built-in track x both controllers in the lecture's world, and the improved one in
    every world (with that world's lane profile) under each condition; or, given `tracks`
    (names or files), the improved controller on each as drawn (no condition added) in every
    world. Once per seed of `seeds` (default: `seed`); every run started `start` (offset [m],
    yaw [deg]) off the centre line."""
    worlds, seeds = list(worlds or WORLDS), list(seeds or [seed])
    if tracks:  # each track's seeds side by side
        work = [(t, w, 'improved', 'clean', s, start) for w in worlds for t in tracks
                for s in seeds]
    else:
        work = [(t, 'lecture', c, 'clean', s, start) for s in seeds for t in BUILTIN
                for c in ('lecture', 'improved') if 'lecture' in worlds]
        work += [(t, w, 'improved', v, s, start) for s in seeds for w in worlds
                 for v in VARIANTS for t in BUILTIN if (w, v) != ('lecture', 'clean')]
    if jobs > 1:
        from multiprocessing import Pool

        with Pool(jobs) as pool:
            results = pool.map(_bench_job, work)
    else:
        results = [_bench_job(job) for job in work]
    (stream or sys.stdout).write(benchmark_table(results) + benchmark_summary(results))
    return results


# the options --benchmark takes; any other given with it is refused rather than ignored
# (--robot has its own message)
BENCHMARK_TAKES = ('benchmark', 'worlds', 'tracks', 'seeds', 'seed', 'start_offset',
                   'start_yaw', 'jobs', 'json', 'force', 'robot', 'list_tracks')
FLAGS = {'keep_going': '--continue'}  # where an option's name is not its flag's


def flag(name):
    """The command-line flag of the option `name` (argparse's dest)."""
    return FLAGS.get(name, f"--{name.replace('_', '-')}")


def benchmark_summary(results):
    """Per world, how many of the improved controller's runs completed."""
    lines = []
    for world in dict.fromkeys(r['world'] for r in results):
        mine = [r for r in results if r['world'] == world and r['controller'] == 'improved']
        done = sum(r['completed'] for r in mine)
        off = {(r['start_offset_m'], r['start_yaw_deg']) for r in mine} - {(0.0, 0.0)}
        lines.append(f'{world}: the improved controller completed {done} of {len(mine)} runs' +
                     ''.join(f', started {o:+g} m and {y:+g} degrees off the centre line'
                             for o, y in off))
    return '\n'.join(lines) + '\n'


def benchmark_table(results):
    rows = ['| world | track | seed | controller | condition | completed | progress | '
            'RMS offset | max offset | mean speed | departures | ended |',
            '|---|---|---|---|---|---|---|---|---|---|---|---|']
    for r in results:
        rows.append(f"| {r['world']} | {r['track']} | {r['seed']} | {r['controller']} | "
                    f"{r['variant']} | "
                    f"{'yes' if r['completed'] else 'no'} | {r['progress']:.0%} | "
                    f"{r['rms_offset_m'] * 100:.1f} cm | {r['max_offset_m'] * 100:.1f} cm | "
                    f"{r['mean_speed_mps']:.3f} m/s | {r['departures']} | {r['ended']} |")
    return '\n'.join(rows) + '\n'


def ranged(low, high, kind=float, open_low=False):
    """An argparse type: a finite number from low to high (more than low if open_low)."""
    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            value = None
        if value is None or not math.isfinite(value) or value > high or (
                value <= low if open_low else value < low):
            raise argparse.ArgumentTypeError(
                f"'{text}' is not a number {'above' if open_low else 'from'} {low:g} "
                f"{'and at most' if open_low else 'to'} {high:g}")
        return value
    return parse


def tape_option(first, second, example):
    """An argparse type for LINE:<first>:<second> (metres), e.g. --gap left:2.0:0.2."""
    def parse(text):
        try:
            line, a, b = text.split(':')
            return {'line': line, first: float(a), second: float(b)}
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not LINE:{first.upper()}:"
                                             f'{second.upper()}, e.g. {example}') from None
    return parse


def build_parser():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--track', default='lecture',
                        help=f"built-in ({', '.join(BUILTIN)}) or a YAML/JSON file")
    parser.add_argument('--world', choices=sorted(WORLDS),
                        help="what the floor looks like (default: the track file's, or lecture)")
    parser.add_argument('--controller', choices=('lecture', 'improved'), default='lecture',
                        help="the lecture's rule (default) or the improved controller")
    parser.add_argument('--seed', type=ranged(0, 10**9, int), default=0,
                        help='frame noise seed, 0 to 10^9 (default 0)')
    parser.add_argument('--robot', metavar='NAME|FILE',
                        help="drive with a robot preset's settings, as kobuki_lane.py --robot "
                             "resolves them: 'kobuki', 'duckiebot' or a YAML file (its loop "
                             'rate, lane profile, distances and speeds); told the lane width '
                             "of the track and the camera's mounting (the simulated one, or "
                             "--mounting's); the camera is the world's (default: the "
                             "simulator's own settings for the world)")
    parser.add_argument('--json', metavar='FILE', help='write the run metrics as JSON')
    parser.add_argument('--plot', metavar='FILE', help='write the top-down view as PNG')
    parser.add_argument('--video', metavar='FILE',
                        help='write onboard (annotated) beside top-down view, .avi or .mp4')
    parser.add_argument('--time-limit', type=ranged(0, 1e5, open_low=True), metavar='S',
                        help='end the run here, above 0 (default: track length / 0.04 m/s + 30 s)')
    parser.add_argument('--force', action='store_true',
                        help='replace --json, --plot, --video and --chessboard files that exist '
                             'already (without it, an existing file is refused before the run)')
    parser.add_argument('--continue', dest='keep_going', action='store_true',
                        help='drive on after a departure instead of ending the run')
    scene = parser.add_argument_group('scene and robot (override the track file)')
    scene.add_argument('--noise', type=ranged(0, 100),
                       help='frame noise sigma [grey levels], 0 to 100')
    scene.add_argument('--gradient', type=ranged(0, 255),
                       help='lighting gradient [grey levels], 0 to 255')
    scene.add_argument('--glare', type=ranged(0, 255),
                       help='glare patch brightness [grey levels], 0 to 255')
    scene.add_argument('--gap', type=tape_option('at', 'length', 'left:2.0:0.2'),
                       action='append', default=[],
                       metavar='LINE:AT:LENGTH', help='tape missing, e.g. left:2.0:0.2 [m]')
    scene.add_argument('--dashes', type=tape_option('on', 'off', 'both:0.1:0.1'),
                       metavar='LINE:ON:OFF',
                       help='dashed tape, e.g. both:0.1:0.1 [m]')
    scene.add_argument('--camera-height', type=ranged(0, 2, open_low=True),
                       help='[m], above 0, at most 2')
    scene.add_argument('--camera-pitch', type=ranged(-45, 80),
                       help='down from horizontal [deg], -45 to 80')
    scene.add_argument('--camera-roll', type=ranged(-45, 45),
                       help='about the optical axis, + right side lower [deg], -45 to 45')
    scene.add_argument('--mounting', metavar='FILE',
                       help="the improved controller's idea of the mounting, a YAML from "
                            'calibration.py --ground (default: the true one)')
    scene.add_argument('--start-offset', type=ranged(-1, 1), default=0.0,
                       help='[m], + left, -1 to 1 (with --benchmark: every run)')
    scene.add_argument('--start-yaw', type=ranged(-90, 90), default=0.0,
                       help='[deg], + left, -90 to 90 (with --benchmark: every run)')
    scene.add_argument('--accel', type=ranged(0, 10), default=0.0,
                       help='base acceleration limit [m/s^2], 0 for none, at most 10')
    scene.add_argument('--latency', type=ranged(0, 2), default=0.05,
                       help='publish to wheels [s], 0 to 2 (default 0.05)')
    scene.add_argument('--odometry', action='store_true',
                       help="the base publishes odometry on /odom and the improved "
                            "controller's lane memory follows it, as on the robot (default: "
                            'dead reckoning on the commands)')
    scene.add_argument('--slip', type=ranged(0, 0.5), default=0.0,
                       help='with --odometry: the wheels turn this fraction more than the robot '
                            'moves, 0 to 0.5')
    scene.add_argument('--odom-noise', type=ranged(0, 1), default=0.0,
                       help="with --odometry: sigma of odometry's turn rate error [rad/s], "
                            '0 to 1')
    scene.add_argument('--turn-response', type=ranged(0.3, 2), default=1.0,
                       help='the base turns this share of the turn asked, 0.3 to 2 (default 1: '
                            "as asked; gym-duckietown's Duckiebot turns about 0.6 of it)")
    board = parser.add_argument_group('a chessboard on the floor, for calibration.py --ground')
    board.add_argument('--chessboard', metavar='FILE',
                       help="write what the track's camera, mounted as it is, sees of a "
                            'chessboard lying in front of the robot (PNG), instead of a run')
    board.add_argument('--pattern', default='7x5',
                       help='its inner corners, columns (across the robot) x rows (default 7x5)')
    board.add_argument('--square', type=ranged(0.005, 0.5), default=0.05,
                       help='side of a square [m], 0.005 to 0.5 (default 0.05)')
    board.add_argument('--board-ahead', type=ranged(0.05, 5), default=0.8,
                       help="nearest row of inner corners this far ahead of the robot's centre "
                            '[m], 0.05 to 5 (default 0.8)')
    bench = parser.add_argument_group('benchmark')
    bench.add_argument('--benchmark', action='store_true',
                       help="run every built-in track x {lecture, improved} in the lecture's "
                            'world, and the improved controller in every world, clean and with '
                            'noise 10, a lighting gradient and a 20 cm gap; print a Markdown '
                            'table (--json writes all results)')
    bench.add_argument('--worlds', nargs='+', choices=sorted(WORLDS), metavar='WORLD',
                       help='with --benchmark: only these worlds')
    bench.add_argument('--tracks', nargs='+', metavar='TRACK',
                       help='with --benchmark: these tracks (built-in names or files) instead '
                            'of the built-in ones, the improved controller only, each as drawn '
                            '(no noise, gradient or gap added), in every world of --worlds; '
                            'e.g. the S-bends drawn after tuning: --tracks tools/tracks/s_*.yaml')
    bench.add_argument('--seeds', nargs='+', type=ranged(0, 10**9, int), metavar='SEED',
                       help='with --benchmark: every run once per seed (default: --seed)')
    bench.add_argument('--jobs', type=ranged(1, 64, int), default=2,
                       help='parallel runs, 1 to 64 (default 2)')
    parser.add_argument('--list-tracks', action='store_true', help='list the built-in tracks')
    return parser


def check_outputs(args):
    """Refuse, before the run, an output that is a folder, has a name its writer cannot use (a
    --plot without an image extension failed in OpenCV after the whole run), is an input (the
    --track or --mounting file) or exists already without --force (the node's rule)."""
    pictures = ('.png', '.jpg', '.jpeg', '.bmp')
    endings = {'--plot': pictures, '--chessboard': pictures, '--video': ('.avi', '.mp4')}
    outputs = [(path, what) for path, what in ((args.json, '--json'), (args.plot, '--plot'),
                                               (args.video, '--video'),
                                               (args.chessboard, '--chessboard')) if path]
    for path, what in outputs:
        check_output(PROG, path, what)
        if os.path.isdir(path):
            fail(PROG, f"{what} '{path}' is a folder; give a file name")
        if what in endings and not path.lower().endswith(endings[what]):
            fail(PROG, f"{what} '{path}': give a name ending in "
                       f"{' or '.join(endings[what])}")
    inputs = [(args.track, '--track file'), (args.mounting, '--mounting file')]
    check_outputs_apart(PROG, inputs, outputs, args.force)


def customise(spec, args):
    if args.world:
        spec = with_world(spec, WORLDS[args.world])
    for key in ('noise', 'gradient', 'glare'):
        if getattr(args, key) is not None:
            setattr(spec.scene, key, getattr(args, key))
    for gap in args.gap:
        if gap['line'] not in ('left', 'right', 'both') or gap['length'] <= 0:
            fail(PROG, f'--gap {gap}: line must be left, right or both, length positive')
    spec.gaps = spec.gaps + args.gap
    if args.dashes:
        d = args.dashes
        if d['line'] not in ('left', 'right', 'both') or d['on'] <= 0 or d['off'] <= 0:
            fail(PROG, f'--dashes {d}: line must be left, right or both, on and off positive')
        spec.dashes = d
    if args.camera_height is not None:
        spec.mounting.height = args.camera_height
    if args.camera_pitch is not None:
        spec.mounting.pitch_deg = args.camera_pitch
    if args.camera_roll is not None:
        spec.mounting.roll_deg = args.camera_roll
    return spec


def write_chessboard(spec, args):
    """The --chessboard picture: the board on the floor through the track's camera."""
    try:
        pattern = parse_pattern(args.pattern)
    except ValueError as e:
        fail(PROG, f'--pattern: {e}')
    image = chessboard_view(CAMERAS[spec.camera], spec.mounting, pattern, args.square,
                            args.board_ahead, seed=args.seed)
    if not cv2.imwrite(args.chessboard, image):
        fail(PROG, f"--chessboard '{args.chessboard}': cannot write it")
    m = spec.mounting
    print(f'wrote {args.chessboard}: a {args.pattern} board of {args.square:g} m squares '
          f'{args.board_ahead:g} m ahead, seen by the {spec.camera} camera {m.height:g} m up, '
          f'pitched {m.pitch_deg:g} deg, rolled {m.roll_deg:g} deg, {m.forward:g} m ahead of '
          'the robot centre')


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    check_outputs(args)
    if args.list_tracks:
        for name in BUILTIN:
            spec = load_track(name)
            print(f'{name}: {spec.track.length:.2f} m, {len(spec.track.segments)} segments'
                  f"{', closed' if spec.closed else ''}")
        for name, world in WORLDS.items():
            print(f'world {name}: {world.floor} floor, lane profile {world.lane}, '
                  f'{world.camera} camera')
        return 0
    if (args.tracks or args.seeds) and not args.benchmark:
        fail(PROG, '--tracks and --seeds go with --benchmark; one run takes --track and --seed')
    if args.benchmark:
        if args.robot:  # its rows are the simulator's own settings, measured as such
            fail(PROG, '--robot drives one run; --benchmark runs every track with the '
                       "simulator's own settings for each world: leave one of them out")
        ignored = [flag(name) for name, value in vars(args).items()
                   if name not in BENCHMARK_TAKES and value != parser.get_default(name)]
        if ignored:  # taken silently, they would not be what the table measured
            takes = [flag(name) for name in BENCHMARK_TAKES
                     if name not in ('benchmark', 'robot', 'list_tracks')]
            fail(PROG, f"{', '.join(ignored)}: for one run; --benchmark drives its own tracks, "
                       f"worlds and conditions (it takes {', '.join(takes)})")
        if args.tracks:
            try:
                for track in args.tracks:
                    load_track(track)  # a bad file is refused before any run
            except TrackError as e:
                fail(PROG, f'--tracks: {e}')
        results = benchmark(max(1, args.jobs), args.seed, worlds=args.worlds,
                            tracks=args.tracks, seeds=args.seeds,
                            start=(args.start_offset, args.start_yaw))
        write_json(args.json, results)
        failed = [r for r in results if r['controller'] == 'improved' and not r['completed']]
        if failed:
            print(f'{PROG}: {len(failed)} improved-controller runs did not complete',
                  file=sys.stderr)
        return 1 if failed else 0
    try:
        spec = customise(load_track(args.track), args)
    except TrackError as e:
        fail(PROG, str(e))
    if args.chessboard:
        write_chessboard(spec, args)
        return 0
    factory, params, mounting = controller_for, None, None
    if args.mounting:
        try:
            mounting = read_mounting(args.mounting)
        except MountingError as e:
            fail(PROG, f'--mounting: {e}')
    if args.robot:
        try:
            params, improved = robot_settings(args.robot, spec, args.controller, mounting)
        except ValueError as e:
            fail(PROG, f'--robot: {e}')
        factory = preset_factory(improved)
    elif mounting:
        factory = functools.partial(controller_for, mounting=mounting)
    limits = BaseLimits(accel=args.accel, alpha=args.accel * 4, latency=args.latency,
                        slip=args.slip, odom_noise=args.odom_noise,
                        turn_response=args.turn_response)
    result = run(spec, args.controller, args.seed, args.video, args.plot, args.time_limit,
                 args.keep_going, args.start_offset, math.radians(args.start_yaw), limits,
                 factory, args.odometry, params)
    print(f"{result['track']} / {result['controller']}: "
          f"{'completed' if result['completed'] else 'ended: ' + result['ended']}, "
          f"progress {result['progress']:.0%}, {result['distance_m']:.2f} m in "
          f"{result['time_s']:.1f} s ({result['mean_speed_mps']:.3f} m/s), RMS offset "
          f"{result['rms_offset_m'] * 100:.1f} cm, max {result['max_offset_m'] * 100:.1f} cm, "
          f"departures {result['departures']}")
    if result['estimate']:
        print(describe_estimate(result['estimate']))
    write_json(args.json, result)
    return 0 if result['completed'] else 1


def write_json(path, data):
    if path:
        with open(path, 'w', encoding='utf-8') as f:
            json.dump(data, f, indent=1)


if __name__ == '__main__':
    sys.exit(main())
