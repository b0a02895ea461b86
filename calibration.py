#!/usr/bin/env python3
"""Camera calibration for kobuki_lane: the lecture's camera, or one from a ROS camera_info YAML.

The lecture's `calibration_camera(seeimg)` undistorts every frame with one fixed camera
matrix and five distortion coefficients (plumb_bob: k1, k2, p1, p2, k3). Those exact numbers
live here as LECTURE_CAMERA. Any other camera is loaded from the YAML layout that ROS's
`camera_calibration` writes (image_width, image_height, camera_matrix, distortion_coefficients).

usage:
    python calibration.py --show lecture          print a calibration and what it implies
    python calibration.py --show camera.yaml
    python calibration.py --images 'calib/*.png' --pattern 9x6 --square 0.025 -o camera.yaml
                                                  calibrate from chessboard pictures

--pattern is the chessboard's inner corners (columns x rows), --square the side of one square
in metres. The tool finds the corners (sub-pixel), calibrates (plumb_bob), prints the RMS
reprojection error and the pictures it could not use, and writes the camera_info YAML layout
ROS's camera_calibration writes, which kobuki_lane.py --calibration camera.yaml loads.

In code:
    camera = load_calibration('lecture')       # or 'none', or a path to a YAML file
    undistorted = calibration_camera(frame, camera)
"""

import argparse
import math
import sys
from dataclasses import dataclass

import cv2
import numpy as np

from settings import output_problem


class CalibrationError(ValueError):
    """A calibration file that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class Camera:
    """Pinhole camera with plumb_bob distortion, valid at image_size (width, height) in pixels."""

    name: str
    matrix: np.ndarray  # 3x3 camera matrix K [px]
    distortion: np.ndarray  # (k1, k2, p1, p2, k3)
    image_size: tuple  # (width, height) [px] the matrix was calibrated at

    def scaled_to(self, width, height):
        """The same camera read out at another resolution (K scales with the image)."""
        if (width, height) == tuple(self.image_size):
            return self
        sx, sy = width / self.image_size[0], height / self.image_size[1]
        k = self.matrix.copy()
        k[0, :] *= sx
        k[1, :] *= sy
        return Camera(self.name, k, self.distortion, (width, height))


# The lecture's slide "calibration_camera" (Refer Slide Time 18:57), digit for digit.
# The slides give no image size; cx ~ 310 and cy ~ 196 fit a 640x480 webcam.
LECTURE_CAMERA = Camera(
    name='lecture',
    matrix=np.array([[893.45537548, 0.0, 309.61828309],
                     [0.0, 866.99738285, 196.40832355],
                     [0.0, 0.0, 1.0]]),
    distortion=np.array([2.28504143e-01, -7.32838958e+00, -2.43747623e-02,
                         9.12080996e-03, 3.98425001e+01]),
    image_size=(640, 480),
)


def calibration_camera(seeimg, camera):
    """Undistort one frame (the lecture's function; camera None means no calibration)."""
    if camera is None:
        return seeimg
    h, w = seeimg.shape[:2]
    cam = camera.scaled_to(w, h)
    # same call as the slide: the new camera matrix is the old one
    return cv2.undistort(seeimg, cam.matrix, cam.distortion, None, cam.matrix)


def undistortion_maps(camera, width, height):
    """The maps cv2.undistort builds on every call, built once for cv2.remap.

    They are the CV_16SC2 fixed-point maps cv2.undistort uses inside, so
    cv2.remap(frame, *maps, cv2.INTER_LINEAR) gives exactly calibration_camera(frame, camera).
    """
    cam = camera.scaled_to(width, height)
    return cv2.initUndistortRectifyMap(cam.matrix, cam.distortion, None, cam.matrix,
                                       (width, height), cv2.CV_16SC2)


def load_calibration(spec):
    """'lecture' -> LECTURE_CAMERA, 'none' -> None, anything else -> a camera_info YAML path."""
    if spec == 'lecture':
        return LECTURE_CAMERA
    if spec == 'none':
        return None
    return read_camera_info(spec)


def _matrix(doc, field, rows, cols, path):
    block = doc.get(field)
    if not isinstance(block, dict) or 'data' not in block:
        raise CalibrationError(f"{path}: field '{field}' is missing or has no 'data' list")
    data = block['data']
    try:
        values = np.array(data, dtype=float).ravel()
    except (TypeError, ValueError):
        raise CalibrationError(f"{path}: field '{field}.data' must be a list of numbers") from None
    if cols is None:  # distortion: any length OpenCV accepts
        if values.size not in (4, 5, 8, 12, 14):
            raise CalibrationError(f"{path}: field '{field}.data' has {values.size} values; "
                                   "expected 4, 5, 8, 12 or 14")
        return values
    if values.size != rows * cols:
        raise CalibrationError(f"{path}: field '{field}.data' has {values.size} values; "
                               f"expected {rows * cols} ({rows}x{cols})")
    if not np.all(np.isfinite(values)):
        raise CalibrationError(f"{path}: field '{field}.data' has a value that is not finite")
    return values.reshape(rows, cols)


def read_camera_info(path):
    """Read the YAML that ROS's camera_calibration writes; errors name the field at fault."""
    import yaml  # Debian's python3-yaml, which rospy itself needs

    try:
        with open(path, encoding='utf-8') as f:
            doc = yaml.safe_load(f)
    except FileNotFoundError:
        raise CalibrationError(f"{path}: no such calibration file "
                               "(use --calibration lecture, none, or a camera_info YAML)") from None
    except (OSError, yaml.YAMLError) as e:
        raise CalibrationError(f"{path}: cannot read as YAML: {e}") from None
    if not isinstance(doc, dict):
        raise CalibrationError(f"{path}: not a camera_info YAML mapping")
    size = []
    for field in ('image_width', 'image_height'):
        value = doc.get(field)
        if not isinstance(value, int) or value <= 0:
            raise CalibrationError(f"{path}: field '{field}' must be a positive integer")
        size.append(value)
    k = _matrix(doc, 'camera_matrix', 3, 3, path)
    if k[0, 0] <= 0 or k[1, 1] <= 0:
        raise CalibrationError(f"{path}: field 'camera_matrix' needs positive fx and fy")
    model = doc.get('distortion_model', 'plumb_bob')
    if model not in ('plumb_bob', 'rational_polynomial'):
        raise CalibrationError(f"{path}: field 'distortion_model' is '{model}'; "
                               "only plumb_bob and rational_polynomial are supported")
    dist = _matrix(doc, 'distortion_coefficients', 1, None, path)
    return Camera(str(doc.get('camera_name', path)), k, dist, tuple(size))


def describe(camera):
    """Human-readable summary: focal lengths, principal point, field of view."""
    if camera is None:
        return 'no calibration: frames are used as they come'
    k = camera.matrix
    w, h = camera.image_size
    fov_x = math.degrees(2 * math.atan(w / (2 * k[0, 0])))
    fov_y = math.degrees(2 * math.atan(h / (2 * k[1, 1])))
    return (f"camera '{camera.name}' at {w}x{h}: fx={k[0, 0]:.2f} fy={k[1, 1]:.2f} "
            f"cx={k[0, 2]:.2f} cy={k[1, 2]:.2f} px, field of view {fov_x:.1f} x {fov_y:.1f} deg, "
            f"distortion {np.array2string(camera.distortion, precision=4)}")


def find_corners(gray, pattern):
    """The chessboard's inner corners to a tenth of a pixel, or None if it is not all there."""
    found, corners = cv2.findChessboardCorners(
        gray, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
    return cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), criteria)


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
    rms, k, dist, _, _ = cv2.calibrateCamera(object_points, image_points, size, None, None)
    return CalibrationResult(Camera(name, k, dist.ravel()[:5], size), float(rms), used, unusable)


