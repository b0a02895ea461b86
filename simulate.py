#!/usr/bin/env python3
"""Drive a simulated Kobuki round a taped track with kobuki_lane's real loop.

The simulator is the loop's frame source: each read renders the onboard camera view (the
lecture's camera matrix and distortion, the track's mounting) from the robot's pose, after
moving the robot up to the current simulated time with the Twists the loop published, which
reach it through the headless rospy stand-in. One frame per loop iteration at 4 Hz, as on the
robot; nothing sleeps, and a run is deterministic for a given seed.

The base is Kobuki-like: unicycle kinematics, |linear.x| <= 0.7 m/s, |angular.z| <= pi rad/s,
an optional acceleration limit, commands reaching the wheels --latency seconds after they are
published, and the driver's timeout: no command for 0.6 s and the base stops.

usage:
    python simulate.py --track lecture --controller improved --json out.json --plot out.png
    python simulate.py --track my_track.yaml --controller lecture --video run.avi
    python simulate.py --benchmark                     every built-in track x both controllers
    python simulate.py --list-tracks

A run ends when the robot completes the track, departs the lane (its centre more than half a
lane width from the centre line; --continue drives on), stalls (no progress for 30 s), or
reaches --time-limit. Built-in tracks: lecture (A straight, B left, C right), oval, s_bend,
tight. Track files: see tracks.py.
"""

import argparse
import json
import math
import sys
from dataclasses import dataclass

import cv2
import numpy as np

from calibration import LECTURE_CAMERA
from floor_camera import FloorCamera, FloorMap, Track
from kobuki_lane import LaneFollower, LaneParams, LectureRule, VideoSink
from lane_control import ImprovedController, ImprovedParams
from rospy_standin import SimClock, StandInRospy, Twist
from settings import output_problem
from tracks import BUILTIN, TrackError, load_track

STALL_TIME = 30.0  # [s] without 5 cm of progress ends a run


@dataclass
class BaseLimits:
    v_max: float = 0.7  # [m/s] Kobuki's top speed
    omega_max: float = math.pi  # [rad/s] Kobuki's top turn rate
    accel: float = 0.0  # [m/s^2] linear acceleration limit, 0 for none
    alpha: float = 0.0  # [rad/s^2] angular acceleration limit, 0 for none
    timeout: float = 0.6  # [s] kobuki driver: no command for this long and the base stops
    latency: float = 0.05  # [s] from publish to the wheels


def _approach(value, target, rate_limit, dt):
    if rate_limit <= 0:
        return target
    step = rate_limit * dt
    return value + float(np.clip(target - value, -step, step))


class DiffDriveBase:
    """A differential-drive base integrated exactly along arcs in `dt` steps."""

    def __init__(self, pose, limits=None, dt=0.01, t0=0.0):
        self.x, self.y, self.yaw = pose
        self.limits = limits or BaseLimits()
        self.dt = dt
        self.t = t0
        self.v = self.omega = 0.0
        self.distance = 0.0
        self._pending = []  # (time it reaches the wheels, v, omega)
        self._cmd = (0.0, 0.0)
        self._cmd_time = -math.inf

    @property
    def pose(self):
        return (self.x, self.y, self.yaw)

    def command(self, t, v, omega):
        """A Twist published at time t."""
        self._pending.append((t + self.limits.latency, float(v), float(omega)))

    def advance(self, t_end):
        """Drive until t_end."""
        lim = self.limits
        while self.t < t_end - 1e-12:
            dt = min(self.dt, t_end - self.t)
            while self._pending and self._pending[0][0] <= self.t + 1e-12:
                self._cmd_time, *cmd = self._pending.pop(0)
                self._cmd = tuple(cmd)
            v_cmd, w_cmd = self._cmd if self.t - self._cmd_time <= lim.timeout else (0.0, 0.0)
            v_cmd = float(np.clip(v_cmd, -lim.v_max, lim.v_max))
            w_cmd = float(np.clip(w_cmd, -lim.omega_max, lim.omega_max))
            self.v = _approach(self.v, v_cmd, lim.accel, dt)
            self.omega = _approach(self.omega, w_cmd, lim.alpha, dt)
            self._move(self.v, self.omega, dt)
            self.t += dt

    def _move(self, v, omega, dt):
        if abs(omega) < 1e-9:
            self.x += v * dt * math.cos(self.yaw)
            self.y += v * dt * math.sin(self.yaw)
        else:
            r, yaw2 = v / omega, self.yaw + omega * dt
            self.x += r * (math.sin(yaw2) - math.sin(self.yaw))
            self.y -= r * (math.cos(yaw2) - math.cos(self.yaw))
            self.yaw = yaw2
        self.distance += abs(v) * dt


