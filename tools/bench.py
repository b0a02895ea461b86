#!/usr/bin/env python3
"""Benchmark kobuki_lane's pipeline against the lecture's literal code and the OpenCV floor.

One run, on the same 640x480 frames (samples/track and frames rendered by the simulator on
every built-in track, with offsets, noise, a lighting gradient and gaps), prints:

  pipeline    per-stage and whole-frame median and p95 milliseconds and frames per second for
              literal  the slides' calls transcribed one by one (LITERAL below): cv2.undistort
                       on every frame, the unused gray in calibration_camera, the mask made
                       afresh, every row of the frame
              project  lanelib.fast.FastPipeline, the node's default (segments identical
                       to kobuki_lane.detect(); see tests/test_pipeline.py)
              floor    only the OpenCV calls no pipeline can avoid, each on its smallest input:
                       remap and gray on the triangle's pixels, blur, Canny and the mask on the
                       rectangles that hold its rows, HoughLinesP on the full-size image the
                       lecture's call gets
              and the ratios project/literal and project/floor; and the whole frame for
              slides   kobuki_lane.detect(), the slides' calls as the node shows them
                       (--pipeline slides). One OpenCV thread, as on one core.
  latency     frame read -> Twist published, in LaneFollower's real loop (the stand-in rospy)
  throughput  whole-process dry runs (python kobuki_lane.py --dry-run) over a video of
              --video-frames frames, with the project's pipeline and with the literal one
  memory      in a fresh process running the node's dry-run loop over the samples, looped:
              RSS after 1,000 and after --soak frames, and the peak
  improved    the improved controller (perception, lane fit, steering) per stage, each frame
              read afresh, interleaved with the literal code on the same frames; and driving:
              every frame of simulate.py's closed-loop runs of the lane tracks (the lecture's
              world) in turn, as a running node reads them, with the lane from the frames
              before (the prior's refit, the memory, the bend), which costs more than a fresh
              frame (--quick: the lecture track only); and the same with the settings
              --robot duckiebot gives, on the duckietown world's S-bends (--quick: s_bend),
              and those again with the base's odometry followed and --pitch-from motion;
              the driving rows against AIM_MS (their slowest median and largest p95), and
              each as a multiple of the literal code's frame timed beside the improved one:
              it moves less with the machine's hour than the milliseconds do (1.6 to 2.0
              over five runs on 2026-12-06, docs/benchmarks.md)
  worst case  cluttered frames (dense texture, many edges; plain floor with up to 1,600
              lines): the lecture's Hough stage, the improved controller's whole frame

usage (from the repository root):
    python -m tools.bench                      everything (about 3 minutes on 2 cores)
    python -m tools.bench --quick              fewer frames, no throughput or memory runs
    python -m tools.bench --json out/bench.json
    python -m tools.bench --quick --lane duckietown   the improved perception with two colours

default values: 300 simulator frames plus the 28 samples, each timed 3 times; a 2,000-frame
video; a 10,000-frame soak.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import time
from dataclasses import replace

import cv2
import numpy as np

import kobuki_lane
from kobuki_lane import LaneFollower, LaneParams, LectureRule, detect
from lanelib.camera import LECTURE_CAMERA
from lanelib.cli import check_output
from lanelib.fast import FastPipeline, Layout
from lanelib.improved import ImprovedController, ImprovedParams
from lanelib.lanes import BUILTIN as BUILTIN_LANES
from lanelib.outputs import Outputs
from lanelib.rospy_standin import SimClock, StandInRospy, Twist
from lanelib.safety import SafeBase
from lanelib.sim.simulator import VARIANTS, apply_variant
from lanelib.sim.tracks import LANE_TRACKS, load_track, with_world
from lanelib.sim.world import WORLDS, FloorCamera, FloorMap
from lanelib.sources import ListSource
from lanelib.stages import Detection, slope_sum
from tools.common import REPO, SAMPLES, machine, rss_mb, whole_number, write_json

OUT = os.path.join('out', 'bench')
STAGES = ('undistort', 'gray', 'blur', 'canny', 'roi', 'hough', 'slopes')
IMPROVED_STAGES = ('undistort', 'colour', 'pieces', 'lane', 'steer')
# the duckiebot preset's driving: Duckietown's lane on the two S-bends (1.0 and 0.9 m radius)
PRESET_TRACKS = ('s_bend', 'tight')
AIM_MS = 10.0  # [ms] a driving frame's aim (issue 25): well within a camera's 33 ms at 30 Hz


# ---------------------------------------------------------------- the lecture, literally

def literal_calibration_camera(seeimg):
    """The slide's calibration_camera (18:57), less cv2.imshow."""
    dist = np.array([2.28504143e-01, -7.32838958e+00, -2.43747623e-02, 9.12080996e-03,
                     3.98425001e+01])
    mtx = np.array([[893.45537548, 0.0, 309.61828309],
                    [0.0, 866.99738285, 196.40832355],
                    [0.0, 0.0, 1.0]])
    gray = cv2.cvtColor(seeimg, cv2.COLOR_BGR2GRAY)  # noqa: F841 (the slide computes it too)
    dst = cv2.undistort(seeimg, mtx, dist, None, mtx)
    return dst


