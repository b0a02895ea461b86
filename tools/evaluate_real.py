#!/usr/bin/env python3
"""How often the decisions agree with hand labels on real camera frames.

Reads a folder with labels.csv (file, expected_steering, confidence, scene, notes), as in
../shared/real-frames, and decides every labelled image (and every 10th frame of a labelled
video) three ways, each image with a fresh controller (no history from other images):

    lecture    the lecture's rule (algorithm 1.1), with --calibration none: the lecture's
               camera matrix belongs to the lecture's camera, not these;
    improved   the improved controller on that single frame, with the camera, mounting and lane
               profile of the frame's source (below); its decision word: left or right when the
               lane's centre lies more than half a lane width to that side at its look-ahead,
               straight otherwise, none when it sees no lane;
    straight   always 'straight', the baseline any controller has to beat.

A label 'no_lane' expects 'none'. A video counts once, by the decision most of its frames get.
Figures are printed per source and in all: agreement with the labels, and on the frames
labelled left or right, how many got the right direction; with and without the labels judged
doubtful from the pictures (DOUBTFUL below, with why).

usage (from the repository root):
    python -m tools.evaluate_real ../shared/real-frames [--json out.json] [--details]
                                                        [--pictures out/real]

Sources (one camera each, never one per frame):
    duckiebot  Duckietown's published default intrinsics (lanelib.camera.DUCKIEBOT_CAMERA); the
               duckietown lane profile; the lens 0.10 m above the floor. Its pitch: for dt-core's
               frames, 22.4 degrees down, where Duckietown's default extrinsic homography puts
               the horizon (row 115 of the rectified image); for the other Duckietown sources,
               none published, estimated from the source's own frames (horizon_pitch: the median
               row where the two lane lines' near parts meet, over all its frames). Floor mask
               0.1 m (past the Duckiebot's bumper) to 0.8 m ahead. Frames named *_rect are
               already rectified: the same matrix, no distortion. The controller's distances
               and speeds are the Kobuki's scaled to a Duckietown lane (x 0.2375 / 0.35).
    dashcam    no calibration published: a 60 degree horizontal field of view, lens 1.2 m up,
               pitch estimated as above; a highway lane profile (3.7 m, the left line any
               colour, the right one white); distances and speeds scaled by 3.7 / 0.35; floor
               mask 5 to 30 m ahead.
"""

import argparse
import collections
import csv
import math
import os
import sys
from dataclasses import replace

import cv2
import numpy as np

from kobuki_lane import LaneParams, LectureRule, detect
from lanelib.camera import DUCKIEBOT_CAMERA, Camera
from lanelib.cli import check_output, fail
from lanelib.colour import colour_masks
from lanelib.improved import ImprovedController, ImprovedParams
from lanelib.lanes import LaneProfile, Line
from lanelib.outputs import contact_sheet
from tools.common import write_json

PROG = 'tools.evaluate_real'
HIGHWAY = LaneProfile('highway', 3.7, Line('any', 'dashed', 0.15), Line('white', 'solid', 0.15))
DT_CORE_PITCH = 22.4  # [deg] Duckietown's default extrinsic homography: horizon at row 115
DOUBTFUL = {  # label: why it is judged doubtful, from the picture
    'duckietown_dt-core_anti_instagram/316closed_0029.jpg':
        'labelled left for a bend ahead, but the lane in front of the robot runs about 20 '
        'degrees to the right of its heading (the yellow dashes climb to the right): turning '
        'now, a lane follower turns right first',
    'duckietown_dt-core_anti_instagram/226night_0052.jpg':
        "the label's own note: the near yellow slants right, then bends left; turning now, a "
        'lane follower turns right first',
    'duckietown_dt-core_anti_instagram/226noon_0005.jpg':
        'labelled straight for a straight road, but both lines lean right and meet about 11 '
        'degrees right of the image centre: the robot stands askew, its lane 0.9 m ahead lies '
        'more than half a lane to the right, and a lane follower turns right to line up',
}


def source_of(relpath):
    return relpath.split('/')[0]


def camera_for(relpath, width, height):
    if source_of(relpath).startswith('udacity'):
        f = (width / 2) / math.tan(math.radians(30))
        k = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]])
        return Camera('dashcam', k, np.zeros(5), (width, height))
    if '_rect' in relpath:
        return replace(DUCKIEBOT_CAMERA, distortion=np.zeros(5))
    return DUCKIEBOT_CAMERA


def improved_params(relpath, pitch):
    """The improved controller's settings for a frame's source, at the camera's pitch."""
    dashcam = source_of(relpath).startswith('udacity')
    width = HIGHWAY.lane_width if dashcam else 0.2375
    s = width / 0.35  # the Kobuki's distances and speeds, scaled to this lane
    d = ImprovedParams()
    return ImprovedParams(
        camera_height=1.2 if dashcam else 0.10, camera_pitch=pitch, camera_forward=0.0,
        lane='duckietown', lane_width=width, roi_near=5.0 if dashcam else 0.1,
        roi_far=30.0 if dashcam else 0.8, lookahead=d.lookahead * s,
        lookahead_min=d.lookahead_min * s, v_max=d.v_max * s, v_min=d.v_min * s, memory=0.0)