class TrackSimulator:
    """A frame source that is a robot on a track; it hears the node's Twists via `ros`."""

    live = False
    skipped = 0
    total = None

    def __init__(self, spec, ros, seed=0, time_limit=None, keep_going=False, start_offset=0.0,
                 start_yaw=0.0, limits=None):
        self.spec, self.ros = spec, ros
        track = spec.track
        # open tracks go on straight beyond the finish so the camera still sees tape there
        shown = track if spec.closed else Track(track.lane_width, track.tape_width,
                                                 track.segments + [{'straight': 3.5}])
        self.floor_map = FloorMap(shown, spec.gaps, spec.dashes)
        self.camera = FloorCamera(LECTURE_CAMERA, spec.mounting)
        ros.listeners.append(lambda t, topic, msg: self.base.command(t, msg.linear.x,
                                                                    msg.angular.z))
        self.rng = np.random.default_rng(seed)
        self.seed = seed
        self.keep_going = keep_going
        self._start = (start_offset, start_yaw, limits, time_limit)
        self.frames = 0
        self.restart(0.0)

    def restart(self, t0):
        """Put the robot back at the start at time t0, for a new run on the same track."""
        offset, yaw, limits, time_limit = self._start
        track = self.spec.track
        self.base = DiffDriveBase(track.pose_at(0.0, offset, yaw), limits, t0=t0)
        self.time_limit = t0 + (time_limit or (track.length / 0.04 + 30.0))
        self.history = []  # (t, x, y, s, offset)
        self.departure_points = []
        self.ended = None
        self._idx = 0
        self._departed = False
        self._best = (0.0, t0)  # (progress s, time reached)

    def where(self):
        """Arc length along the centre line and signed offset (+ left) of the robot."""
        c = self.spec.track.centre
        lo, hi = max(0, self._idx - 60), min(len(c), self._idx + 400)
        d = np.hypot(c[lo:hi, 0] - self.base.x, c[lo:hi, 1] - self.base.y)
        self._idx = lo + int(np.argmin(d))
        cx, cy, heading, s = c[self._idx]
        offset = -(self.base.x - cx) * math.sin(heading) + (self.base.y - cy) * math.cos(heading)
        return s, offset

    def _check(self, t):
        s, offset = self.where()
        self.history.append((t, self.base.x, self.base.y, s, offset))
        out = abs(offset) > self.spec.track.lane_width / 2
        if out and not self._departed:
            self.departure_points.append((self.base.x, self.base.y))
        self._departed = out
        if s > self._best[0] + 0.05:
            self._best = (s, t)
        if s >= self.spec.track.length - 0.02:
            return 'completed'
        if out and not self.keep_going:
            return 'departure'
        if t >= self.time_limit:
            return 'time limit'
        if t - self._best[1] > STALL_TIME:
            return 'stalled'
        return None

    def read(self):
        t = self.ros.clock.now()
        self.base.advance(t)
        self.ended = self.ended or self._check(t)
        if self.ended:
            return False, None, None
        frame = self.camera.render(self.floor_map, self.base.pose, self.spec.scene, self.rng)
        self.frames += 1
        return True, frame, self.frames - 1

    def release(self):
        pass

    def metrics(self, controller):
        h = np.array(self.history) if self.history else np.zeros((1, 5))
        t = float(h[-1, 0])
        length = self.spec.track.length
        offsets = h[:, 4]
        return dict(track=self.spec.name, controller=controller,
                    completed=self.ended == 'completed',
                    progress=round(min(1.0, float(h[:, 3].max()) / length), 4),
                    distance_m=round(self.base.distance, 3), time_s=round(t, 2),
                    mean_speed_mps=round(self.base.distance / t, 4) if t > 0 else 0.0,
                    rms_offset_m=round(float(np.sqrt(np.mean(offsets ** 2))), 4),
                    max_offset_m=round(float(np.abs(offsets).max()), 4),
                    departures=len(self.departure_points), ended=self.ended,
                    frames=self.frames, seed=self.seed, track_length_m=round(length, 3))