def literal_region_of_interest(img, vertices):
    mask = np.zeros_like(img)
    cv2.fillPoly(mask, vertices, 255)
    masked_image = cv2.bitwise_and(img, mask)
    return masked_image


def literal_lecture_pipeline(frame, algorithm='1.1', mark=lambda stage: None):
    """The slides' main loop body (21:44 to 23:14) for one frame: (segments (N, 4), theta).

    One departure, the project's fix: gray is taken from the undistorted image (the slide takes
    it from the raw frame, so its undistortion was wasted); without it the two would not see
    the same edges and no comparison of segments would mean anything.
    """
    mark('start')
    image = frame.copy()
    image = literal_calibration_camera(image)
    mark('undistort')
    gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    mark('gray')
    blurred = cv2.GaussianBlur(gray, (5, 5), 0)
    mark('blur')
    edged = cv2.Canny(blurred, 85, 85)
    mark('canny')
    height, width = frame.shape[:2]
    region_of_interest_vertices = [
        (0, height),
        (width / 2, height / 2),
        (width, height),
    ]
    if algorithm == '1.1':
        edged = literal_region_of_interest(edged, np.array([region_of_interest_vertices],
                                                           np.int32))
    mark('roi')
    lines = cv2.HoughLinesP(
        edged,
        rho=6,
        theta=np.pi / 60,
        threshold=160,
        lines=np.array([]),
        minLineLength=40,
        maxLineGap=25
    )
    mark('hough')
    theta = 0.0
    if lines is not None:
        for x in range(0, len(lines)):
            for x1, y1, x2, y2 in lines[x]:
                theta = theta + math.atan2((y2 - y1), (x2 - x1))
    mark('slopes')
    return (np.empty((0, 4), np.int32) if lines is None else lines.reshape(-1, 4)), theta


