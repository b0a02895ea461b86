"""Cameras: the lecture's, or one from a ROS camera_info YAML; undistortion maps.

The lecture's `calibration_camera(seeimg)` undistorts every frame with one fixed camera matrix
and five distortion coefficients (plumb_bob: k1, k2, p1, p2, k3). Those exact numbers live here
as LECTURE_CAMERA. Any other camera is loaded from the YAML layout that ROS's
`camera_calibration` writes (image_width, image_height, camera_matrix, distortion_coefficients).
"""

import json
import math
import os
from dataclasses import dataclass

import cv2
import numpy as np

from lanelib.files import read_yaml


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


# Duckietown's published default camera (duckiefleet calibrations/camera_intrinsic/default.yaml):
# the Duckiebot's wide-angle 640x480 camera, about 75 degrees vertical field of view.
DUCKIEBOT_CAMERA = Camera(
    name='duckiebot',
    matrix=np.array([[307.7379294605756, 0.0, 329.692367951685],
                     [0.0, 314.9827773443905, 244.4605588877848],
                     [0.0, 0.0, 1.0]]),
    distortion=np.array([-0.2565888993516047, 0.04481160508242147, -0.00505275149956019,
                         0.001308569367976665, 0.0]),
    image_size=(640, 480),
)
# the same file's projection_matrix (its first three columns): the camera matrix of the image
# Duckietown rectifies with it, on which its extrinsic calibrations (homographies) are made
DUCKIEBOT_PROJECTION = np.array([[210.1107940673828, 0.0, 327.2577820024981],
                                 [0.0, 253.8408660888672, 239.9969353923052],
                                 [0.0, 0.0, 1.0]])
CAMERAS = {'lecture': LECTURE_CAMERA, 'duckiebot': DUCKIEBOT_CAMERA,
           # its frames rectified already (dt-core's image_rect, duckietown-lx's *_rect):
           # the same camera matrix, nothing left to undistort
           'duckiebot-rectified': Camera('duckiebot-rectified', DUCKIEBOT_CAMERA.matrix,
                                         np.zeros(5), DUCKIEBOT_CAMERA.image_size)}


def undistortion_maps(camera, width, height, source=None):
    """The maps cv2.undistort builds on every call, built once for cv2.remap.

    They are the CV_16SC2 fixed-point maps cv2.undistort uses inside, so
    cv2.remap(frame, *maps, cv2.INTER_LINEAR) gives exactly cv2.undistort's result (the
    lecture's calibration_camera; tests/test_pipeline.py checks it). source: the (width,
    height) of the frames remapped, when it is not the undistorted image's: the maps then read
    the camera's frames at that size straight into the undistorted image at this one (the
    camera read out at fewer pixels, with no frame shrunk first).
    """
    cam = camera.scaled_to(width, height)
    matrix = cam.matrix
    if source is not None:
        # each pixel read where cv2.resize's INTER_AREA centres it, f (x + 1/2) - 1/2 for a
        # factor f: at a factor 2 between two pixels, so that the linear remap averages them
        # as the resize does (read at 2 x, every other column, a tape's edge is noisier)
        matrix = camera.scaled_to(*source).matrix.copy()
        matrix[:2, 2] += (np.array(source) / (width, height) - 1) / 2
    return cv2.initUndistortRectifyMap(matrix, cam.distortion, None, cam.matrix,
                                       (width, height), cv2.CV_16SC2)


def load_calibration(spec):
    """A name in CAMERAS (lecture, duckiebot, duckiebot-rectified), 'none' -> None, anything
    else -> a camera_info YAML path."""
    if spec in CAMERAS:
        return CAMERAS[spec]
    if spec == 'none':
        return None
    return read_camera_info(spec)


def rectified_matrix(spec):
    """(camera, the camera matrix of the image a ROS or Duckietown pipeline rectifies it to)
    for a --calibration: image_proc and dt-core rectify with the camera_info's
    projection_matrix (its first three columns), which for a wide-angle camera keeps more of
    the view than its camera_matrix. Duckietown's default has it; a camera_info YAML's own is
    read (its camera_matrix if it has none); a built-in without one: its camera matrix."""
    camera = load_calibration(spec)
    if camera is None:
        raise CalibrationError("a rectified image needs a camera: --calibration lecture, "
                               "duckiebot or a camera_info YAML, not none")
    if spec == 'duckiebot':
        return camera, DUCKIEBOT_PROJECTION
    if spec in CAMERAS:
        return camera, camera.matrix
    doc = read_yaml(spec, CalibrationError)
    if 'projection_matrix' not in doc:
        return camera, camera.matrix
    projection = _matrix(doc, 'projection_matrix', 3, 4, spec)[:, :3]
    if not np.all(np.isfinite(projection)) or projection[0, 0] <= 0 or \
            projection[1, 1] <= 0 or not np.allclose(projection[2], [0.0, 0.0, 1.0]):
        raise CalibrationError(f"{spec}: field 'projection_matrix' is not a camera's "
                               '([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0])')
    return camera, projection


DISTORTION_LENGTHS = (4, 5, 8, 12, 14)  # what OpenCV's plumb_bob and rational models take
MODELS = ('plumb_bob', 'rational_polynomial')


def _matrix(doc, field, rows, cols, path):
    block = doc.get(field)
    if not isinstance(block, dict) or 'data' not in block:
        raise CalibrationError(f"{path}: field '{field}' is missing or has no 'data' list")
    data = block['data']
    try:
        values = np.array(data, dtype=float).ravel()
    except (TypeError, ValueError):
        raise CalibrationError(f"{path}: field '{field}.data' must be a list of numbers") from None
    if cols is None:  # distortion: checked with the rest in checked_camera
        return values
    if values.size != rows * cols:
        raise CalibrationError(f"{path}: field '{field}.data' has {values.size} values; "
                               f"expected {rows * cols} ({rows}x{cols})")
    return values.reshape(rows, cols)