# ---------------------------------------------------------------- pictures

class TopDown:
    """The track from above, in pixels; the driven path coloured by offset."""

    def __init__(self, sim, size=480):
        self.sim = sim
        left, right = sim.spec.track.tape_lines()
        pts = np.vstack([left, right])
        lo, hi = pts.min(axis=0) - 0.4, pts.max(axis=0) + 0.4
        self.scale = size / float(max(hi - lo))
        self.lo = lo
        self.shape = (int((hi[1] - lo[1]) * self.scale) + 1, int((hi[0] - lo[0]) * self.scale) + 1)
        self.background = np.full(self.shape + (3,), 40, np.uint8)
        for line in (left, right):
            cv2.polylines(self.background, [self.px(line)], False, (200, 200, 200), 2,
                          cv2.LINE_AA)

    def px(self, xy):
        xy = np.asarray(xy, float).reshape(-1, 2)
        u = (xy[:, 0] - self.lo[0]) * self.scale
        v = self.shape[0] - 1 - (xy[:, 1] - self.lo[1]) * self.scale
        return np.stack([u, v], axis=1).round().astype(np.int32).reshape(-1, 1, 2)

    def draw(self, title=None):
        img = self.background.copy()
        h = np.array(self.sim.history) if self.sim.history else None
        half = self.sim.spec.track.lane_width / 2
        if h is not None and len(h) > 1:
            pts = self.px(h[:, 1:3])
            level = np.clip(np.abs(h[:, 4]) / half * 255, 0, 255).astype(np.uint8)
            colours = cv2.applyColorMap(level.reshape(-1, 1), cv2.COLORMAP_JET).reshape(-1, 3)
            for i in range(len(pts) - 1):
                cv2.line(img, tuple(pts[i, 0]), tuple(pts[i + 1, 0]),
                         tuple(int(c) for c in colours[i]), 2, cv2.LINE_AA)
        for x, y in self.sim.departure_points:
            u, v = self.px([x, y])[0, 0]
            cv2.drawMarker(img, (int(u), int(v)), (0, 0, 255), cv2.MARKER_TILTED_CROSS, 14, 2)
        base = self.sim.base
        nose = [base.x + 0.15 * math.cos(base.yaw), base.y + 0.15 * math.sin(base.yaw)]
        cv2.arrowedLine(img, tuple(self.px([base.x, base.y])[0, 0]), tuple(self.px(nose)[0, 0]),
                        (255, 255, 255), 2, tipLength=0.4)
        if title:
            for i, text in enumerate(title.split('\n')):
                cv2.putText(img, text, (6, 16 + 16 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.42,
                            (255, 255, 255), 1, cv2.LINE_AA)
        cv2.putText(img, 'path colour: |offset| 0 (blue) .. half a lane (red); x: departure',
                    (6, img.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.36, (220, 220, 220), 1,
                    cv2.LINE_AA)
        return img


class SideBySide(VideoSink):
    """Annotated onboard view beside the top-down view, for --video."""

    def __init__(self, path, fps, topdown):
        super().__init__(path, fps)
        self.topdown = topdown

    def write(self, image):
        top = self.topdown.draw()
        h = image.shape[0]
        top = cv2.resize(top, (int(top.shape[1] * h / top.shape[0]), h))
        super().write(np.hstack([image, top]))


# ---------------------------------------------------------------- runs

def make_controller(name, spec, params):
    if name == 'lecture':
        return LectureRule(params)
    m = spec.mounting
    return ImprovedController(params, ImprovedParams(
        camera_height=m.height, camera_pitch=m.pitch_deg, camera_forward=m.forward,
        lane_width=spec.track.lane_width))


def run(spec, controller='lecture', seed=0, video=None, plot=None, time_limit=None,
        keep_going=False, start_offset=0.0, start_yaw=0.0, limits=None):
    """One closed-loop run; returns the metrics dict."""
    ros = StandInRospy(SimClock(), quiet=True)
    sim = TrackSimulator(spec, ros, seed, time_limit, keep_going, start_offset, start_yaw,
                         limits)
    params = LaneParams()
    topdown = TopDown(sim) if (video or plot) else None
    sink = SideBySide(video, params.rate, topdown) if video else None
    follower = LaneFollower(ros, Twist, sim, params, LECTURE_CAMERA,
                            controller=make_controller(controller, spec, params), video=sink)
    try:
        follower.run()
    finally:
        if sink:
            sink.close()
    result = sim.metrics(controller)
    result['decisions'] = follower.counts
    if plot:
        outcome = 'completed' if result['completed'] else 'ended: ' + result['ended']
        title = (f"{spec.name} / {controller}: {outcome}"
                 f"\nprogress {result['progress']:.0%}  rms {result['rms_offset_m'] * 100:.1f} cm  "
                 f"max {result['max_offset_m'] * 100:.1f} cm  {result['mean_speed_mps']:.2f} m/s  "
                 f"departures {result['departures']}")
        cv2.imwrite(plot, topdown.draw(title))
    return result


# ---------------------------------------------------------------- command line

VARIANTS = {  # the robustness conditions of the benchmark
    'clean': {},
    'noise 10': dict(noise=10.0),
    'lighting gradient': dict(gradient=80.0),
    'gap 20 cm': dict(gap=0.2),
}


def apply_variant(spec, variant):
    """The track with a benchmark condition: noise, a lighting gradient, or a gap."""
    cond = VARIANTS[variant]
    if 'noise' in cond:
        spec.scene.noise = cond['noise']
    if 'gradient' in cond:
        spec.scene.gradient = cond['gradient']
    if 'gap' in cond:
        # 40 % of the way along every built-in track is in a left bend, where the right (outer)
        # tape is the only one in view: the gap takes away all the camera sees
        spec.gaps = spec.gaps + [dict(line='right', at=0.4 * spec.track.length,
                                      length=cond['gap'])]
    return spec


def _bench_job(job):
    track, controller, variant, seed = job
    result = run(apply_variant(load_track(track), variant), controller, seed=seed)
    result['variant'] = variant
    return result


def benchmark(jobs=2, seed=0, stream=None):
    """Every built-in track x both controllers, and the improved one under each condition."""
    work = [(t, c, 'clean', seed) for t in BUILTIN for c in ('lecture', 'improved')]
    work += [(t, 'improved', v, seed) for v in VARIANTS if v != 'clean' for t in BUILTIN]
    if jobs > 1:
        from multiprocessing import Pool

        with Pool(jobs) as pool:
            results = pool.map(_bench_job, work)
    else:
        results = [_bench_job(job) for job in work]
    (stream or sys.stdout).write(benchmark_table(results))
    return results


def benchmark_table(results):
    rows = ['| track | controller | condition | completed | progress | RMS offset | max offset '
            '| mean speed | departures | ended |',
            '|---|---|---|---|---|---|---|---|---|---|']
    for r in results:
        rows.append(f"| {r['track']} | {r['controller']} | {r['variant']} | "
                    f"{'yes' if r['completed'] else 'no'} | {r['progress']:.0%} | "
                    f"{r['rms_offset_m'] * 100:.1f} cm | {r['max_offset_m'] * 100:.1f} cm | "
                    f"{r['mean_speed_mps']:.3f} m/s | {r['departures']} | {r['ended']} |")
    return '\n'.join(rows) + '\n'


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
    parser.add_argument('--controller', choices=('lecture', 'improved'), default='lecture',
                        help="the lecture's rule (default) or the improved controller")
    parser.add_argument('--seed', type=int, default=0, help='frame noise seed (default 0)')
    parser.add_argument('--json', metavar='FILE', help='write the run metrics as JSON')
    parser.add_argument('--plot', metavar='FILE', help='write the top-down view as PNG')
    parser.add_argument('--video', metavar='FILE',
                        help='write onboard (annotated) beside top-down view, .avi or .mp4')
    parser.add_argument('--time-limit', type=float, metavar='S',
                        help='end the run here (default: track length / 0.04 m/s + 30 s)')
    parser.add_argument('--continue', dest='keep_going', action='store_true',
                        help='drive on after a departure instead of ending the run')
    scene = parser.add_argument_group('scene and robot (override the track file)')
    scene.add_argument('--noise', type=float, help='frame noise sigma [grey levels]')
    scene.add_argument('--gradient', type=float, help='lighting gradient [grey levels]')
    scene.add_argument('--glare', type=float, help='glare patch brightness [grey levels]')
    scene.add_argument('--gap', type=tape_option('at', 'length', 'left:2.0:0.2'),
                       action='append', default=[],
                       metavar='LINE:AT:LENGTH', help='tape missing, e.g. left:2.0:0.2 [m]')
    scene.add_argument('--dashes', type=tape_option('on', 'off', 'both:0.1:0.1'),
                       metavar='LINE:ON:OFF',
                       help='dashed tape, e.g. both:0.1:0.1 [m]')
    scene.add_argument('--camera-height', type=float, help='[m]')
    scene.add_argument('--camera-pitch', type=float, help='down from horizontal [deg]')
    scene.add_argument('--start-offset', type=float, default=0.0, help='[m], + left')
    scene.add_argument('--start-yaw', type=float, default=0.0, help='[deg], + left')
    scene.add_argument('--accel', type=float, default=0.0,
                       help='base acceleration limit [m/s^2], 0 for none')
    scene.add_argument('--latency', type=float, default=0.05,
                       help='publish to wheels [s] (default 0.05)')
    bench = parser.add_argument_group('benchmark')
    bench.add_argument('--benchmark', action='store_true',
                       help='run every built-in track x {lecture, improved}, and the improved '
                            'controller with noise 10, a lighting gradient and a 20 cm gap; '
                            'print a Markdown table (--json writes all results)')
    bench.add_argument('--jobs', type=int, default=2, help='parallel runs (default 2)')
    parser.add_argument('--list-tracks', action='store_true', help='list the built-in tracks')
    return parser


def fail(message):
    print(f'simulate.py: error: {message}', file=sys.stderr)
    raise SystemExit(2)


def check_outputs(args):
    for path in (args.json, args.plot, args.video):
        problem = path and output_problem(path)
        if problem:
            fail(f"cannot write '{path}': {problem}")


def customise(spec, args):
    for key in ('noise', 'gradient', 'glare'):
        if getattr(args, key) is not None:
            setattr(spec.scene, key, getattr(args, key))
    for gap in args.gap:
        if gap['line'] not in ('left', 'right', 'both') or gap['length'] <= 0:
            fail(f'--gap {gap}: line must be left, right or both, length positive')
    spec.gaps = spec.gaps + args.gap
    if args.dashes:
        d = args.dashes
        if d['line'] not in ('left', 'right', 'both') or d['on'] <= 0 or d['off'] <= 0:
            fail(f'--dashes {d}: line must be left, right or both, on and off positive')
        spec.dashes = d
    if args.camera_height is not None:
        spec.mounting.height = args.camera_height
    if args.camera_pitch is not None:
        spec.mounting.pitch_deg = args.camera_pitch
    return spec


def main(argv=None):
    args = build_parser().parse_args(argv)
    check_outputs(args)
    if args.list_tracks:
        for name in BUILTIN:
            spec = load_track(name)
            print(f'{name}: {spec.track.length:.2f} m, {len(spec.track.segments)} segments'
                  f"{', closed' if spec.closed else ''}")
        return 0
    if args.benchmark:
        results = benchmark(max(1, args.jobs), args.seed)
        if args.json:
            with open(args.json, 'w', encoding='utf-8') as f:
                json.dump(results, f, indent=1)
        return 0
    try:
        spec = customise(load_track(args.track), args)
    except TrackError as e:
        fail(str(e))
    limits = BaseLimits(accel=args.accel, alpha=args.accel * 4, latency=args.latency)
    result = run(spec, args.controller, args.seed, args.video, args.plot, args.time_limit,
                 args.keep_going, args.start_offset, math.radians(args.start_yaw), limits)
    print(f"{result['track']} / {result['controller']}: "
          f"{'completed' if result['completed'] else 'ended: ' + result['ended']}, "
          f"progress {result['progress']:.0%}, {result['distance_m']:.2f} m in "
          f"{result['time_s']:.1f} s ({result['mean_speed_mps']:.3f} m/s), RMS offset "
          f"{result['rms_offset_m'] * 100:.1f} cm, max {result['max_offset_m'] * 100:.1f} cm, "
          f"departures {result['departures']}")
    if args.json:
        with open(args.json, 'w', encoding='utf-8') as f:
            json.dump(result, f, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
