"""calibration.py: the lecture's camera, ROS camera_info YAML files, and their errors."""

import cv2
import numpy as np
import pytest
from helpers import SAMPLES

from calibration import main
from kobuki_lane import calibration_camera
from kobuki_lane import main as node_main
from lanelib.camera import LECTURE_CAMERA, CalibrationError, load_calibration

# the layout ROS's camera_calibration writes (ost.yaml)
ROS_YAML = """image_width: 640
image_height: 480
camera_name: usb_cam
camera_matrix:
  rows: 3
  cols: 3
  data: [600.5, 0, 320.25, 0, 601.5, 240.75, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.1, 0.01, 0.001, -0.002, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [590, 0, 320, 0, 0, 590, 240, 0, 0, 0, 1, 0]
"""


def test_lecture_and_none():
    assert load_calibration('lecture') is LECTURE_CAMERA
    assert load_calibration('none') is None
    frame = np.zeros((10, 10, 3), np.uint8)
    assert calibration_camera(frame, None) is frame


def test_a_ros_camera_info_yaml_loads(tmp_path):
    path = tmp_path / 'camera.yaml'
    path.write_text(ROS_YAML)
    cam = load_calibration(str(path))
    assert cam.name == 'usb_cam' and cam.image_size == (640, 480)
    assert cam.matrix[0, 0] == 600.5 and cam.matrix[1, 2] == 240.75
    assert cam.distortion.tolist() == [-0.1, 0.01, 0.001, -0.002, 0]


def test_the_node_runs_with_a_yaml_calibration(tmp_path):
    path = tmp_path / 'camera.yaml'
    path.write_text(ROS_YAML)
    assert node_main(['--source', SAMPLES, '--dry-run', '--calibration', str(path),
                      '--quiet']) == 0


def test_scaling_to_another_resolution_scales_the_matrix():
    half = LECTURE_CAMERA.scaled_to(320, 240)
    assert half.matrix[0, 0] == pytest.approx(893.45537548 / 2)
    assert half.matrix[1, 2] == pytest.approx(196.40832355 / 2)
    assert LECTURE_CAMERA.scaled_to(640, 480) is LECTURE_CAMERA


@pytest.mark.parametrize('change, field', [
    (('camera_matrix:\n  rows: 3\n  cols: 3\n  data: [600.5, 0, 320.25, 0, 601.5, 240.75, 0, 0, 1]',
      'camera_matrix:\n  rows: 3\n  cols: 3\n  data: [600.5, 0, 320.25]'), "'camera_matrix.data'"),
    (('image_width: 640', 'image_width: wide'), "'image_width'"),
    (('distortion_model: plumb_bob', 'distortion_model: fisheye'), "'distortion_model'"),
    (('data: [-0.1, 0.01, 0.001, -0.002, 0]', 'data: [-0.1, 0.01]'),
     "'distortion_coefficients.data'"),
    (('camera_matrix:', 'camera_matrx:'), "'camera_matrix'"),
])
def test_malformed_yaml_names_the_field(tmp_path, change, field):
    path = tmp_path / 'bad.yaml'
    path.write_text(ROS_YAML.replace(*change))
    with pytest.raises(CalibrationError) as e:
        load_calibration(str(path))
    assert field in str(e.value) and str(path) in str(e.value)


def test_missing_or_non_yaml_file(tmp_path):
    with pytest.raises(CalibrationError, match='no such calibration file'):
        load_calibration(str(tmp_path / 'nope.yaml'))
    bad = tmp_path / 'x.yaml'
    bad.write_text('key: [unclosed')
    with pytest.raises(CalibrationError, match='cannot read as YAML'):
        load_calibration(str(bad))


def test_show_prints_the_cameras_field_of_view(capsys):
    assert main(['--show', 'lecture']) == 0
    out = capsys.readouterr().out
    assert 'fx=893.46' in out and 'field of view 39.4' in out


# ---------------------------------------------------------------- the chessboard tool

TRUE_K = np.array([[600.0, 0.0, 322.0], [0.0, 610.0, 238.0], [0.0, 0.0, 1.0]])
TRUE_DIST = np.array([-0.15, 0.04, 0.001, -0.0015, 0.0])
PATTERN, SQUARE = (9, 6), 0.025  # inner corners, metres