def horizon_pitch(frames, camera):
    """The camera's pitch [deg down] from its frames: the median row where the near parts of
    the two lane lines meet (long line pieces of white or yellow in the lowest 40 % of each
    frame, the longest on each side, extended), or None with no frame to read."""
    rows = []
    for frame in frames:
        h, w = frame.shape[:2]
        cam = camera.scaled_to(w, h)
        image = cv2.undistort(frame, cam.matrix, cam.distortion, None, cam.matrix)
        near = np.zeros((h, w), np.uint8)
        near[int(0.6 * h):] = 255
        masks = colour_masks(image, near)
        lines = cv2.HoughLinesP(cv2.Canny((masks['white'] | masks['yellow']) & near, 50, 150),
                                rho=2, theta=np.pi / 180, threshold=30, minLineLength=h // 10,
                                maxLineGap=h // 40)
        row = _meeting_row(lines, w, h)
        if row is not None:
            rows.append(row)
    if not rows:
        return None
    k = camera.matrix
    return math.degrees(math.atan((k[1, 2] - np.median(rows)) / k[1, 1]))


def _meeting_row(lines, w, h):
    best = {}
    for x1, y1, x2, y2 in ([] if lines is None else lines.reshape(-1, 4)):
        if x2 == x1 or abs((y2 - y1) / (x2 - x1)) < 0.3:
            continue
        slope = (y2 - y1) / (x2 - x1)
        side = 'left' if slope < 0 else 'right'
        if (side == 'left') != (x1 + (h - y1) / slope < w / 2):  # each on its own half
            continue
        length = math.hypot(x2 - x1, y2 - y1)
        if side not in best or length > best[side][0]:
            best[side] = (length, x1, y1, slope)
    if len(best) < 2:
        return None
    (_, xa, ya, sa), (_, xb, yb, sb) = best['left'], best['right']
    x = (yb - ya + sa * xa - sb * xb) / (sa - sb)
    return ya + sa * (x - xa)


def pitches(folder, rows):
    """Each source's pitch: dt-core's published one, the others' estimated from their frames
    (a source of one frame cannot calibrate a camera: Duckietown's default then)."""
    by_source = collections.defaultdict(list)
    for row in rows:
        by_source[source_of(row['file'])].append(row['file'])
    out = {}
    for source, files in by_source.items():
        if source.startswith('duckietown_dt-core'):
            out[source] = (DT_CORE_PITCH, 'published')
            continue
        frames = [f for path in files for f in frames_of(os.path.join(folder, path))]
        estimate = horizon_pitch(frames, camera_for(files[0], *frames[0].shape[1::-1])) \
            if len(files) >= 3 else None
        out[source] = ((estimate, 'estimated') if estimate is not None
                       else (DT_CORE_PITCH, 'default'))
    return out


def decide(frame, relpath, pitch, pictures=None):
    """(lecture decision, improved decision, improved record) for one frame; with
    `pictures` (a path ending in .png), the improved controller's stages there, as one sheet."""
    p = LaneParams()
    lecture = LectureRule(p)(detect(frame, None, p)).decision
    camera = camera_for(relpath, frame.shape[1], frame.shape[0])
    profile = HIGHWAY if source_of(relpath).startswith('udacity') else None
    ctl = ImprovedController(p, improved_params(relpath, pitch), camera, profile)
    detection = ctl.perceive(frame, keep_stages=pictures is not None)
    command = ctl(detection)
    if pictures is not None:
        cv2.imwrite(pictures, contact_sheet([(title, image) for _, title, image in
                                             ctl.pictures(detection, command)], columns=3))
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


COLUMNS = ('file', 'expected_steering', 'confidence', 'scene')
STEERING = ('left', 'right', 'straight', 'no_lane')


def read_labels(folder):
    """The rows of folder/labels.csv; ValueError, saying which, for a column missing, a label
    that is not one of STEERING, or a file that is not there."""
    path = os.path.join(folder, 'labels.csv')
    with open(path, encoding='utf-8', newline='') as f:
        reader = csv.DictReader(f)
        missing = [c for c in COLUMNS if c not in (reader.fieldnames or ())]
        if missing:
            raise ValueError(f"{path}: no column {', '.join(missing)} (it needs "
                             f"{', '.join(COLUMNS)})")
        rows = list(reader)
    for line, row in enumerate(rows, start=2):
        if row['expected_steering'] not in STEERING:
            raise ValueError(f"{path} line {line}: expected_steering "
                             f"'{row['expected_steering']}' is not one of {', '.join(STEERING)}")
        if not os.path.isfile(os.path.join(folder, row['file'] or '')):
            raise ValueError(f"{path} line {line}: '{row['file']}' is not a file in {folder}")
    return rows


def evaluate(folder, pictures=None):
    """Every labelled file decided three ways; with `pictures` (a folder), the improved
    controller's stages of each (of a video, its first frame read) as <file>.png there."""
    rows = read_labels(folder)
    pitch = pitches(folder, rows)
    results = []
    for row in rows:
        expected = 'none' if row['expected_steering'] == 'no_lane' else row['expected_steering']
        votes = {'lecture': collections.Counter(), 'improved': collections.Counter()}
        detail = None
        for i, frame in enumerate(frames_of(os.path.join(folder, row['file']))):
            sheet = None
            if pictures is not None and i == 0:
                sheet = os.path.join(pictures, row['file'].replace('/', '__') + '.png')
            lecture, improved, detail = decide(frame, row['file'],
                                               pitch[source_of(row['file'])][0], sheet)
            votes['lecture'][lecture] += 1
            votes['improved'][improved] += 1
        results.append(dict(file=row['file'], source=source_of(row['file']),
                            expected=expected, confidence=row['confidence'],
                            scene=row['scene'], doubtful=DOUBTFUL.get(row['file']),
                            lecture=votes['lecture'].most_common(1)[0][0],
                            improved=votes['improved'].most_common(1)[0][0],
                            straight='straight', frames=sum(votes['lecture'].values()),
                            improved_detail=detail))
    return results, pitch


def figures(results, name):
    """'agree/n (pct), turns right/turns' for one way of deciding."""
    n = len(results)
    agree = sum(r[name] == r['expected'] for r in results)
    turns = [r for r in results if r['expected'] in ('left', 'right')]
    right = sum(r[name] == r['expected'] for r in turns)
    pct = f' ({agree / n:.0%})' if n else ''
    tpct = f' ({right / len(turns):.0%})' if turns else ''
    return f'{agree}/{n}{pct}, turn direction {right}/{len(turns)}{tpct}'


def report(results, pitch, details=False, stream=None):
    stream = stream or sys.stdout
    stream.write('cameras: ' + '; '.join(f'{s} pitch {p:.1f} deg ({how})'
                                         for s, (p, how) in sorted(pitch.items())) + '\n')
    standing = [r for r in results if not r['doubtful']]
    for title, subset in (('all labels', results),
                          (f'without the {len(results) - len(standing)} doubtful labels',
                           standing)):
        stream.write(f'\n{title}:\n')
        for source in ['all'] + sorted({r['source'] for r in subset}):
            rows = subset if source == 'all' else [r for r in subset if r['source'] == source]
            stream.write(f'  {source}:\n')
            for name in ('improved', 'lecture', 'straight'):
                stream.write(f'    {name:9s} {figures(rows, name)}\n')
    stream.write('\ndoubtful labels:\n')
    for r in results:
        if r['doubtful']:
            stream.write(f"  {r['file']} ({r['expected']}): {r['doubtful']}\n")
    if details:
        stream.write('\n| file | label | lecture | improved |\n|---|---|---|---|\n')
        for r in results:
            stream.write(f"| {r['file']} | {r['expected']}{' (doubtful)' if r['doubtful'] else ''}"
                         f" | {r['lecture']} | {r['improved']} |\n")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('folder', help='a folder with labels.csv')
    parser.add_argument('--json', metavar='FILE', help='write every decision as JSON')
    parser.add_argument('--details', action='store_true', help='a table of every file')
    parser.add_argument('--pictures', metavar='DIR',
                        help="write the improved controller's stages for every file there (one "
                        'sheet per file: the frame, undistorted, the floor band, each colour '
                        'mask, the pieces of tape by side, the lane and the decision)')
    args = parser.parse_args(argv)
    if not os.path.isfile(os.path.join(args.folder, 'labels.csv')):
        fail(PROG, f"no labels.csv in '{args.folder}'")
    if args.json:  # before the evaluation, not after it
        check_output(PROG, args.json, '--json')
    if args.pictures:
        try:
            os.makedirs(args.pictures, exist_ok=True)
        except OSError as e:
            fail(PROG, f"--pictures: cannot make '{args.pictures}': {e.strerror}")
        check_output(PROG, os.path.join(args.pictures, 'x.png'), '--pictures')
    try:
        read_labels(args.folder)
    except (OSError, ValueError) as e:
        fail(PROG, str(e))
    results, pitch = evaluate(args.folder, args.pictures)
    report(results, pitch, args.details)
    write_json(args.json, dict(cameras={s: dict(pitch_deg=round(p, 2), how=how)
                                        for s, (p, how) in pitch.items()}, results=results))
    return 0


if __name__ == '__main__':
    sys.exit(main())
