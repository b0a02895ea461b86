"""The camera's mounting on the robot, measured from one picture of a chessboard on the floor.

This is the extrinsic half of a camera calibration (Duckietown does the same with a board on
the floor, but keeps a bare homography): calibration.py --ground solves for where the lens is
and how it points, in metres and degrees, and writes a small YAML that kobuki_lane.py
--mounting reads:

    height: 0.2013          # [m] lens above the floor
    pitch_deg: 0.42         # [deg] optical axis below horizontal
    roll_deg: -0.1          # [deg] about the optical axis, + when the camera's right side is lower
    forward: 0.098          # [m] lens ahead of the robot's centre
    reprojection_error_px: 0.21

Where the board goes: flat on the floor, squarely in front of the robot, its middle on the
robot's centre line, with its `columns` inner corners running across the robot (left to
right), and its nearest row of inner corners `board_ahead` metres ahead of the robot's centre
(the midpoint between the wheels): measure along the floor from below the wheel axle to that
row of corners. The robot frame is lanelib/geometry.py's: x ahead, y left, z up.
"""

import math
from dataclasses import dataclass

import cv2
import numpy as np

from lanelib.files import read_yaml
from lanelib.geometry import Mounting
from lanelib.settings import above, between

KEYS = ('height', 'pitch_deg', 'roll_deg', 'forward')
# the bounds of a mounting, in a file or as the improved controller's flags alike
BOUNDS = dict(height=above(0, 2), pitch_deg=between(-45, 80), roll_deg=between(-45, 45),
              forward=between(-2, 2))
MAX_ERROR_PX = 2.0  # a fit worse than this is refused: the board or its settings are wrong
# a Duckietown homography whose mounting puts the floor further than this from it was made with
# another camera: dt-core's log-calib-config holds 42 robots' extrinsic calibrations; the 41
# with the camera above the floor, each read with its robot's projection matrix (the default's
# where it has none), leave 1.6 to 40 px; read with the camera matrix, 71 to 180
HOMOGRAPHY_ERROR_PX = 50.0


class MountingError(ValueError):
    """A picture, a fit or a file that gives no usable mounting; the message says what to do."""


@dataclass
class MountingResult:
    mounting: Mounting
    error_px: float  # RMS reprojection error of the board's corners
    yaw_deg: float  # the optical axis left (+) of the robot's heading
    lateral: float  # [m] the lens left (+) of the robot's centre line
    corners: np.ndarray  # (N, 2) the inner corners found, nearest row first, left to right


def parse_pattern(text):
    """'9x6' -> (9, 6): a chessboard's inner corners, columns x rows; ValueError if not."""
    try:
        cols, rows = (int(n) for n in text.lower().split('x'))
    except ValueError:
        raise ValueError(f"'{text}' is not COLSxROWS, e.g. 9x6") from None
    if cols < 2 or rows < 2:
        raise ValueError('a chessboard has at least 2x2 inner corners')
    return cols, rows


def board_points(pattern, square, board_ahead):
    """The inner corners of a board (columns x rows) on the floor in the robot frame, nearest
    row first, each row from the robot's right to its left: (N, 3)."""
    cols, rows = pattern
    i, j = np.meshgrid(np.arange(rows), np.arange(cols), indexing='ij')
    x = board_ahead + i * square
    y = (j - (cols - 1) / 2) * square
    return np.stack([x, y, np.zeros_like(x)], axis=-1).reshape(-1, 3).astype(np.float64)


def find_corners(gray, pattern):
    """A chessboard's inner corners (columns x rows) to a thousandth of a pixel, in OpenCV's
    order, or None if the whole board is not in the picture (or the picture is too small to
    look in: OpenCV fails on it). calibration.py --images and --ground both use this."""
    try:
        found, corners = cv2.findChessboardCorners(
            gray, pattern, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not found:
            return None
        criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 0.001)
        return cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), criteria)
    except cv2.error:  # a picture of a few pixels: no board in it
        return None


def find_board(gray, pattern):
    """The chessboard's inner corners to a tenth of a pixel as a (rows, columns, 2) grid,
    nearest row first and each row from the robot's right to its left (the picture's right to
    its left), or None if the whole board is not found. OpenCV numbers the corners from any
    corner of the board; the grid is turned so that it reads as board_points."""
    corners = find_corners(gray, pattern)
    if corners is None:
        return None
    cols, rows = pattern
    grid = corners.reshape(rows, cols, 2)

    def across(g):  # how much more a step along a row moves sideways than up or down
        step = np.abs(np.diff(g, axis=1)).mean(axis=(0, 1))
        return step[0] / max(step[1], 1e-9)

    if rows > 1 and across(np.swapaxes(grid, 0, 1)) > across(grid):
        return None  # OpenCV's rows run along the robot: the board lies the other way round
    if grid[0, :, 1].mean() < grid[-1, :, 1].mean():
        grid = grid[::-1]  # nearest row (lowest in the picture) first
    if grid[:, 0, 0].mean() < grid[:, -1, 0].mean():
        grid = grid[:, ::-1]  # each row from the robot's right: the picture's right
    return grid


