#!/usr/bin/env python3
"""Regenerate the pictures of docs/WALKTHROUGH.md from samples/track, with the node's own code.

usage (from the repository root):
    python -m tools.make_walkthrough            writes docs/img/*.png (small, 320 px wide)
    python -m tools.make_walkthrough --out DIR  somewhere else (the tests compare with docs/img)
"""

import argparse
import os
import sys

import cv2

from kobuki_lane import LaneParams, LectureRule, detect
from lanelib.camera import LECTURE_CAMERA
from lanelib.outputs import STAGE_TITLES, annotate, contact_sheet, stage_pictures
from lanelib.stages import as_bgr
from tools.common import REPO, SAMPLES

FRAME = '012_B.jpg'  # region B, bending left: both tapes and the wall in view
WIDTH = 320


def small(image):
    h, w = image.shape[:2]
    return cv2.resize(image, (WIDTH, round(h * WIDTH / w)), interpolation=cv2.INTER_AREA)


def write(folder, name, image):
    if image.ndim == 3 and (image[..., 0] == image[..., 1]).all() and \
            (image[..., 1] == image[..., 2]).all():
        image = image[..., 0]  # gray pictures as one channel: a third of the size
    cv2.imwrite(os.path.join(folder, name), image, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    return name


def make(folder):
    os.makedirs(folder, exist_ok=True)
    frame = cv2.imread(os.path.join(SAMPLES, FRAME))
    written = []
    for algorithm in ('1.1', '1.0'):
        p = LaneParams(algorithm=algorithm)
        detection = detect(frame, LECTURE_CAMERA, p, keep_stages=True)
        command = LectureRule(p)(detection)
        if algorithm == '1.1':
            pictures = stage_pictures(detection, command, p)
            keys = [key for key, _ in STAGE_TITLES] + ['hough']
            for k, ((_, image), key) in enumerate(zip(pictures, keys)):
                written.append(write(folder, f'{k}_{key}.png', small(as_bgr(image))))
            sheet = contact_sheet(pictures, width=200, columns=4)
            written.append(write(folder, 'sheet.png', sheet))
        written.append(write(folder, f'algorithm_{algorithm}.png',
                             small(annotate(detection, command, p))))
    return written


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--out', default=os.path.join(REPO, 'docs', 'img'))
    args = parser.parse_args(argv)
    names = make(args.out)
    size = sum(os.path.getsize(os.path.join(args.out, n)) for n in names)
    print(f'make_walkthrough: wrote {len(names)} pictures ({size / 1024:.0f} KB) to {args.out}',
          file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
