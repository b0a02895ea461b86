#!/usr/bin/env python3
"""How often the node's decisions agree with hand labels on real camera frames.

Reads a folder with labels.csv (file, expected_steering, confidence, scene, notes), as in
../shared/real-frames, and decides every labelled image (and every 10th frame of a labelled
video) as a user would: kobuki_lane.py itself, run on that one picture (a fresh node, no history
from other pictures), with the flags a user types for the picture's robot, and nothing else:

    improved   --controller improved --robot PRESET: the preset of the source's robot (below);
               its decision word: left or right when the lane's centre lies more than half a
               lane width to that side at its look-ahead, or the lane seen beyond it bends that
               far from the line it starts along, straight otherwise, none with no lane
    lecture    the lecture's rule with --calibration none (the lecture's camera matrix is the
               lecture's webcam's, not these)
    straight   always 'straight', the baseline any controller has to beat

A label 'no_lane' expects 'none'. A video counts once, by the decision most of its frames get.
Figures are printed per source and in all: agreement with the labels, and on the frames labelled
left or right, how many were decided that way ('turn direction'), and for the improved
controller how many its command itself turned that way ('command turned': the sign of its
angular.z; the decision word reads where the lane lies ahead, the command is what the robot
does first, and the two can differ: a robot left of its lane's centre before a left bend
turns right first); with and without the labels judged doubtful from the pictures (DOUBTFUL
below, with why, or a label whose notes say 'doubtful: why').

The presets (--robot SOURCE=PRESET, repeatable, overrides these; a source is a label's first
folder, and its name's start is enough):
    duckietown*, negatives*   duckiebot: Duckietown's published default camera and mounting,
                              config/duckiebot.yaml; frames named *_rect are rectified already:
                              --calibration duckiebot-rectified (the same camera, no distortion)
    udacity*                  tools/robots/dashcam.yaml: a car's dash camera on a highway lane,
                              no calibration published, so what a user would assume (a 60 degree
                              field of view, level, 1.2 m up); nothing is estimated from the
                              frames scored
A picture published with its robot's own calibration gets it as that robot's user would:
duckietown-lx's visual_control_* pictures, --mounting tools/robots/visual_control_mounting.yaml
(the homography its visual-lane-servoing exercise gives for them, read by calibration.py
--homography: 15.0 degrees down, 0.128 m up, where Duckietown's default is 21.6 and 0.108).

usage (from the repository root):
    python -m tools.evaluate_real ../shared/real-frames [--json out.json] [--details]
                                  [--robot SOURCE=PRESET ...] [--pictures out/real]
"""

import argparse
import collections
import contextlib
import csv
import io
import json
import os
import sys
import tempfile

import cv2

import kobuki_lane
from lanelib.cli import check_output, fail
from tools.common import REPO, write_json

PROG = 'tools.evaluate_real'
PRESETS = {'duckietown': 'duckiebot', 'negatives': 'duckiebot',
           'udacity': os.path.join(REPO, 'tools', 'robots', 'dashcam.yaml')}
# pictures published with their robot's calibration: its mounting (made from it by
# calibration.py --homography), as that robot's user gives it
MOUNTINGS = {'duckietown_duckietown-lx/visual_control_':
             os.path.join(REPO, 'tools', 'robots', 'visual_control_mounting.yaml')}
COLUMNS = ('file', 'expected_steering', 'confidence', 'scene')
STEERING = ('left', 'right', 'straight', 'no_lane')
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
        'degrees right of the image centre: the robot stands askew, its lane at the look-ahead '
        'lies more than half a lane to the right, and a lane follower turns right to line up',
}


def noted_doubt(row):
    """Why a label is doubtful, where its own notes say so ('doubtful: why'), else None."""
    _, mark, why = (row.get('notes') or '').partition('doubtful:')
    return (why.strip() or 'doubtful') if mark else None


def source_of(relpath):
    return relpath.split('/')[0]


def preset_for(source, presets):
    """The --robot for a source: the longest key of `presets` its name starts with."""
    keys = sorted((k for k in presets if source.startswith(k)), key=len, reverse=True)
    if not keys:
        raise ValueError(f"no robot preset for the pictures in '{source}': give --robot "
                         f'{source}=PRESET')
    return presets[keys[0]]


def flags_for(relpath, presets):
    """The improved controller's flags for a picture, as its robot's user types them."""
    flags = ['--controller', 'improved', '--robot', preset_for(source_of(relpath), presets)]
    if '_rect' in os.path.basename(relpath):
        flags += ['--calibration', 'duckiebot-rectified']
    for start, mounting in MOUNTINGS.items():
        if relpath.startswith(start):
            flags += ['--mounting', mounting]
    return flags


def node_decides(picture, flags, workdir, stages=None):
    """The decision record kobuki_lane.py writes for one picture, run in this process with
    `flags` (what it logs is kept out of the report); with `stages` (a folder) its pictures."""
    out = os.path.join(workdir, 'decision.jsonl')
    argv = ['--source', picture, '--dry-run', '--quiet', '--progress', 'off', '--decisions', out,
            '--force', *flags]
    if stages:
        argv += ['--stages', stages]
    said = io.StringIO()
    with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said):
        try:
            status = kobuki_lane.main(argv)
        except SystemExit as e:
            status = e.code
    if status != 0:
        raise RuntimeError(f'kobuki_lane.py {" ".join(argv)} exited {status}: '
                           f'{said.getvalue().strip()[-500:]}')
    with open(out, encoding='utf-8') as f:
        return json.loads(f.readlines()[-1])