def solve_mounting(image, camera, pattern, square, board_ahead):
    """The mounting from one picture (BGR or gray) of the board lying as the module says,
    with the camera's intrinsics (a lanelib.camera.Camera at the picture's size).
    MountingError when the board is not found or the fit makes no sense."""
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    h, w = gray.shape
    cam = camera.scaled_to(w, h)
    cols, rows = pattern
    grid = find_board(gray, pattern)
    if grid is None and cols != rows:
        grid = find_board(gray, (rows, cols))
        if grid is not None:
            raise MountingError(
                f'the board lies the wrong way round: turn it a quarter turn, so that its '
                f'{cols} inner corners run across the robot, or give --pattern {rows}x{cols}')
    if grid is None:
        raise MountingError(
            f'no {cols}x{rows} chessboard found: the whole board must be in the picture, flat '
            'on the floor, evenly lit, with a white margin round it; --pattern counts the inner '
            'corners (where four squares meet), columns x rows')
    image_points = grid.reshape(-1, 1, 2).astype(np.float64)
    object_points = board_points(pattern, square, board_ahead)
    ok, rvec, tvec = cv2.solvePnP(object_points, image_points, cam.matrix, cam.distortion,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise MountingError('the board was found but no camera pose fits it; check --pattern, '
                            '--square and --calibration')
    projected, _ = cv2.projectPoints(object_points, rvec, tvec, cam.matrix, cam.distortion)
    error = float(np.sqrt(np.mean(np.sum((projected - image_points) ** 2, axis=2))))
    rotation, _ = cv2.Rodrigues(rvec)  # robot -> camera: its rows are the camera's axes
    result = pose_mounting(rotation, -rotation.T @ tvec.ravel(), error, grid.reshape(-1, 2))
    check(result, board_ahead)
    return result


def pose_mounting(rotation, lens, error_px, corners):
    """The MountingResult of a camera pose: `rotation` takes the robot frame to the camera's
    (its rows are the camera's axes in the robot frame), `lens` is where the lens is."""
    x_cam, _, z_cam = rotation
    pitch = math.degrees(math.asin(float(np.clip(-z_cam[2], -1.0, 1.0))))
    yaw = math.degrees(math.atan2(z_cam[1], z_cam[0]))
    # the camera's x axis unrolled (level, square to the optical axis), and its y axis
    level = np.cross(z_cam, [0.0, 0.0, 1.0])
    level /= max(np.linalg.norm(level), 1e-12)
    down = np.cross(z_cam, level)
    roll = math.degrees(math.atan2(float(x_cam @ down), float(x_cam @ level)))
    return MountingResult(Mounting(float(lens[2]), pitch, float(lens[0]), roll), error_px, yaw,
                          float(lens[1]), corners)


def homography_mounting(homography, matrix, size):
    """The mounting a Duckietown extrinsic calibration holds. Duckietown keeps it as a bare
    homography (its camera_extrinsic YAML): pixels of the rectified image, whose camera matrix
    is `matrix` (Duckietown rectifies with the camera_info's projection matrix, not its camera
    matrix), to floor points (x ahead, y left, metres, from the middle of the wheel axle). Its
    inverse is matrix @ [r1 r2 t] up to scale, r1 and r2 the floor's x and y axes seen from the
    camera and t the axle's middle: the nearest rotation to them gives the mounting.
    error_px: how far the floor's pixels with that mounting lie from the homography's, over
    the floor in view of a `size` (width, height) picture up to 1 m ahead; large when the
    homography was made with another camera matrix. MountingError for a matrix that is no
    homography of a floor below a camera."""
    h = np.asarray(homography, float)
    if h.size != 9 or not np.all(np.isfinite(h)):
        raise MountingError('a homography is 9 finite numbers (3x3, row by row)')
    h = h.reshape(3, 3)
    if abs(np.linalg.det(h)) < 1e-15:
        raise MountingError('the homography is singular: it maps no picture to a floor')
    m = np.linalg.inv(matrix) @ np.linalg.inv(h)  # floor (x, y, 1) -> camera rays
    m *= 2.0 / (np.linalg.norm(m[:, 0]) + np.linalg.norm(m[:, 1]))
    if (m[:, 0] + m[:, 2])[2] < 0:  # the floor 1 m ahead lies in front of the camera
        m = -m
    u, _, vt = np.linalg.svd(np.column_stack([m[:, 0], m[:, 1], np.cross(m[:, 0], m[:, 1])]))
    rotation = u @ vt  # robot -> camera (the third column makes it a rotation, not a mirror)
    shift = m[:, 2]  # the axle's middle in the camera's frame
    # the pixels of the floor in view (up to 1 m ahead), mapped by the homography and by
    # the mounting
    width, height = size
    uu, vv = np.meshgrid(np.linspace(0, width - 1, 17), np.linspace(0, height - 1, 13))
    pixels = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)])
    floor = h @ pixels
    ahead = floor[0] / floor[2]
    seen = (ahead > 0) & (ahead < 1.0)  # (the sky maps behind the robot)
    if seen.sum() < 4:
        raise MountingError('the homography puts none of the picture on the floor ahead')
    points = np.vstack([floor[:2, seen] / floor[2, seen], np.zeros(seen.sum())])
    rays = matrix @ (rotation @ points + shift[:, None])
    error = float(np.sqrt(np.mean(np.sum((rays[:2] / rays[2] - pixels[:2, seen]) ** 2,
                                         axis=0))))
    result = pose_mounting(rotation, -rotation.T @ shift, error, pixels[:2, seen].T)
    if result.mounting.height <= 0:
        raise MountingError(f'the homography puts the camera {-100 * result.mounting.height:.1f}'
                            ' cm below the floor')
    return result