class Floor:
    """The OpenCV calls no pipeline can skip, each on the smallest input it can have: remap and
    gray on exactly the mask's pixels (remap in the faster way the pipeline found: from a BGRA
    copy of the rows and columns it reads, the copy counted), blur, Canny and the mask on the
    two rectangles that hold the mask's rows (Layout._pieces, less their margins), HoughLinesP
    on the full-size image the lecture's call gets. With no mask (algorithm 1.0) every call
    takes the whole frame."""

    def __init__(self, p, width=640, height=480):
        self.p = p
        self.lay = Layout(width, height, LECTURE_CAMERA, p)
        m1, m2 = self.lay.maps
        # blur and Canny: the rectangles the pipeline splits the mask's rows into, without the
        # margins round them that make its edges right (with no mask: the whole frame)
        self.rects = [rows for rows, _, _ in self.lay.pieces]
        if self.lay.mask is None:
            self.top, self.bottom = 0, height
            self.maps = m1, m2
        else:
            self.top, self.bottom = self.lay.top, self.lay.bottom
            keep = np.flatnonzero(self.lay.mask.ravel() > 0)
            keep = np.resize(keep, -(-keep.size // width) * width)  # whole rows of the mask's
            self.maps = (m1.reshape(-1, 2)[keep].reshape(-1, width, 2),  # pixels, packed
                         m2.reshape(-1)[keep].reshape(-1, width))

    def __call__(self, raw, mark=lambda stage: None):
        p, lay, top, bottom = self.p, self.lay, self.top, self.bottom
        # the content blur and Canny see, made outside the timed calls
        band = cv2.cvtColor(cv2.remap(raw, lay.maps[0][top:bottom], lay.maps[1][top:bottom],
                                      cv2.INTER_LINEAR), cv2.COLOR_BGR2GRAY)
        mark('start')
        y0, y1, x0, x1 = lay.source
        cv2.cvtColor(raw[y0:y1, x0:x1], cv2.COLOR_BGR2BGRA, dst=lay.bgra[y0:y1, x0:x1])
        pixels = cv2.remap(lay.bgra, *self.maps, cv2.INTER_LINEAR)
        mark('undistort')
        cv2.cvtColor(pixels, cv2.COLOR_BGRA2GRAY)
        mark('gray')
        rects = self.rects
        blurred = [cv2.GaussianBlur(band[a - top:b - top, c0:c1], (p.blur_kernel, p.blur_kernel),
                                    0) for a, b, c0, c1 in rects]
        mark('blur')
        edged = [cv2.Canny(image, p.canny_low, p.canny_high) for image in blurred]
        mark('canny')
        if lay.mask is not None:
            for e, (a, b, c0, c1) in zip(edged, rects):
                cv2.bitwise_and(e, lay.mask[a:b, c0:c1], dst=lay.edges[a:b, c0:c1])
            edged = [lay.edges]
        mark('roi')
        cv2.HoughLinesP(edged[0], rho=p.hough_rho, theta=p.hough_theta,
                        threshold=int(p.hough_threshold), minLineLength=p.min_line_length,
                        maxLineGap=p.max_line_gap)
        mark('hough')
        mark('slopes')


# ---------------------------------------------------------------- frames

def simulator_frames(count, seed=0):
    """`count` onboard views from every built-in track and benchmark condition, at random
    places along the track with offsets up to 6 cm and heading errors up to 8 degrees."""
    rng = np.random.default_rng(seed)
    specs = [apply_variant(load_track(name), variant) for name in LANE_TRACKS
             for variant in VARIANTS]
    views = []
    for spec in specs:
        views.append((spec, FloorMap(spec.track, spec.gaps, spec.dashes),
                      FloorCamera(LECTURE_CAMERA, spec.mounting)))
    frames = []
    for i in range(count):
        spec, floor_map, camera = views[i % len(views)]
        s = rng.uniform(0.0, spec.track.length * 0.95)
        pose = spec.track.pose_at(s, rng.uniform(-0.06, 0.06), math.radians(rng.uniform(-8, 8)))
        frames.append(camera.render(floor_map, pose, spec.scene, rng))
    return frames


def sample_frames():
    names = sorted(f for f in os.listdir(SAMPLES) if f.endswith('.jpg'))
    return [cv2.imread(os.path.join(SAMPLES, f)) for f in names]


def cluttered_frame(seed=0, size=(480, 640), lines=300, texture=True):
    """Dense texture and many edges: a worst case for Canny and Hough."""
    rng = np.random.default_rng(seed)
    if texture:
        small = rng.integers(0, 256, (size[0] // 4, size[1] // 4, 3), dtype=np.uint8)
        frame = cv2.resize(small, (size[1], size[0]), interpolation=cv2.INTER_NEAREST)
    else:
        frame = np.full((size[0], size[1], 3), 95, np.uint8)
    for _ in range(lines):
        x1, x2 = rng.integers(0, size[1], 2)
        y1, y2 = rng.integers(0, size[0], 2)
        cv2.line(frame, (int(x1), int(y1)), (int(x2), int(y2)),
                 tuple(int(c) for c in rng.integers(0, 256, 3)), 2)
    return frame


# ---------------------------------------------------------------- timing

class StageClock:
    """mark(stage) adds the time since the previous mark to that stage's time for the frame
    (a stage may be marked more than once per frame, once per piece); `end` ends a frame."""

    def __init__(self, stages=STAGES, end='slopes'):
        self.stages, self.end = stages, end
        self.times = {s: [] for s in stages + ('total',)}
        self._frame = {}
        self._start = self._last = 0.0

    def mark(self, stage):
        now = time.perf_counter()
        if stage == 'start':
            self._start, self._frame = now, dict.fromkeys(self.stages, 0.0)
        else:
            self._frame[stage] += now - self._last
            if stage == self.end:
                for name, seconds in self._frame.items():
                    self.times[name].append(seconds)
                self.times['total'].append(now - self._start)
        self._last = now


def stats(seconds):
    ms = np.asarray(seconds) * 1000.0
    return dict(median_ms=round(float(np.median(ms)), 3),
                p95_ms=round(float(np.percentile(ms, 95)), 3),
                fps=round(1000.0 / float(np.median(ms)), 1))


def against_aim(rows, literal_ms, aim_ms=AIM_MS):
    """The driving rows (name: time_improved_driving's result) against the aim: their slowest
    median and largest p95 [ms], whether both are under aim_ms, and each row's median as a
    multiple of the literal code's whole frame (literal_ms, timed in the same run)."""
    medians = {name: row['total']['median_ms'] for name, row in rows.items()}
    slowest = max(medians.values())
    largest = max(row['total']['p95_ms'] for row in rows.values())
    return dict(aim_ms=aim_ms, slowest_median_ms=slowest, largest_p95_ms=largest,
                under_aim=bool(slowest < aim_ms and largest < aim_ms), literal_ms=literal_ms,
                over_literal={name: round(m / literal_ms, 2) for name, m in medians.items()})


def time_pipelines(frames, repeats, algorithm='1.1'):
    """Literal, project and floor on the same frames, interleaved so that drift and cache
    effects hit all three alike; then detect() on the same frames (its whole time per frame:
    it has no stage marks)."""
    p = LaneParams(algorithm=algorithm)
    clocks = {name: StageClock() for name in ('literal', 'project', 'floor')}
    project = FastPipeline(p, detect, mark=clocks['project'].mark)
    floor = Floor(p, *frames[0].shape[1::-1])
    runs = [lambda f: literal_lecture_pipeline(f, algorithm, clocks['literal'].mark),
            lambda f: project(f, LECTURE_CAMERA),
            lambda f: floor(f, clocks['floor'].mark)]
    for _ in range(repeats):
        for i, frame in enumerate(frames):
            for k in range(3):  # each goes first, second and third in turn
                runs[(i + k) % 3](frame)
    result = {name: {stage: stats(t) for stage, t in clock.times.items()}
              for name, clock in clocks.items()}
    slides = []
    for _ in range(repeats):
        for frame in frames:
            start = time.perf_counter()
            detect(frame, LECTURE_CAMERA, p)
            slides.append(time.perf_counter() - start)
    result['slides'] = {'total': stats(slides)}
    return result


def latency(frames):
    """Frame read -> Twist published in LaneFollower's loop, over every frame."""
    read_at, delays = [], []

    class TimedSource(ListSource):
        def read(self):
            item = super().read()
            read_at.append(time.perf_counter())
            return item

    ros = StandInRospy(SimClock(), quiet=True, keep=10)
    ros.listeners.append(lambda *_: delays.append(time.perf_counter() - read_at[-1]))
    follower = LaneFollower(ros, TimedSource(frames), LectureRule(LaneParams()),
                            SafeBase(ros, Twist))
    follower.run()
    return stats(delays[:-1])  # the last is the stop sent after the input ended


def make_video(frames, count, path):
    if os.path.exists(path) and cv2.VideoCapture(path).get(cv2.CAP_PROP_FRAME_COUNT) >= count:
        return path
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*'MJPG'), 30, (w, h))
    for i in range(count):
        writer.write(frames[i % len(frames)])
    writer.release()
    return path


def throughput(video, count):
    """Whole-process dry runs over the video: the project's pipeline, then the literal one."""
    result = {}
    for name, cmd in (('project', ['kobuki_lane.py']),
                      ('literal', ['-m', 'tools.bench', '--literal-dry-run'])):
        argv = [sys.executable] + cmd + ['--source', os.path.abspath(video), '--dry-run',
                                         '--quiet', '--progress', 'off']
        start = time.perf_counter()
        subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                       cwd=REPO)
        elapsed = time.perf_counter() - start
        result[name] = dict(frames=count, seconds=round(elapsed, 2),
                            fps=round(count / elapsed, 1))
    return result


def memory_child(count):
    """In a fresh process: the node's dry-run loop over the samples, looped to `count` frames,
    with decisions written; prints RSS after 1,000 frames, at the end, and the peak (JSON)."""
    frames, marks = sample_frames(), {}

    class Looped(ListSource):
        def read(self):
            if self._next >= count:
                return False, None, None
            self._next += 1
            if self._next in (1000, count):
                marks[self._next] = rss_mb()
            return True, frames[(self._next - 1) % len(frames)], self._next - 1

    ros = StandInRospy(SimClock(), quiet=True, keep=100)
    os.makedirs(OUT, exist_ok=True)
    p = LaneParams()
    with open(os.path.join(OUT, 'soak_decisions.jsonl'), 'w') as decisions:
        LaneFollower(ros, Looped([]), LectureRule(p), SafeBase(ros, Twist),
                     Outputs(p, decisions=decisions)).run()
    peak = rss_mb('VmHWM')  # ru_maxrss would carry the parent's peak over exec
    print(json.dumps(dict(frames=count, rss_1000_mb=round(marks[1000], 1),
                          rss_end_mb=round(marks[count], 1),
                          growth_mb=round(marks[count] - marks[1000], 2),
                          peak_rss_mb=round(peak, 1))))
    return 0


def memory(count):
    out = subprocess.run([sys.executable, '-m', 'tools.bench', '--memory-child', str(count)],
                         check=True, capture_output=True, text=True, cwd=REPO).stdout
    return json.loads(out.strip().splitlines()[-1])


def improved_controller(mark, lane='lecture'):
    """The improved controller (lane profile `lane`), its stages timed by `mark`, and a
    function that reads one frame afresh (the lane searched for in full, as on the first
    frame) and steers."""
    c = ImprovedController(LaneParams(), ImprovedParams(lane=lane), camera=LECTURE_CAMERA,
                           mark=mark)

    def read(frame):
        c.reset()
        c(c.perceive(frame))
        return c
    return read


def time_improved(frames, repeats, lane='lecture'):
    """The improved controller (lane profile `lane`) against the literal code on the same
    frames, interleaved: per stage and whole frame (perception, the lane's fit and the
    steering)."""
    clocks = dict(literal=StageClock(), improved=StageClock(IMPROVED_STAGES, 'steer'))
    improved = improved_controller(clocks['improved'].mark, lane)
    runs = [lambda f: literal_lecture_pipeline(f, '1.1', clocks['literal'].mark), improved]
    for _ in range(repeats):
        for i, frame in enumerate(frames):
            for k in range(2):
                runs[(i + k) % 2](frame)
    result = {name: {stage: stats(t) for stage, t in clock.times.items()}
              for name, clock in clocks.items()}
    times = clocks['improved'].times
    result['improved']['perception'] = stats(np.add(np.add(times['undistort'], times['colour']),
                                                    times['pieces']))
    literal = result['literal']['total']['median_ms']
    result['perception_over_literal'] = round(
        result['improved']['perception']['median_ms'] / literal, 3)
    result['improved_over_literal'] = round(result['improved']['total']['median_ms'] / literal,
                                            3)
    return result


def time_improved_driving(tracks, seed=0, robot=None, world=None, odometry=False, **settings):
    """The improved controller per stage as a running node uses it: every frame of
    simulate.py's closed-loop run of each track (the lecture's world, clean, or `world`), in
    turn, with the lane from the frames before; with `robot`, the preset's settings and rate
    (simulate.robot_settings: what `simulate.py --robot ROBOT` drives with) instead of the
    simulator's defaults, and `settings` (the preset's, changed); with `odometry`, the
    base's odometry followed (simulate.py --odometry)."""
    import simulate

    clock = StageClock(IMPROVED_STAGES, 'steer')
    results = []
    for track in tracks:
        spec = load_track(track)
        if world:
            spec = with_world(spec, WORLDS[world])
        params, improved = simulate.robot_settings(robot, spec) if robot else (None, None)
        if settings:
            improved = replace(improved, **settings)
        make = simulate.preset_factory(improved) if robot else simulate.controller_for

        def timed(name, spec, params, make=make, **kwargs):
            controller = make(name, spec, params, **kwargs)
            controller.mark = clock.mark
            return controller
        results.append(simulate.run(spec, 'improved', seed=seed, controller_factory=timed,
                                    params=params, odometry=odometry))
    result = {stage: stats(t) for stage, t in clock.times.items()}
    result.update(tracks=list(tracks), frames=len(clock.times['total']),
                  completed=[r['completed'] for r in results])
    return result


def worst_case(repeats=20):
    """Cluttered frames: the lecture's Hough stage and whole pipeline (never bounded), and the
    improved controller's whole frame, on dense texture with 300 lines, and on plain floor
    with ever more lines (the most pieces of line to sort)."""
    def timed(make, frame):
        clock = StageClock(*make[1])
        read = make[0](clock.mark)
        for _ in range(repeats):
            out = read(frame)
        if isinstance(out, ImprovedController):
            return dict(total=stats(clock.times['total']),
                        pieces=len(out.perceive(frame).pieces), cluttered=out.cluttered)
        return dict(hough=stats(clock.times['hough']), total=stats(clock.times['total']),
                    segments=int(len(out.lines)))

    def lecture(mark):
        pipeline = FastPipeline(LaneParams(), detect, mark=mark)
        return lambda frame: pipeline(frame, LECTURE_CAMERA)

    lecture = (lecture, (STAGES, 'slopes'))
    improved = (improved_controller, (IMPROVED_STAGES, 'steer'))
    frame = cluttered_frame()
    out = dict(lecture=timed(lecture, frame), improved=timed(improved, frame))
    lines = [timed(improved, cluttered_frame(n, lines=n, texture=False))
             for n in (100, 200, 400, 800, 1600)]
    out['improved_most_lines'] = max(lines, key=lambda t: t['total']['median_ms'])
    return out


# ---------------------------------------------------------------- report

def stage_table(result):
    """The improved controller's stages and whole frame, median / p95 ms, as a table."""
    return '\n'.join(['| stage | median / p95 ms |', '|---|---|'] + [
        f"| {stage} | {result[stage]['median_ms']:.3f} / {result[stage]['p95_ms']:.3f} |"
        for stage in IMPROVED_STAGES + ('total',)])


def table(results):
    rows = ['| stage | literal median / p95 ms | project median / p95 ms | '
            'floor median / p95 ms |', '|---|---|---|---|']
    for stage in STAGES + ('total',):
        cells = [f"{results[n][stage]['median_ms']:.3f} / {results[n][stage]['p95_ms']:.3f}"
                 for n in ('literal', 'project', 'floor')]
        rows.append(f'| {stage} | ' + ' | '.join(cells) + ' |')
    return '\n'.join(rows)


def literal_dry_run(argv):
    """kobuki_lane.py's own main(), with the lecture's literal calls as the pipeline."""
    def literal(p):
        def pipeline(frame, camera, keep_stages=False):
            lines, _ = literal_lecture_pipeline(frame, p.algorithm)
            return Detection(lines, slope_sum(lines, p.slope_min))
        return pipeline

    def controller(name, params, camera, improved, pipeline, odometry=None):
        return LectureRule(params, camera, literal(params))

    return kobuki_lane.main(argv, make_controller=controller)


def build_parser():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--sim-frames', type=whole_number(0), default=300,
                        help='simulator frames besides the 28 samples (default: 300)')
    parser.add_argument('--repeats', type=whole_number(1), default=3,
                        help='times each frame is timed, at least 1 (default: 3)')
    parser.add_argument('--video-frames', type=whole_number(1), default=2000,
                        help='length of the throughput video (default: 2000)')
    parser.add_argument('--soak', type=whole_number(1000, why=' (RSS is compared with frame '
                                                              '1,000)'), default=10000,
                        help='frames of the memory run, at least 1,000 (default: 10000)')
    parser.add_argument('--quick', action='store_true',
                        help='60 simulator frames, 1 repeat, no throughput or memory runs')
    parser.add_argument('--json', metavar='FILE', help='write every figure as JSON')
    parser.add_argument('--lane', default='lecture', choices=sorted(BUILTIN_LANES),
                        help="the improved controller's lane profile (default: lecture, which "
                        "looks in one colour mask; duckietown and autorace look in two)")
    return parser


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ['--literal-dry-run']:
        return literal_dry_run(argv[1:])
    if argv[:1] == ['--memory-child']:
        return memory_child(int(argv[1]))
    args = build_parser().parse_args(argv)
    if args.json:
        check_output('tools.bench', args.json, '--json')
    if args.quick:
        args.sim_frames, args.repeats = 60, 1
    cv2.setNumThreads(1)
    report = dict(machine=machine())
    print(f"machine: {report['machine']}")
    print(f'rendering {args.sim_frames} simulator frames ...', file=sys.stderr)
    frames = sample_frames() + simulator_frames(args.sim_frames)
    report['frames'] = len(frames)
    for algorithm in ('1.1', '1.0'):
        res = time_pipelines(frames, args.repeats, algorithm)
        tot = {n: res[n]['total']['median_ms'] for n in res}
        res['ratios'] = dict(project_over_literal=round(tot['project'] / tot['literal'], 3),
                             literal_over_project=round(tot['literal'] / tot['project'], 2),
                             project_over_floor=round(tot['project'] / tot['floor'], 3))
        report[f'pipeline_{algorithm}'] = res
        print(f'\npipeline, algorithm {algorithm}: {len(frames)} frames x {args.repeats}, '
              '640x480, one OpenCV thread')
        print(table(res))
        print(f"speed-up over literal {res['ratios']['literal_over_project']}x; "
              f"project/floor {res['ratios']['project_over_floor']}; detect() (--pipeline "
              f"slides): median {res['slides']['total']['median_ms']:.3f} ms, p95 "
              f"{res['slides']['total']['p95_ms']:.3f} ms")
    report['latency'] = latency(frames)
    print(f"\nframe read -> Twist published: median {report['latency']['median_ms']} ms, "
          f"p95 {report['latency']['p95_ms']} ms")
    report['improved'] = imp = time_improved(frames, args.repeats, args.lane)
    imp['lane'] = args.lane
    print(f'\nimproved controller (lane profile {args.lane}, each frame read afresh) against the '
          f'literal code, interleaved, {len(frames)} frames x {args.repeats}:')
    print(stage_table(imp['improved']))
    print(f"perception (undistort, colour, pieces) median "
          f"{imp['improved']['perception']['median_ms']:.3f} ms, the literal code's whole frame "
          f"{imp['literal']['total']['median_ms']:.3f} ms: perception/literal "
          f"{imp['perception_over_literal']}, whole improved frame/literal "
          f"{imp['improved_over_literal']}")
    tracks = ['lecture'] if args.quick else list(LANE_TRACKS)
    report['improved_driving'] = drive = time_improved_driving(tracks)
    print(f"\nimproved controller driving (simulate.py, {', '.join(tracks)}: {drive['frames']} "
          'frames in turn, with the lane from the frames before):')
    print(stage_table(drive))
    tracks = ['s_bend'] if args.quick else list(PRESET_TRACKS)
    report['improved_driving_duckiebot'] = drive = time_improved_driving(
        tracks, robot='duckiebot', world='duckietown')
    print(f"\nimproved controller driving with --robot duckiebot (simulate.py, the duckietown "
          f"world, {', '.join(tracks)}: {drive['frames']} frames in turn; the simulated "
          'camera\'s mounting, as --mounting gives it):')
    print(stage_table(drive))
    report['improved_driving_duckiebot_odometry'] = drive = time_improved_driving(
        tracks, robot='duckiebot', world='duckietown', odometry=True, pitch_from='motion')
    print(f"\nthe same with the base's odometry and --pitch-from motion (the pitch read from "
          f"the floor's motion, timed in 'steer'): {drive['frames']} frames:")
    print(stage_table(drive))
    report['against_aim'] = aim = against_aim(
        dict(Kobuki=report['improved_driving'], duckiebot=report['improved_driving_duckiebot'],
             odometry=report['improved_driving_duckiebot_odometry']),
        imp['literal']['total']['median_ms'])
    print(f"\ndriving, every row: the slowest median {aim['slowest_median_ms']:.3f} ms, the "
          f"largest p95 {aim['largest_p95_ms']:.3f} ms: "
          f"{'under' if aim['under_aim'] else 'NOT under'} the aim of {aim['aim_ms']:g} ms; "
          'the medians as multiples of the literal code\'s frame ('
          f"{aim['literal_ms']:.3f} ms, timed beside the improved one above): " +
          ', '.join(f'{name} {x:.2f}' for name, x in aim['over_literal'].items()))
    report['worst_case'] = worst = worst_case()
    w = worst['lecture']
    print(f"\ncluttered frame, lecture: Hough median {w['hough']['median_ms']} ms (p95 "
          f"{w['hough']['p95_ms']}), whole pipeline {w['total']['median_ms']} ms, "
          f"{w['segments']} segments")
    for name in ('improved', 'improved_most_lines'):
        w = worst[name]
        print(f"cluttered frame, {name}: whole frame median {w['total']['median_ms']} ms "
              f"(p95 {w['total']['p95_ms']}), {w['pieces']} pieces of line read"
              f"{' (more found: cluttered)' if w['cluttered'] else ''}")
    if not args.quick:
        os.makedirs(OUT, exist_ok=True)
        video = make_video(frames, args.video_frames,
                           os.path.join(OUT, f'video_{args.video_frames}.avi'))
        report['throughput'] = tp = throughput(video, args.video_frames)
        print(f"\ndry run over a {args.video_frames}-frame video, whole process: project "
              f"{tp['project']['fps']} frames/s ({tp['project']['seconds']} s), literal "
              f"{tp['literal']['fps']} frames/s ({tp['literal']['seconds']} s): "
              f"{tp['project']['fps'] / tp['literal']['fps']:.2f}x")
        report['memory'] = mem = memory(args.soak)
        print(f"memory: RSS {mem['rss_1000_mb']} MB after 1,000 frames, {mem['rss_end_mb']} MB "
              f"after {mem['frames']:,}: growth {mem['growth_mb']} MB; peak RSS "
              f"{mem['peak_rss_mb']} MB")
    write_json(args.json, report)
    return 0


if __name__ == '__main__':
    sys.exit(main())