def frames_of(path, workdir):
    """The picture itself, or every 10th frame of a video written out as pictures."""
    if not path.lower().endswith(('.mp4', '.avi', '.mov')):
        yield path
        return
    cap = cv2.VideoCapture(path)
    i = 0
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        if i % 10 == 0:
            picture = os.path.join(workdir, f'frame_{i:05d}.png')
            cv2.imwrite(picture, frame)
            yield picture
        i += 1
    cap.release()


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


def evaluate(folder, presets, pictures=None):
    """Every labelled file decided three ways; with `pictures` (a folder), the improved
    controller's stages of each (of a video, its first frame) as <file>_sheet.png there."""
    results = []
    for row in read_labels(folder):
        expected = 'none' if row['expected_steering'] == 'no_lane' else row['expected_steering']
        votes = {'lecture': collections.Counter(), 'improved': collections.Counter()}
        flags = flags_for(row['file'], presets)
        detail = None
        with tempfile.TemporaryDirectory() as work:
            for i, picture in enumerate(frames_of(os.path.join(folder, row['file']), work)):
                stages = None
                if pictures is not None and i == 0:
                    stages = os.path.join(work, 'stages')
                lecture = node_decides(picture, ['--calibration', 'none'], work)
                detail = node_decides(picture, flags, work, stages)
                votes['lecture'][lecture['decision']] += 1
                votes['improved'][detail['decision']] += 1
                if stages:
                    sheet = [n for n in os.listdir(stages) if n.endswith('_sheet.png')][0]
                    os.replace(os.path.join(stages, sheet), os.path.join(
                        pictures, row['file'].replace('/', '__') + '.png'))
        results.append(dict(file=row['file'], source=source_of(row['file']),
                            expected=expected, confidence=row['confidence'],
                            scene=row['scene'],
                            doubtful=DOUBTFUL.get(row['file']) or noted_doubt(row),
                            flags=' '.join(flags),
                            lecture=votes['lecture'].most_common(1)[0][0],
                            improved=votes['improved'].most_common(1)[0][0],
                            straight='straight', frames=sum(votes['lecture'].values()),
                            improved_detail={k: detail.get(k) for k in (
                                'offset_m', 'heading_rad', 'curvature', 'confidence',
                                'angular_z')}))
    return results


def figures(results, name):
    """'agree/n (pct), turn direction right/turns (pct)' for one way of deciding; for the
    improved controller also ', command turned right/turns (pct)'."""
    n = len(results)
    agree = sum(r[name] == r['expected'] for r in results)
    turns = [r for r in results if r['expected'] in ('left', 'right')]
    right = sum(r[name] == r['expected'] for r in turns)
    pct = f' ({agree / n:.0%})' if n else ''
    tpct = f' ({right / len(turns):.0%})' if turns else ''
    out = f'{agree}/{n}{pct}, turn direction {right}/{len(turns)}{tpct}'
    if name == 'improved':
        turned = sum(turned_by(r) == r['expected'] for r in turns)
        out += f', command turned {turned}/{len(turns)}' + (
            f' ({turned / len(turns):.0%})' if turns else '')
    return out


def turned_by(result):
    """'left' or 'right': the way the improved controller's command for the picture (of a
    video, its last frame's) turns the robot (the sign of its angular.z), else 'straight'."""
    omega = (result.get('improved_detail') or {}).get('angular_z') or 0.0
    return 'left' if omega > 0 else 'right' if omega < 0 else 'straight'


def report(results, details=False, stream=None):
    stream = stream or sys.stdout
    flags = sorted({(r['source'], r['flags']) for r in results})
    stream.write('flags per source (besides --source PICTURE --dry-run):\n' +
                 ''.join(f'  {source}: {flag}\n' for source, flag in flags))
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
        stream.write('\n| file | label | lecture | improved | its command turned |\n'
                     '|---|---|---|---|---|\n')
        for r in results:
            stream.write(f"| {r['file']} | {r['expected']}{' (doubtful)' if r['doubtful'] else ''}"
                         f" | {r['lecture']} | {r['improved']} | {turned_by(r)} |\n")


def preset_option(text):
    source, sep, preset = text.partition('=')
    if not sep or not source or not preset:
        raise argparse.ArgumentTypeError(f"'{text}' is not SOURCE=PRESET, e.g. "
                                         'rendered=duckiebot')
    return source, preset


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('folder', help='a folder with labels.csv')
    parser.add_argument('--json', metavar='FILE', help='write every decision as JSON')
    parser.add_argument('--details', action='store_true', help='a table of every file')
    parser.add_argument('--robot', type=preset_option, action='append', default=[],
                        metavar='SOURCE=PRESET',
                        help='the --robot for the pictures of a source (see above)')
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
    presets = dict(PRESETS, **dict(args.robot))
    try:
        rows = read_labels(args.folder)
        for row in rows:
            preset_for(source_of(row['file']), presets)
    except (OSError, ValueError) as e:
        fail(PROG, str(e))
    results = evaluate(args.folder, presets, args.pictures)
    report(results, args.details)
    write_json(args.json, dict(presets=presets, results=results))
    return 0


if __name__ == '__main__':
    sys.exit(main())