def camera_info_yaml(camera):
    """The YAML camera_calibration writes (the rectification is the identity for a monocular
    camera, and the projection is K with a zero fourth column)."""
    def block(rows, cols, values):
        data = ', '.join(f'{v:.10g}' for v in np.asarray(values, float).ravel())
        return f'  rows: {rows}\n  cols: {cols}\n  data: [{data}]\n'

    k = camera.matrix
    projection = np.hstack([k, np.zeros((3, 1))])
    return (f'image_width: {camera.image_size[0]}\nimage_height: {camera.image_size[1]}\n'
            f'camera_name: {camera.name}\ncamera_matrix:\n{block(3, 3, k)}'
            f'distortion_model: plumb_bob\n'
            f'distortion_coefficients:\n{block(1, len(camera.distortion), camera.distortion)}'
            f'rectification_matrix:\n{block(3, 3, np.eye(3))}'
            f'projection_matrix:\n{block(3, 4, projection)}')


def pattern_size(text):
    try:
        cols, rows = (int(n) for n in text.lower().split('x'))
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not COLSxROWS, e.g. 9x6") from None
    if cols < 2 or rows < 2:
        raise argparse.ArgumentTypeError('a chessboard has at least 2x2 inner corners')
    return cols, rows


def positive_float(text):
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f'{text} is not a positive length')
    return value


def run_calibration(args):
    import glob

    problem = output_problem(args.output)
    if problem:
        raise CalibrationError(f"cannot write '{args.output}': {problem}")
    paths = sorted(glob.glob(args.images))
    if not paths:
        raise CalibrationError(f"no files match '{args.images}' (quote the pattern)")
    result = calibrate(paths, args.pattern, args.square, args.name)
    for path, why in result.unusable:
        print(f'not used: {path}: {why}', file=sys.stderr)
    with open(args.output, 'w', encoding='utf-8') as f:
        f.write(camera_info_yaml(result.camera))
    print(f'{len(result.used)} of {len(paths)} pictures used; RMS reprojection error '
          f'{result.rms:.3f} px')
    print(describe(result.camera))
    print(f'wrote {args.output}: use it with kobuki_lane.py --calibration {args.output}')


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
    parser.add_argument('-o', '--output', default='camera.yaml',
                        help='camera_info YAML to write (default: camera.yaml)')
    parser.add_argument('--name', default='camera', help="camera_name in the YAML")
    args = parser.parse_args(argv)
    try:
        if args.images:
            run_calibration(args)
        else:
            print(describe(load_calibration(args.show or 'lecture')))
    except CalibrationError as e:
        print(f'calibration.py: error: {e}', file=sys.stderr)
        return 2
    return 0


if __name__ == '__main__':
    sys.exit(main())
