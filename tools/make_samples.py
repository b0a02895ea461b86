#!/usr/bin/env python3
"""Regenerate samples/: frames of a taped floor track seen through the lecture's camera.

The track is the lecture's, in three regions: A straight, B a left curve, C a right curve.
A robot drives along its centre line (with a small, seeded wobble in offset and heading) and
a frame is rendered every --spacing metres with lanelib/sim/world.py: the lecture's camera matrix
and distortion, a camera --height above the floor pitched --pitch degrees down, and a wall
--max-range metres away. Frames are named NNN_<region>.jpg so that name order is driving order.

usage (from the repository root):
    python -m tools.make_samples                 rewrite samples/track/ with the defaults
    python -m tools.make_samples --out /tmp/s --pitch 5 --noise 10

default values: height 0.20 m, pitch 0 deg (a level webcam on the Kobuki's front), lane
0.35 m, tape 0.03 m, floor 95 and tape 235 grey levels, noise sigma 3, seed 1.
"""

import argparse
import math
import os
import sys

import cv2
import numpy as np

from lanelib.camera import LECTURE_CAMERA
from lanelib.geometry import Mounting
from lanelib.sim.world import FloorCamera, FloorMap, Scene, Track
from tools.common import SAMPLES

# The lecture's track (slide at 08:30): region A straight, B bending left, C bending right.
LECTURE_SEGMENTS = [
    ('A', {'straight': 2.0}),
    ('B', {'arc': {'radius': 1.2, 'angle_deg': 90}}),
    ('C', {'arc': {'radius': 1.2, 'angle_deg': -90}}),
]


def region_of(s, lengths):
    """Which region the arc length s falls in."""
    end = 0.0
    for name, length in lengths:
        end += length
        if s < end:
            return name
    return lengths[-1][0]


def segment_length(seg):
    if 'straight' in seg:
        return float(seg['straight'])
    return float(seg['arc']['radius']) * math.radians(abs(float(seg['arc']['angle_deg'])))


def make_frames(args):
    """Yield (file name, frame) along the lecture's track."""
    segs = [seg for _, seg in LECTURE_SEGMENTS]
    # a straight run-out after C so the camera always has floor tape ahead
    track = Track(lane_width=args.lane_width, tape_width=args.tape_width,
                  segments=segs + [{'straight': 3.0}])
    lengths = [(name, segment_length(seg)) for name, seg in LECTURE_SEGMENTS]
    floor_map = FloorMap(track)
    camera = FloorCamera(LECTURE_CAMERA, Mounting(height=args.height, pitch_deg=args.pitch))
    scene = Scene(floor=args.floor, tape=args.tape, noise=args.noise, max_range=args.max_range)
    rng = np.random.default_rng(args.seed)
    total = sum(length for _, length in lengths)
    n = int(total / args.spacing)
    for i in range(n):
        s = (i + 0.5) * args.spacing
        offset = rng.uniform(-args.wobble_offset, args.wobble_offset)
        yaw = math.radians(rng.uniform(-args.wobble_yaw, args.wobble_yaw))
        region = region_of(s, lengths)
        frame = camera.render(floor_map, track.pose_at(s, offset, yaw), scene, rng)
        yield f'{i:03d}_{region}.jpg', frame


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--out', default=SAMPLES, help='output folder')
    parser.add_argument('--height', type=float, default=0.20, help='camera height [m]')
    parser.add_argument('--pitch', type=float, default=0.0, help='camera pitch down [deg]')
    parser.add_argument('--lane-width', type=float, default=0.35, help='between tape centres [m]')
    parser.add_argument('--tape-width', type=float, default=0.03, help='[m]')
    parser.add_argument('--floor', type=float, default=95.0, help='floor grey level')
    parser.add_argument('--tape', type=float, default=235.0, help='tape grey level')
    parser.add_argument('--noise', type=float, default=3.0, help='noise sigma [grey levels]')
    parser.add_argument('--max-range', type=float, default=3.0, help='wall distance [m]')
    parser.add_argument('--spacing', type=float, default=0.2, help='between frames [m]')
    parser.add_argument('--wobble-offset', type=float, default=0.02, help='max offset [m]')
    parser.add_argument('--wobble-yaw', type=float, default=2.0, help='max yaw error [deg]')
    parser.add_argument('--quality', type=int, default=90, help='JPEG quality')
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    for old in os.listdir(args.out):
        if old.endswith('.jpg'):
            os.remove(os.path.join(args.out, old))
    count = 0
    for name, frame in make_frames(args):
        cv2.imwrite(os.path.join(args.out, name), frame,
                    [cv2.IMWRITE_JPEG_QUALITY, args.quality])
        count += 1
    print(f'make_samples: wrote {count} frames to {args.out}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
