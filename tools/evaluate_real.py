#!/usr/bin/env python3
"""How often the decisions agree with hand labels on real camera frames.

Reads a folder with labels.csv (file, expected_steering, confidence, scene, notes), as in
../shared/real-frames, and decides every labelled image (and every 10th frame of a labelled
video) twice:

    lecture    the lecture's rule (algorithm 1.1), with --calibration none: the lecture's
               camera matrix belongs to the lecture's camera, not these;
    improved   the improved controller's perception on that single frame (no history), with
               the camera profile of the frame's source below; decision = sign of angular.z
               with the dead band, none when it sees no lane.

A label 'no_lane' expects 'none'. A video counts once, by the decision most of its frames get.

usage (from the repository root):
    python -m tools.evaluate_real ../shared/real-frames [--json out.json] [--details]

Camera profiles (one per camera, never per frame):
    duckiebot  Duckietown's published default intrinsics (duckiefleet
               calibrations/camera_intrinsic/default.yaml: fx 307.7, fy 315.0, plumb_bob
               k1 -0.257); lens 0.10 m above the floor, pitched 18 degrees down (the horizon
               in these frames); lane 0.22 m between the yellow and white tape centres; floor
               mask from the bottom of the view to 0.6 m ahead.
               Frames named *_rect are already rectified: the same matrix, no distortion.
    dashcam    no calibration published: a 60 degree horizontal field of view, lens 1.2 m up,
               level; lane 3.7 m; floor mask 6 to 30 m ahead.
"""

import argparse
import collections
import csv
import os
import sys

import cv2
import numpy as np

from kobuki_lane import LaneParams, LectureRule, detect, make_controller
from lanelib.camera import Camera
from lanelib.cli import check_output, fail
from lanelib.improved import ImprovedParams
from tools.common import write_json

PROG = 'tools.evaluate_real'

DUCKIEBOT_K = np.array([[307.7379294605756, 0, 329.692367951685],
                        [0, 314.9827773443905, 244.4605588877848], [0, 0, 1]])
DUCKIEBOT_DIST = np.array([-0.2565888993516047, 0.04481160508242147, -0.00505275149956019,
                           0.001308569367976665, 0])


def profile(relpath, width, height):
    """(camera, ImprovedParams) for a frame, by where it comes from."""
    if relpath.startswith('udacity'):
        f = (width / 2) / np.tan(np.radians(30))
        k = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]])
        camera = Camera('dashcam', k, np.zeros(5), (width, height))
        return camera, ImprovedParams(camera_height=1.2, camera_pitch=0.0, camera_forward=0.0,
                                      lane_width=3.7, roi_near=6.0, roi_far=30.0)
    rectified = '_rect' in relpath
    camera = Camera('duckiebot', DUCKIEBOT_K, np.zeros(5) if rectified else DUCKIEBOT_DIST,
                    (640, 480))
    return camera, ImprovedParams(camera_height=0.10, camera_pitch=18.0, camera_forward=0.0,
                                  lane_width=0.22, roi_near=0.02, roi_far=0.6)


def decide(frame, relpath):
    """(lecture decision, improved decision, improved record) for one frame."""
    p = LaneParams()
    lecture = LectureRule(p)(detect(frame, None, p)).decision
    camera, ip = profile(relpath, frame.shape[1], frame.shape[0])
    ctl = make_controller('improved', p, camera, ip)
    command = ctl(ctl.perceive(frame))
    return lecture, command.decision, dict(ctl.extra(), angular_z=round(command.angular_z, 3))


def frames_of(path):
    if not path.lower().endswith(('.mp4', '.avi', '.mov')):
        yield cv2.imread(path)
        return
    cap = cv2.VideoCapture(path)
    i = 0
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        if i % 10 == 0:
            yield frame
        i += 1
    cap.release()


def evaluate(folder):
    with open(os.path.join(folder, 'labels.csv'), encoding='utf-8') as f:
        rows = list(csv.DictReader(f))
    results = []
    for row in rows:
        expected = 'none' if row['expected_steering'] == 'no_lane' else row['expected_steering']
        votes = {'lecture': collections.Counter(), 'improved': collections.Counter()}
        detail = None
        for frame in frames_of(os.path.join(folder, row['file'])):
            lecture, improved, detail = decide(frame, row['file'])
            votes['lecture'][lecture] += 1
            votes['improved'][improved] += 1
        results.append(dict(file=row['file'], expected=expected, confidence=row['confidence'],
                            scene=row['scene'],
                            lecture=votes['lecture'].most_common(1)[0][0],
                            improved=votes['improved'].most_common(1)[0][0],
                            frames=sum(votes['lecture'].values()), improved_detail=detail))
    return results


def report(results, details=False, stream=None):
    stream = stream or sys.stdout
    n = len(results)
    for name in ('lecture', 'improved'):
        agree = sum(r[name] == r['expected'] for r in results)
        by = collections.Counter(r[name] for r in results)
        stream.write(f'{name:9s} agrees on {agree}/{n} ({agree / n:.0%}); decided '
                     f"{', '.join(f'{k} {v}' for k, v in sorted(by.items()))}\n")
        for conf in ('high', 'medium', 'low'):
            sub = [r for r in results if r['confidence'] == conf]
            if sub:
                ok = sum(r[name] == r['expected'] for r in sub)
                stream.write(f'          {conf} confidence labels: {ok}/{len(sub)}\n')
    if details:
        stream.write('\n| file | label | lecture | improved |\n|---|---|---|---|\n')
        for r in results:
            stream.write(f"| {r['file']} | {r['expected']} | {r['lecture']} | "
                         f"{r['improved']} |\n")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('folder', help='a folder with labels.csv')
    parser.add_argument('--json', metavar='FILE', help='write every decision as JSON')
    parser.add_argument('--details', action='store_true', help='a table of every file')
    args = parser.parse_args(argv)
    if not os.path.isfile(os.path.join(args.folder, 'labels.csv')):
        fail(PROG, f"no labels.csv in '{args.folder}'")
    if args.json:  # before the evaluation, not after it
        check_output(PROG, args.json, '--json')
    results = evaluate(args.folder)
    report(results, args.details)
    write_json(args.json, results)
    return 0


if __name__ == '__main__':
    sys.exit(main())