def board_texture(px=40):
    """The printed board: (cols+1) x (rows+1) squares of px pixels, with a white margin."""
    cols, rows = PATTERN[0] + 1, PATTERN[1] + 1
    squares = (np.indices((rows, cols)).sum(axis=0) % 2 == 0).astype(np.uint8) * 255
    board = np.kron(255 - squares, np.ones((px, px), np.uint8))
    return cv2.copyMakeBorder(board, px, px, px, px, cv2.BORDER_CONSTANT, value=255), px


def render_view(rvec, tvec, size=(640, 480)):
    """The board seen through TRUE_K and TRUE_DIST: each pixel's undistorted ray meets the
    board's plane (z = 0 in board coordinates, origin at the first inner corner)."""
    texture, px = board_texture()
    w, h = size
    uv = np.stack(np.meshgrid(np.arange(w), np.arange(h)), axis=-1).reshape(-1, 1, 2)
    xy = cv2.undistortPointsIter(uv.astype(np.float64), TRUE_K, TRUE_DIST, None, None,
                                 (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-9))
    r = cv2.Rodrigues(np.asarray(rvec, float))[0]
    plane = np.linalg.inv(np.column_stack([r[:, 0], r[:, 1], tvec]))
    pts = np.concatenate([xy.reshape(-1, 2), np.ones((w * h, 1))], axis=1) @ plane.T
    board_xy = pts[:, :2] / pts[:, 2:3]
    # board metres -> texture pixels: the first inner corner is 2 squares in from the edge
    tex = board_xy / SQUARE * px + 2 * px - 0.5
    mx = tex[:, 0].reshape(h, w).astype(np.float32)
    my = tex[:, 1].reshape(h, w).astype(np.float32)
    view = cv2.remap(texture, mx, my, cv2.INTER_AREA, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=128)
    return cv2.GaussianBlur(view, (3, 3), 0)


@pytest.fixture(scope='module')
def chessboards(tmp_path_factory):
    folder = tmp_path_factory.mktemp('calib')
    rng = np.random.default_rng(7)
    centre = np.array([(PATTERN[0] - 1) * SQUARE / 2, (PATTERN[1] - 1) * SQUARE / 2, 0.0])
    for i in range(14):
        rvec = np.radians(rng.uniform([-35, -35, -20], [35, 35, 20]))
        r = cv2.Rodrigues(rvec)[0]
        distance = rng.uniform(0.35, 0.6)
        shift = rng.uniform([-0.06, -0.04], [0.06, 0.04])
        tvec = np.array([shift[0], shift[1], distance]) - r @ centre
        cv2.imwrite(str(folder / f'view_{i:02d}.png'), render_view(rvec, tvec))
    cv2.imwrite(str(folder / 'view_99_blank.png'), np.full((480, 640), 128, np.uint8))
    return folder


def test_the_tool_recovers_the_intrinsics_within_1_percent(chessboards, tmp_path, capsys):
    out = tmp_path / 'camera.yaml'
    assert main(['--images', str(chessboards / '*.png'), '--pattern', '9x6', '--square',
                 str(SQUARE), '-o', str(out), '--name', 'rendered']) == 0
    printed = capsys.readouterr()
    assert 'not used:' in printed.err and 'view_99_blank.png' in printed.err
    rms = float(printed.out.split('RMS reprojection error ')[1].split()[0])
    assert rms < 0.3
    camera = load_calibration(str(out))  # the YAML the node loads
    k = camera.matrix
    for got, want in ((k[0, 0], 600.0), (k[1, 1], 610.0), (k[0, 2], 322.0), (k[1, 2], 238.0)):
        assert abs(got - want) / want < 0.01, (got, want)
    assert camera.image_size == (640, 480) and camera.name == 'rendered'
    import yaml

    doc = yaml.safe_load(out.read_text())
    for field in ('image_width', 'image_height', 'camera_name', 'camera_matrix',
                  'distortion_model', 'distortion_coefficients', 'rectification_matrix',
                  'projection_matrix'):
        assert field in doc
    assert doc['projection_matrix']['rows'] == 3 and doc['projection_matrix']['cols'] == 4
    assert node_main(['--source', SAMPLES, '--dry-run', '--quiet', '--calibration',
                      str(out)]) == 0


