"""How far askew a robot stands on a straight lane, read from the picture alone.

On a straight lane the two lines meet, in the undistorted picture, at the lane's vanishing
point, on the floor's horizon: fx tan(psi) / cos(pitch) to the side of the image centre for a
lane running psi from the robot's heading, whatever the camera's height or where the robot
stands across the lane (a small roll aside). The pitch is the duckiebot preset's. This
reads that angle for the Duckietown frames labelled 'straight' in a folder with labels.csv (as
tools.evaluate_real reads), with nothing of the node's: no floor projection, no lane estimate.
The lines are found by plain colour thresholds: the right line the largest white blob in the
lower part of the picture whose bottom lies right of centre, the left line the yellow left of
it in the lower part (blobs of a dash's size, not specks); each a straight line fitted to its
pixels (cv2.fitLine, Huber). Where a
line is not found (a dark or blurred frame, a bumper across the view; fewer than INLIERS of its
pixels within NEAR of the line fitted), or the two meet further than HORIZON from the floor's
horizon (the preset's camera pitch: not a lane's two lines), the angle is blank.

A robot askew by more than atan(turn_offset / lookahead) of the duckiebot preset (11.0 degrees:
half a lane width at 2.571 lane widths) has its lane's centre, at the look-ahead, more than half
a lane aside even where it stands on the centre line: a lane follower turns to line up, and by
the labels' convention (turn now to follow the lane) a 'straight' label there is doubtful.

    python -m tools.askew FOLDER [--pictures DIR]

prints file, angle (degrees, + the lane runs to the right of the robot's heading), and whether
beyond that angle; --pictures writes each picture undistorted with the two lines drawn.
"""

import argparse
import csv
import math
import os
import sys

import cv2
import numpy as np

from lanelib.camera import DUCKIEBOT_CAMERA
from lanelib.files import read_yaml
from lanelib.improved import ImprovedParams
from lanelib.robots import preset_path

PROG = 'tools.askew'
LOWER = 0.45  # the white line is looked for below this fraction of the picture's height
LOWER_YELLOW = 0.55  # and the yellow below this: far up, yellow ducks stand on the road's edge
YELLOW = ((15, 90, 90), (40, 255, 255))  # HSV, OpenCV's hue 0..180
WHITE = ((0, 0, 150), (180, 60, 255))
MIN_PIXELS = 150  # fewer pixels of a line: not found
MIN_ROWS = 10  # fewer rows of it whole in the picture: not found
EDGE = 2  # [px] a row of a line this near the picture's side is cut by it
BLOB = 300  # [px] smaller white blobs are not the line
NEAR = 0.06  # [of the width] a line's pixels this near it are on it
INLIERS = 0.6  # fewer of them on it: the blob is no line (a floor's tint, a blur)
HORIZON = 0.1  # [of the height] lines meeting further from the horizon (about 9 degrees of
# pitch off the preset's, at the Duckiebot's focal length) are not a lane's two lines
DASH = 100  # [px] smaller yellow blobs are specks (a dim floor's tint), not dashes
RIGHT_OF = 0.45  # [of the width] the white line's bottom lies right of this
GAP = 15  # [px] the yellow must lie this far left of the white line


def limit_deg(robot='duckiebot'):
    """atan(turn_offset / lookahead) of a preset (its own, or the defaults): how far askew
    the lane's centre at the look-ahead lies turn_offset aside, for a robot on the centre line."""
    preset = read_yaml(preset_path(robot), ValueError, 'a robot preset')
    p = ImprovedParams()
    return math.degrees(math.atan(preset.get('turn_offset', p.turn_offset) /
                                  preset.get('lookahead', p.lookahead)))


def _fit(mask):
    """The line through the middles of a mask's rows (a tape is wide near the camera, and cut
    where it leaves the picture: a line through all its pixels leans), or None: too few
    pixels, or too few of them near the line."""
    ys, xs = np.nonzero(mask)
    if len(xs) < MIN_PIXELS:
        return None
    w = mask.shape[1]
    rows = np.unique(ys)
    sums = np.bincount(ys, weights=xs, minlength=mask.shape[0])[rows]
    counts = np.bincount(ys, minlength=mask.shape[0])[rows]
    lo = np.full(mask.shape[0], w)
    hi = np.full(mask.shape[0], -1)
    np.minimum.at(lo, ys, xs)
    np.maximum.at(hi, ys, xs)
    whole = (lo[rows] > EDGE) & (hi[rows] < w - 1 - EDGE)  # rows not cut by the picture's edge
    if np.count_nonzero(whole) < MIN_ROWS:
        return None
    middles = np.column_stack([sums / counts, rows])[whole].astype(np.float32)
    vx, vy, x0, y0 = line = cv2.fitLine(middles, cv2.DIST_HUBER, 0, 0.01, 0.01).ravel()
    off = np.abs((xs - x0) * vy - (ys - y0) * vx)  # each pixel's distance from the line
    if np.mean(off < NEAR * w) < INLIERS:
        return None
    return line


