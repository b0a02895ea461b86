"""calibration.py: the lecture's camera, ROS camera_info YAML files, and their errors."""

import numpy as np
import pytest
from conftest import SAMPLES

from calibration import LECTURE_CAMERA, CalibrationError, calibration_camera, load_calibration, main
from kobuki_lane import main as node_main

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