def checked_camera(name, k, dist, size, model, where, fields=None):
    """A Camera from a calibration's parts, each checked as ROS's camera_calibration would
    write it; CalibrationError names `where` (a file, a topic) and the field at fault. fields:
    the names the source gives K, D and the model (a YAML's, or CameraInfo's). D empty: no
    distortion (a simulated or rectified camera's camera_info says so)."""
    kf, df, mf = fields or ('camera_matrix', 'distortion_coefficients', 'distortion_model')
    k, dist = np.asarray(k, float).reshape(3, 3), np.asarray(dist, float).ravel()
    if not np.all(np.isfinite(k)):
        raise CalibrationError(f"{where}: field '{kf}' has a value that is not finite")
    if k[0, 0] <= 0 or k[1, 1] <= 0:
        raise CalibrationError(f"{where}: field '{kf}' needs positive fx and fy")
    if not np.allclose(k[2], [0.0, 0.0, 1.0]) or k[1, 0] != 0:
        raise CalibrationError(f"{where}: field '{kf}' is not a camera matrix "
                               '([fx, 0, cx, 0, fy, cy, 0, 0, 1])')
    if model not in MODELS:
        raise CalibrationError(f"{where}: field '{mf}' is '{model}'; "
                               f"only {' and '.join(MODELS)} are supported")
    if dist.size == 0:
        dist = np.zeros(5)
    if dist.size not in DISTORTION_LENGTHS:
        raise CalibrationError(f"{where}: field '{df}' has {dist.size} values; expected "
                               f"{', '.join(map(str, DISTORTION_LENGTHS[:-1]))} or "
                               f'{DISTORTION_LENGTHS[-1]}')
    if not np.all(np.isfinite(dist)):
        raise CalibrationError(f"{where}: field '{df}' has a value that is not finite")
    camera = Camera(name, k, dist, tuple(size))
    problem = folds(camera)
    if problem:
        raise CalibrationError(f"{where}: field '{df}' "
                               f'{np.array2string(dist, precision=3)} {problem}; recalibrate')
    return camera


def read_camera_info(path):
    """Read the YAML that ROS's camera_calibration writes; errors name the field at fault."""
    if not os.path.exists(path):
        raise CalibrationError(f"{path}: no such calibration file "
                               "(use --calibration lecture, none, or a camera_info YAML)")
    doc = read_yaml(path, CalibrationError)
    if not isinstance(doc, dict):
        raise CalibrationError(f"{path}: not a camera_info YAML mapping")
    size = []
    for field in ('image_width', 'image_height'):
        value = doc.get(field)
        if not isinstance(value, int) or value <= 0:
            raise CalibrationError(f"{path}: field '{field}' must be a positive integer")
        size.append(value)
    k = _matrix(doc, 'camera_matrix', 3, 3, path)
    dist = _matrix(doc, 'distortion_coefficients', 1, None, path)
    if dist.size == 0:
        raise CalibrationError(f"{path}: field 'distortion_coefficients.data' is empty; give "
                               '[0, 0, 0, 0, 0] for a camera without distortion')
    return checked_camera(str(doc.get('camera_name', path)), k, dist, size,
                          doc.get('distortion_model', 'plumb_bob'), path,
                          ('camera_matrix', 'distortion_coefficients.data', 'distortion_model'))


def folds(camera):
    """Why undistorting with this camera would ruin frames, or None: its distortion folds the
    image (a row or column of the undistorted frame runs backwards) or leaves most of it
    empty (k1 = 50 does both)."""
    w, h = camera.image_size
    mx, my = cv2.initUndistortRectifyMap(camera.matrix, camera.distortion, None, camera.matrix,
                                         (w, h), cv2.CV_32FC1)
    inside = np.mean((mx >= 0) & (mx < w) & (my >= 0) & (my < h))
    if inside < 0.5:
        return f'leaves {100 * (1 - inside):.0f} % of the undistorted frame empty'
    row, column = mx[h // 2], my[:, w // 2]
    if not (np.all(np.diff(row) > 0) and np.all(np.diff(column) > 0)):
        return 'folds the image (its middle row or column runs backwards)'
    return None


def aspect_problem(camera, width, height):
    """Why a calibration made at another aspect ratio cannot be used on width x height frames
    (scaling it would stretch the image), or None."""
    cw, ch = camera.image_size
    if abs(cw / ch - width / height) > 0.01 * width / height:
        return (f"the calibration '{camera.name}' is for {cw}x{ch} frames, these are "
                f'{width}x{height}: another aspect ratio, which scaling cannot mend; calibrate '
                'at this size (calibration.py --images) or set the camera to it')
    return None


def camera_info_yaml(camera):
    """The YAML camera_calibration writes (the rectification is the identity for a monocular
    camera, and the projection is K with a zero fourth column)."""
    def block(rows, cols, values):
        data = ', '.join(f'{v:.10g}' for v in np.asarray(values, float).ravel())
        return f'  rows: {rows}\n  cols: {cols}\n  data: [{data}]\n'

    k = camera.matrix
    projection = np.hstack([k, np.zeros((3, 1))])
    return (f'image_width: {camera.image_size[0]}\nimage_height: {camera.image_size[1]}\n'
            f'camera_name: {json.dumps(camera.name)}\ncamera_matrix:\n{block(3, 3, k)}'
            f'distortion_model: plumb_bob\n'
            f'distortion_coefficients:\n{block(1, len(camera.distortion), camera.distortion)}'
            f'rectification_matrix:\n{block(3, 3, np.eye(3))}'
            f'projection_matrix:\n{block(3, 4, projection)}')


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