def lane_lines(undistorted):
    """((vx, vy, x0, y0) of the yellow line, and of the white) in the undistorted BGR picture,
    or None for a line not found."""
    h, w = undistorted.shape[:2]
    hsv = cv2.cvtColor(undistorted, cv2.COLOR_BGR2HSV)
    white = cv2.inRange(hsv, *(np.array(v) for v in WHITE)) > 0
    white[:int(LOWER * h)] = False
    n, labels, stats, _ = cv2.connectedComponentsWithStats(white.astype(np.uint8))
    best = None
    for i in range(1, n):
        if stats[i, cv2.CC_STAT_AREA] < BLOB:
            continue
        ys, xs = np.nonzero(labels == i)
        if xs[ys >= ys.max() - 5].mean() < RIGHT_OF * w:  # its bottom left of centre
            continue
        if best is None or stats[i, cv2.CC_STAT_AREA] > stats[best, cv2.CC_STAT_AREA]:
            best = i
    right = None if best is None else _fit(labels == best)
    if right is None:
        return None, None
    vx, vy, x0, y0 = right
    at_row = x0 + (np.arange(h) - y0) * vx / vy  # the white line's x on each row
    yellow = cv2.inRange(hsv, *(np.array(v) for v in YELLOW)) > 0
    yellow[:int(LOWER_YELLOW * h)] = False
    yellow &= np.arange(w)[None, :] < at_row[:, None] - GAP
    n, labels, stats, _ = cv2.connectedComponentsWithStats(yellow.astype(np.uint8))
    dashes = np.isin(labels, [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= DASH])
    return _fit(dashes), right


def preset_pitch(robot='duckiebot'):
    """[rad] the preset's camera pitch, below horizontal."""
    return math.radians(read_yaml(preset_path(robot), ValueError, 'a robot preset')['camera_pitch'])


def horizon_row(camera):
    """[px] the floor's horizon in the undistorted picture, for the preset's camera pitch."""
    return camera.matrix[1, 2] - camera.matrix[1, 1] * math.tan(preset_pitch())


def askew_deg(bgr, camera=DUCKIEBOT_CAMERA):
    """(angle [deg], the picture undistorted, the two lines) or (None, picture, lines): how far
    right of the robot's heading the lane runs, from where its two lines meet."""
    h, w = bgr.shape[:2]
    cam = camera.scaled_to(w, h)
    undistorted = cv2.undistort(bgr, cam.matrix, cam.distortion)
    left, right = lane_lines(undistorted)
    if left is None or right is None:
        return None, undistorted, (left, right)
    (a1, b1, x1, y1), (a2, b2, x2, y2) = left, right
    try:
        t = np.linalg.solve([[a1, -a2], [b1, -b2]], [x2 - x1, y2 - y1])
    except np.linalg.LinAlgError:  # parallel in the picture: they do not meet
        return None, undistorted, (left, right)
    x, y = x1 + a1 * t[0], y1 + b1 * t[0]
    if abs(y - horizon_row(cam)) > HORIZON * h:  # a lane's two lines meet on the horizon
        return None, undistorted, (left, right)
    # a floor direction psi from the heading meets the horizon fx tan(psi) / cos(pitch) aside
    sideways = (x - cam.matrix[0, 2]) / cam.matrix[0, 0] * math.cos(preset_pitch())
    return math.degrees(math.atan(sideways)), undistorted, (left, right)


def _drawn(undistorted, lines, angle):
    out = undistorted.copy()
    for line, colour in zip(lines, ((0, 255, 255), (255, 0, 255))):
        if line is not None:
            vx, vy, x0, y0 = line
            cv2.line(out, (int(x0 - 2000 * vx), int(y0 - 2000 * vy)),
                     (int(x0 + 2000 * vx), int(y0 + 2000 * vy)), colour, 2)
    text = 'lines not found' if angle is None else f'{angle:+.1f} deg'
    cv2.putText(out, text, (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 1, (0, 0, 255), 2)
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('folder', help='a folder with labels.csv (file, expected_steering, ...)')
    parser.add_argument('--pictures', metavar='DIR',
                        help='write each picture undistorted with the two lines drawn here')
    args = parser.parse_args(argv)
    path = os.path.join(args.folder, 'labels.csv')
    try:
        with open(path, encoding='utf-8', newline='') as f:
            rows = [r for r in csv.DictReader(f) if r.get('expected_steering') == 'straight'
                    and (r.get('file') or '').startswith('duckietown')]
    except OSError as e:
        parser.error(f'cannot read {path}: {e.strerror}')
    if args.pictures:
        os.makedirs(args.pictures, exist_ok=True)
    limit = limit_deg()
    out = csv.writer(sys.stdout, lineterminator='\n')
    out.writerow(('file', 'askew_deg', f'beyond_{limit:.1f}_deg'))
    for row in rows:
        bgr = cv2.imread(os.path.join(args.folder, row['file']))
        if bgr is None:
            parser.error(f"{row['file']}: not a picture OpenCV reads")
        angle, undistorted, lines = askew_deg(bgr)
        out.writerow((row['file'], '' if angle is None else f'{angle:+.1f}',
                      '' if angle is None else 'yes' if abs(angle) > limit else 'no'))
        if args.pictures:
            cv2.imwrite(os.path.join(args.pictures, row['file'].replace('/', '__') + '.png'),
                        _drawn(undistorted, lines, angle))
    return 0


if __name__ == '__main__':
    sys.exit(main())
