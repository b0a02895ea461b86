#!/usr/bin/env python3
"""Camera calibration for kobuki_lane: show a calibration, or make one from chessboard pictures.

The lecture's `calibration_camera(seeimg)` undistorts every frame with one fixed camera
matrix and five distortion coefficients (lanelib/camera.py: LECTURE_CAMERA, digit for digit).
Another camera needs its own: this tool makes it, in the YAML layout that ROS's
`camera_calibration` writes, which kobuki_lane.py --calibration camera.yaml loads.

The improved controller also needs the camera's mounting on the robot (height, pitch, roll,
how far ahead of the robot's centre). --ground measures it from one picture of a chessboard
lying on the floor in front of the robot, and writes the YAML that kobuki_lane.py --mounting
reads (lanelib/mounting.py).

usage:
    python calibration.py --show lecture          print a calibration and what it implies
    python calibration.py --show camera.yaml
    python calibration.py --images 'calib/*.png' --pattern 9x6 --square 0.025 -o camera.yaml
                                                  calibrate from chessboard pictures
    python calibration.py --ground board.png --pattern 7x5 --square 0.05 --board-ahead 0.8 \
        --calibration camera.yaml -o mounting.yaml
                                                  measure the mounting from a board on the floor
    python calibration.py --homography robot.yaml --calibration duckiebot -o mounting.yaml
                                                  a Duckiebot's extrinsic calibration as a mounting

--pattern is the chessboard's inner corners (columns x rows), --square the side of one square
in metres. --images finds the corners (sub-pixel), calibrates (plumb_bob), prints the RMS
reprojection error and the pictures it could not use, and writes the camera_info YAML.

--ground: lay the board flat on the floor, squarely in front of the robot, its middle on the
robot's centre line and its COLUMNS inner corners running across the robot (left to right).
--board-ahead D is how far the nearest row of inner corners (where four squares meet) lies
ahead of the robot's centre, the point midway between the two wheels: measure along the floor
from below the wheel axle. Take the picture with the camera as it is mounted, at the size the
node will use, with the whole board and a white margin round it in view. The board must look
big enough for its corners to be found: a level webcam sees the floor from about 0.6 m ahead,
where 5 cm squares (a 7x5 board) work and 2.5 cm ones do not. --calibration gives the camera's
intrinsics (lecture, duckiebot, or a camera_info YAML from --images; default lecture). The tool
prints and writes height [m], pitch_deg (down from horizontal), roll_deg, forward [m, lens
ahead of the robot's centre] and the reprojection error, and refuses a board it cannot find or
a fit that makes no sense (the camera below the floor, an error over 2 px).

--homography: a Duckiebot calibrated by Duckietown's own tools keeps its mounting as a bare
homography (its camera_extrinsic YAML, `homography: [9 numbers]`: pixels of the rectified image
to the floor, in metres from the middle of the wheel axle; with `version: '2'`, the newer
layout, the image's coordinates run from 0 to 1 across it). The tool reads the mounting out of
it and writes the same YAML as --ground. --calibration gives the camera it was made with
(default duckiebot, Duckietown's default; or the robot's camera_intrinsic YAML): Duckietown
rectifies with its projection_matrix, and the homography is read with that. It prints how far
apart the homography and the mounting put the floor in view, and refuses more than
50 px (the homography read with another camera matrix than its own).
"""

import argparse
import math
import sys
from dataclasses import dataclass

import cv2
import numpy as np

from lanelib.camera import (
    CalibrationError,
    Camera,
    camera_info_yaml,
    describe,
    load_calibration,
    rectified_matrix,
)
from lanelib.cli import check_output, check_outputs_apart
from lanelib.files import read_yaml
from lanelib.mounting import (
    HOMOGRAPHY_ERROR_PX,
    MountingError,
    find_corners,
    homography_mounting,
    mounting_yaml,
    parse_pattern,
    solve_mounting,
    warnings,
)

PROG = 'calibration.py'


@dataclass
class CalibrationResult:
    camera: Camera
    rms: float  # [px] reprojection error
    used: list
    unusable: list  # (path, why)