def check(result, board_ahead):
    """Refuse a fit that makes no sense, saying what to check."""
    m = result.mounting
    if m.height <= 0:
        raise MountingError(f'the fit puts the camera {-100 * m.height:.1f} cm below the floor: '
                            'check --board-ahead, --square and --pattern, and that the board '
                            'lies flat')
    if result.error_px > MAX_ERROR_PX:
        raise MountingError(
            f'the board fits the picture badly ({result.error_px:.1f} px RMS, more than '
            f'{MAX_ERROR_PX:g}): check --pattern, --square and --calibration (the intrinsics '
            'must be this camera\'s, at this resolution), and that the board lies flat')
    if not -45 < m.pitch_deg < 90 or abs(m.roll_deg) > 45:
        raise MountingError(f'the fit says pitch {m.pitch_deg:.1f} deg, roll {m.roll_deg:.1f} '
                            'deg, which no camera on a Kobuki has: check the picture and '
                            '--calibration')
    if m.forward > board_ahead or abs(m.forward) > 0.5 or m.height > 1.5:
        raise MountingError(f'the fit puts the lens {abs(m.forward):.2f} m '
                            f"{'ahead of' if m.forward >= 0 else 'behind'} the robot's centre "
                            f'and {m.height:.2f} m up, which is not on a Kobuki: check '
                            '--board-ahead and --square')


def warnings(result):
    """What the fit says that the node cannot take into account: a camera looking sideways or
    off the centre line (or the board not squarely in front of the robot)."""
    said = []
    if abs(result.yaw_deg) > 2.0:
        said.append(f"the camera looks {abs(result.yaw_deg):.1f} deg to the "
                    f"{'left' if result.yaw_deg > 0 else 'right'} of the robot's heading (or "
                    "the board is askew); the node assumes straight ahead: turn the camera "
                    "or the board")
    if abs(result.lateral) > 0.02:
        said.append(f"the lens is {100 * abs(result.lateral):.1f} cm "
                    f"{'left' if result.lateral > 0 else 'right'} of the robot's centre line (or "
                    "the board is not centred); the node assumes it on the line")
    return said


def mounting_yaml(result, homography=None):
    """The YAML --mounting reads: from a board's picture (its reprojection error a field), or
    from the Duckietown homography file `homography` (how far apart the two put the floor
    said in a comment)."""
    m = result.mounting
    made_by = f'calibration.py --homography {homography}' if homography else \
        'calibration.py --ground'
    error = (f'# this mounting and the homography put the floor in view (up to 1 m ahead) '
             f'{result.error_px:.1f} px apart, RMS\n' if homography else
             f'reprojection_error_px: {result.error_px:.3f}\n')
    return (f'# the camera on the robot, from {made_by}\n'
            f'height: {m.height:.4f}  # [m] lens above the floor\n'
            f'pitch_deg: {m.pitch_deg:.3f}  # [deg] optical axis below horizontal\n'
            f'roll_deg: {m.roll_deg:.3f}  # [deg] about the optical axis, + right side lower\n'
            f'forward: {m.forward:.4f}  # [m] lens ahead of the robot centre\n' + error)


def read_mounting(path):
    """A Mounting from the YAML calibration.py --ground writes; MountingError names the field
    at fault. height, pitch_deg, roll_deg and forward are needed; reprojection_error_px is
    allowed; nothing else is."""
    doc = read_yaml(path, MountingError, 'a mounting YAML')
    if not isinstance(doc, dict):
        raise MountingError(f'{path}: not a mapping of {", ".join(KEYS)}')
    unknown = sorted(set(doc) - set(KEYS) - {'reprojection_error_px'})
    if unknown:
        raise MountingError(f"{path}: unknown field '{unknown[0]}' (the fields are "
                            f"{', '.join(KEYS)})")
    values = {}
    for key in KEYS:
        value = doc.get(key)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                not math.isfinite(value):
            raise MountingError(f"{path}: field '{key}' must be a number, not {value!r}")
        if not BOUNDS[key](value):
            raise MountingError(f"{path}: field '{key}' is {value:g}; it must be "
                                f'{BOUNDS[key].range}')
        values[key] = float(value)
    return Mounting(**values)


def mounting_settings(path):
    """The improved controller's camera settings (ImprovedParams fields) in a mounting YAML;
    {} for no path. MountingError (a ValueError) names the field at fault."""
    if not path:
        return {}
    m = read_mounting(str(path))
    return dict(camera_height=m.height, camera_pitch=m.pitch_deg, camera_forward=m.forward,
                camera_roll=m.roll_deg)