def test_the_tool_says_when_it_cannot_calibrate(tmp_path, capsys):
    cv2.imwrite(str(tmp_path / 'a.png'), np.full((48, 64), 100, np.uint8))
    assert main(['--images', str(tmp_path / '*.png'), '-o', str(tmp_path / 'c.yaml')]) == 2
    assert 'only 0 of 1 pictures show the whole 9x6 chessboard' in capsys.readouterr().err
    assert main(['--images', str(tmp_path / 'none*.jpg')]) == 2
    assert 'no files match' in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(['--images', 'x', '--pattern', '9by6'])


def node(*args):
    import subprocess
    import sys

    from helpers import NODE, REPO

    return subprocess.run([sys.executable, NODE, *args], cwd=REPO, capture_output=True,
                          text=True, timeout=120)


@pytest.mark.parametrize('change, said', [
    (('0, 0, 1]', '0, 0, 0]'), "'camera_matrix' is not a camera matrix"),  # singular
    (('[-0.1, 0.01,', '[50, 0.01,'), 'leaves'),  # k1 = 50: most of the frame empty
    (('camera_name: usb_cam', 'camera_name: [usb'), 'cannot read as YAML'),  # a syntax error
])
def test_a_camera_yaml_that_would_ruin_every_frame_is_refused_in_one_line(tmp_path, change,
                                                                         said):
    """Before: a singular matrix or k1 = 50 loaded, then every frame failed in OpenCV (exit 1
    after 5 frames); a YAML syntax error printed the whole usage before its message."""
    path = tmp_path / 'camera.yaml'
    path.write_text(ROS_YAML.replace(*change))
    proc = node('--source', SAMPLES, '--dry-run', '--calibration', str(path))
    assert proc.returncode == 2 and said in proc.stderr, proc.stderr
    assert 'usage:' not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert 'Traceback' not in proc.stderr


def test_a_calibration_for_another_aspect_ratio_is_refused_before_the_run(tmp_path):
    """Before: a 1280x720 calibration was silently stretched onto 640x480 frames."""
    path = tmp_path / 'wide.yaml'
    path.write_text(ROS_YAML.replace('image_width: 640', 'image_width: 1280')
                    .replace('image_height: 480', 'image_height: 720'))
    decisions = tmp_path / 'd.jsonl'
    proc = node('--source', SAMPLES, '--dry-run', '--calibration', str(path), '--decisions',
                str(decisions))
    assert proc.returncode == 2 and 'is for 1280x720 frames, these are 640x480' in proc.stderr
    assert not decisions.exists()
    same_shape = tmp_path / 'half.yaml'  # 320x240: the same 4:3, scaled as before
    same_shape.write_text(ROS_YAML.replace('image_width: 640', 'image_width: 320')
                          .replace('image_height: 480', 'image_height: 240'))
    assert node('--source', SAMPLES, '--dry-run', '--calibration', str(same_shape),
                '--quiet').returncode == 0


def test_a_huge_first_frame_is_said_to_be_slow(tmp_path):
    big = tmp_path / 'big'
    big.mkdir()
    cv2.imwrite(str(big / 'a.png'), np.full((2400, 3200, 3), 90, np.uint8))
    proc = node('--source', str(big), '--dry-run', '--calibration', 'none', '--quiet')
    assert proc.returncode == 0 and 'frames are 3200x2400 (8 megapixels)' in proc.stderr


def test_calibrating_from_copies_of_one_picture_is_refused(chessboards, tmp_path, capsys):
    """Five copies of one view do not pin the camera down (before: fx 670, fy 449, k3 57.9
    written without a word)."""
    import shutil

    one = sorted(chessboards.glob('*.png'))[0]
    copies = tmp_path / 'copies'
    copies.mkdir()
    for i in range(5):
        shutil.copy(one, copies / f'{i}.png')
    out = tmp_path / 'camera.yaml'
    assert main(['--images', str(copies / '*.png'), '--pattern', '9x6', '--square', '0.025',
                 '-o', str(out)]) == 2
    err = capsys.readouterr().err
    assert 'one viewpoint' in err and not out.exists()