def calibrate(paths, pattern, square, name='camera'):
    """Calibrate from chessboard pictures; CalibrationError if fewer than 3 can be used."""
    board = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    board[:, :2] = np.indices(pattern).T.reshape(-1, 2) * square
    object_points, image_points, used, unusable, size = [], [], [], [], None
    for path in paths:
        gray = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
        if gray is None:
            unusable.append((path, 'not a readable image'))
            continue
        if size is not None and gray.shape[::-1] != size:
            unusable.append((path, f'{gray.shape[1]}x{gray.shape[0]}, not {size[0]}x{size[1]}'))
            continue
        corners = find_corners(gray, pattern)
        if corners is None:
            unusable.append((path, f'no {pattern[0]}x{pattern[1]} chessboard found'))
            continue
        size = gray.shape[::-1]
        object_points.append(board)
        image_points.append(corners)
        used.append(path)
    if len(used) < 3:
        raise CalibrationError(f'only {len(used)} of {len(paths)} pictures show the whole '
                               f'{pattern[0]}x{pattern[1]} chessboard; at least 3 are needed '
                               '(10 to 20 at different angles and distances is better)')
    rms, k, dist, rvecs, tvecs = cv2.calibrateCamera(object_points, image_points, size, None,
                                                     None)
    spread = viewpoint_spread(rvecs, tvecs)
    if spread < 5.0:
        raise CalibrationError(
            f'the {len(used)} pictures show the board from one viewpoint (their views differ by '
            f'{spread:.1f} degrees at most), which does not pin the camera down: take 10 to 20 '
            'with the board tilted different ways (by 20 degrees and more), at different '
            'distances and in different parts of the frame')
    return CalibrationResult(Camera(name, k, dist.ravel()[:5], size), float(rms), used, unusable)


def viewpoint_spread(rvecs, tvecs):
    """The largest angle [deg] between two views of the board: between their rotations, or
    between the directions from the camera to the board."""
    rotations = [cv2.Rodrigues(r)[0] for r in rvecs]
    rays = [t.ravel() / np.linalg.norm(t) for t in tvecs]
    largest = 0.0
    for i in range(len(rotations)):
        for j in range(i):
            turn = np.clip((np.trace(rotations[i].T @ rotations[j]) - 1) / 2, -1.0, 1.0)
            ray = np.clip(rays[i] @ rays[j], -1.0, 1.0)
            largest = max(largest, math.degrees(math.acos(turn)), math.degrees(math.acos(ray)))
    return largest


def pattern_size(text):
    try:
        return parse_pattern(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def positive_float(text):
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f'{text} is not a positive length')
    return value


def check_written(args, inputs):
    """-o: refused when its folder cannot be written, when it is one of the inputs, or when it
    exists already without --force (the node's rule, lanelib/cli.py); exit 2."""
    check_output(PROG, args.output, '-o')
    check_outputs_apart(PROG, inputs, [(args.output, '-o')], args.force)


def run_calibration(args):
    import glob

    paths = sorted(glob.glob(args.images))
    if not paths:
        raise CalibrationError(f"no files match '{args.images}' (quote the pattern)")
    check_written(args, [(path, '--images picture') for path in paths])
    result = calibrate(paths, args.pattern, args.square, args.name)
    for path, why in result.unusable:
        print(f'not used: {path}: {why}', file=sys.stderr)
    with open(args.output, 'w', encoding='utf-8') as f:
        f.write(camera_info_yaml(result.camera))
    print(f'{len(result.used)} of {len(paths)} pictures used; RMS reprojection error '
          f'{result.rms:.3f} px')
    print(describe(result.camera))
    print(f'wrote {args.output}: use it with kobuki_lane.py --calibration {args.output}')


def run_ground(args):
    check_written(args, [(args.ground, '--ground picture'),
                         (args.calibration, '--calibration file')])
    if args.board_ahead is None:
        raise CalibrationError('--ground needs --board-ahead D: how far the nearest row of inner '
                               "corners lies ahead of the robot's centre [m]")
    camera = load_calibration(args.calibration)
    if camera is None:
        raise CalibrationError('--ground needs the intrinsics: --calibration lecture, duckiebot '
                               'or a camera_info YAML, not none')
    image = cv2.imread(args.ground, cv2.IMREAD_COLOR)
    if image is None:
        raise CalibrationError(f"'{args.ground}' is not a readable image")
    try:
        result = solve_mounting(image, camera, args.pattern, args.square, args.board_ahead)
    except MountingError as e:
        raise CalibrationError(f'{args.ground}: {e}') from None
    for warning in warnings(result):
        print(f'calibration.py: warning: {warning}', file=sys.stderr)
    m = result.mounting
    print(f'camera {m.height:.4f} m above the floor, {m.forward:.4f} m ahead of the robot '
          f'centre, pitched {m.pitch_deg:.2f} deg down, rolled {m.roll_deg:.2f} deg; '
          f'reprojection error {result.error_px:.3f} px ({len(result.corners)} corners)')
    with open(args.output, 'w', encoding='utf-8') as f:
        f.write(mounting_yaml(result))
    print(f'wrote {args.output}: use it with kobuki_lane.py --controller improved --mounting '
          f'{args.output}')


def run_homography(args):
    check_written(args, [(args.homography, '--homography file'),
                         (args.calibration, '--calibration file')])
    doc = read_yaml(args.homography, CalibrationError, 'a Duckietown camera_extrinsic YAML')
    if not isinstance(doc, dict) or 'homography' not in doc:
        raise CalibrationError(f"{args.homography}: no field 'homography' (a Duckietown "
                               'camera_extrinsic YAML: homography: [9 numbers])')
    camera, matrix = rectified_matrix(args.calibration)
    try:
        homography = np.asarray(doc['homography'], float)
        if str(doc.get('version', '1')).strip() == '2':
            # Duckietown's newer layout: the rectified image's corners at 0 and 1 (its
            # resolution-independent coordinates), so pixels are first divided by the size
            width, height = camera.image_size
            homography = homography.reshape(3, 3) @ np.diag([1 / (width - 1), 1 / (height - 1),
                                                             1.0])
        result = homography_mounting(homography, matrix, camera.image_size)
    except (MountingError, TypeError, ValueError) as e:
        raise CalibrationError(f'{args.homography}: {e}') from None
    if result.error_px > HOMOGRAPHY_ERROR_PX:
        raise CalibrationError(
            f'{args.homography}: no camera mounting on --calibration {args.calibration} gives '
            f'this homography (they put the floor {result.error_px:.0f} px apart, more than '
            f'{HOMOGRAPHY_ERROR_PX:g}): give the camera_intrinsic YAML it was made with')
    m = result.mounting
    print(f'camera {m.height:.4f} m above the floor, {m.forward:.4f} m ahead of the axle, '
          f'pitched {m.pitch_deg:.2f} deg down, rolled {m.roll_deg:.2f} deg; the homography and '
          f'this mounting put the floor in view {result.error_px:.1f} px apart (RMS)')
    if abs(result.yaw_deg) > 2.0 or abs(result.lateral) > 0.02:
        print(f'calibration.py: note: the homography also has the camera looking '
              f'{abs(result.yaw_deg):.1f} deg {"left" if result.yaw_deg > 0 else "right"} of '
              f'the robot\'s heading and {100 * abs(result.lateral):.1f} cm '
              f'{"left" if result.lateral > 0 else "right"} of its centre line; the node '
              'assumes neither', file=sys.stderr)
    with open(args.output, 'w', encoding='utf-8') as f:
        f.write(mounting_yaml(result, homography=args.homography))
    print(f'wrote {args.output}: use it with kobuki_lane.py --controller improved --mounting '
          f'{args.output}')


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--show', metavar='CALIBRATION', default=None,
                        help="'lecture', 'none' or a camera_info YAML path (default: lecture)")
    parser.add_argument('--images', metavar='GLOB',
                        help="chessboard pictures to calibrate from, e.g. 'calib/*.png'")
    parser.add_argument('--pattern', type=pattern_size, default=(9, 6),
                        help='inner corners, columns x rows (default: 9x6)')
    parser.add_argument('--square', type=positive_float, default=0.025,
                        help='side of one square [m] (default: 0.025)')
    parser.add_argument('--ground', metavar='IMAGE',
                        help='measure the mounting from this picture of a chessboard on the floor '
                             '(see above)')
    parser.add_argument('--board-ahead', type=positive_float, metavar='D',
                        help="with --ground: the nearest row of inner corners, this far ahead of "
                             "the robot's centre [m]")
    parser.add_argument('--homography', metavar='FILE',
                        help="a Duckietown camera_extrinsic YAML to read the mounting from "
                             '(see above)')
    parser.add_argument('--calibration', default=None,
                        help="with --ground or --homography: the camera's intrinsics, "
                             "'lecture', 'duckiebot' or a camera_info YAML (default: lecture "
                             'with --ground, duckiebot with --homography)')
    parser.add_argument('-o', '--output',
                        help='YAML to write (default: camera.yaml for --images, mounting.yaml '
                             'for --ground and --homography)')
    parser.add_argument('--name', default='camera', help="camera_name in the YAML")
    parser.add_argument('--force', action='store_true',
                        help='replace the -o file if it exists already (without it, an existing '
                             'file is refused before anything runs)')
    args = parser.parse_args(argv)
    if sum(bool(x) for x in (args.images, args.ground, args.homography)) > 1:
        parser.error('give one of --images, --ground and --homography')
    args.output = args.output or ('camera.yaml' if args.images else 'mounting.yaml')
    args.calibration = args.calibration or ('duckiebot' if args.homography else 'lecture')
    try:
        if args.ground:
            run_ground(args)
        elif args.homography:
            run_homography(args)
        elif args.images:
            run_calibration(args)
        else:
            print(describe(load_calibration(args.show or 'lecture')))
    except CalibrationError as e:
        print(f'calibration.py: error: {e}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
