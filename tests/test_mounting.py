"""calibration.py --ground and --mounting: the camera's mounting measured from a chessboard on
the floor, rendered by the simulator at a known mounting."""

import os
import subprocess
import sys

import cv2
import numpy as np
import pytest
from helpers import NODE, REPO, SAMPLES, read_jsonl

import simulate
from calibration import main as calibration_main
from kobuki_lane import main as node_main
from lanelib.camera import DUCKIEBOT_CAMERA, DUCKIEBOT_PROJECTION, LECTURE_CAMERA, camera_info_yaml
from lanelib.geometry import (
    Mounting,
    floor_to_pixels,
    pixels_to_floor,
    ray_directions,
    rays_to_floor,
    repitched,
)
from lanelib.mounting import (
    HOMOGRAPHY_ERROR_PX,
    MountingError,
    homography_mounting,
    read_mounting,
    solve_mounting,
)
from lanelib.sim.world import chessboard_view

# (camera, true mounting, board pattern, square [m], nearest corners ahead [m])
CASES = {
    'level webcam': (LECTURE_CAMERA, Mounting(0.20, 0.0, 0.10), (7, 5), 0.05, 0.8),
    'webcam pitched and rolled': (LECTURE_CAMERA, Mounting(0.26, 4.0, 0.07, 1.5), (7, 5), 0.05,
                                  0.75),
    'pitched wide camera': (DUCKIEBOT_CAMERA, Mounting(0.10, 20.0, 0.05), (9, 6), 0.025, 0.2),
    'wide camera, steeper': (DUCKIEBOT_CAMERA, Mounting(0.12, 27.0, 0.03, -2.0), (9, 6), 0.025,
                             0.2),
}


@pytest.mark.parametrize('case', CASES)
def test_the_board_gives_back_a_known_mounting(case):
    camera, true, pattern, square, ahead = CASES[case]
    image = chessboard_view(camera, true, pattern, square, ahead, noise=3.0, seed=1)
    result = solve_mounting(image, camera, pattern, square, ahead)
    m = result.mounting
    assert m.height == pytest.approx(true.height, abs=0.005)
    assert m.pitch_deg == pytest.approx(true.pitch_deg, abs=0.5)
    assert m.roll_deg == pytest.approx(true.roll_deg, abs=0.5)
    assert m.forward == pytest.approx(true.forward, abs=0.01)
    assert abs(result.yaw_deg) < 0.5 and abs(result.lateral) < 0.005
    assert result.error_px < 0.5


def test_roll_turns_the_picture_about_the_optical_axis():
    """A camera rolled with its right side lower sees the floor's horizon rise to the right,
    and floor points go to pixels and back unchanged."""
    m = Mounting(0.2, 10.0, 0.1, 5.0)
    matrix = LECTURE_CAMERA.matrix
    u, v, ok = floor_to_pixels(np.array([1.0, 1.0]), np.array([0.3, -0.3]), matrix, m)
    assert ok.all() and v[0] > v[1]  # the left point lower in the picture: horizon rises right
    x, y, hit = pixels_to_floor(np.stack([u, v], axis=1), matrix, m)
    assert hit.all() and np.allclose(x, 1.0) and np.allclose(y, [0.3, -0.3])
    level = Mounting(0.2, 10.0, 0.1)
    assert np.allclose(floor_to_pixels(1.0, 0.3, matrix, level)[:2],
                       floor_to_pixels(1.0, 0.3, matrix, Mounting(0.2, 10.0, 0.1, 0.0))[:2])


def test_floor_points_lie_where_the_pixels_rays_meet_the_floor():
    """rays_to_floor, worked out a component at a time, gives exactly the floor points of
    ray_directions' rays (the lens's height along each ray, over its drop), and marks the rays
    that never come down."""
    m = Mounting(0.2, 10.0, 0.1, 5.0)
    rng = np.random.default_rng(3)
    xn, yn = rng.uniform(-1.0, 1.0, 500), rng.uniform(-0.6, 0.8, 500)
    x, y, ok = rays_to_floor(xn, yn, m)
    d = ray_directions(xn, yn, m.pitch_deg, m.roll_deg)
    down = -d[:, 2]
    assert np.array_equal(ok, down > 1e-9) and 0 < ok.sum() < len(ok)
    t = m.height / down[ok]
    assert np.array_equal(x[ok], m.forward + t * d[ok, 0])
    assert np.array_equal(y[ok], t * d[ok, 1])


@pytest.fixture(scope='module')
def wide_board(tmp_path_factory):
    """What simulate.py --chessboard draws for the duckietown world's camera, and the YAML
    calibration.py --ground makes of it."""
    folder = tmp_path_factory.mktemp('ground')
    picture, yaml = folder / 'board.png', folder / 'mounting.yaml'
    assert simulate.main(['--world', 'duckietown', '--chessboard', str(picture), '--pattern',
                          '9x6', '--square', '0.025', '--board-ahead', '0.2']) == 0
    assert calibration_main(['--ground', str(picture), '--pattern', '9x6', '--square', '0.025',
                             '--board-ahead', '0.2', '--calibration', 'duckiebot', '-o',
                             str(yaml)]) == 0
    return picture, yaml


@pytest.mark.parametrize('turn', [-4.0, 2.5])
def test_repitched_moves_floor_points_to_where_a_camera_pitched_further_sees_them(turn):
    # floor points seen by a camera pitched 19.15 + turn degrees, found with a mounting that
    # says 19.15: repitched puts them back where they are
    given = Mounting(0.108, 19.15, 0.066)
    camera = Mounting(0.108, 19.15 + turn, 0.066)
    matrix = np.array([[300.0, 0, 320], [0, 300.0, 240], [0, 0, 1]])
    x, y = np.array([0.12, 0.3, 0.55, 0.8]), np.array([0.1, -0.12, 0.05, 0.2])
    u, v, ok = floor_to_pixels(x, y, matrix, camera)
    found = pixels_to_floor(np.stack([u, v], axis=-1), matrix, given)
    assert ok.all() and np.abs(found[0] - x).max() > 0.03  # found elsewhere
    back = repitched(found[0], found[1], given, turn)
    assert np.allclose(back[0], x, atol=1e-9) and np.allclose(back[1], y, atol=1e-9)


def test_the_tool_writes_the_mounting_the_node_reads(wide_board):
    _, yaml = wide_board
    m = read_mounting(str(yaml))
    assert m.height == pytest.approx(0.10, abs=0.005)
    assert m.pitch_deg == pytest.approx(20.0, abs=0.5)
    assert m.forward == pytest.approx(0.05, abs=0.01)
    assert 'reprojection_error_px' in yaml.read_text()


def test_the_simulator_drives_with_the_measured_mounting(wide_board, tmp_path):
    _, yaml = wide_board
    out = tmp_path / 'run.json'
    status = simulate.main(['--track', 's_bend', '--world', 'duckietown', '--controller',
                            'improved', '--mounting', str(yaml), '--json', str(out)])
    import json

    result = json.loads(out.read_text())
    assert status == 0 and result['completed'] and result['departures'] == 0
    assert result['rms_offset_m'] <= 0.03


def test_the_node_takes_the_mounting_file_and_flags_override_it(wide_board, tmp_path):
    _, yaml = wide_board
    out = tmp_path / 'd.jsonl'
    argv = ['--source', SAMPLES, '--dry-run', '--controller', 'improved', '--quiet']
    assert node_main([*argv, '--mounting', str(yaml), '--decisions', str(out)]) == 0
    assert len(read_jsonl(out)) == len(os.listdir(SAMPLES))
    from kobuki_lane import LaneParams, build_parser
    from lanelib.node import settings_from

    def improved(*extra):
        args = build_parser().parse_args([*argv, '--mounting', str(yaml), *extra])
        params = dict(extra_params)
        return settings_from(args, lambda name, default: params.get(name, default),
                             LaneParams)[3]

    extra_params = {}
    p = improved()
    assert p.camera_height == pytest.approx(0.10, abs=0.005)
    assert p.camera_pitch == pytest.approx(20.0, abs=0.5)
    assert improved('--camera-pitch', '12').camera_pitch == 12.0  # a flag outranks the file
    extra_params['~camera_height'] = 0.3  # and so does a private parameter
    assert improved().camera_height == 0.3


def cli(*args):
    return subprocess.run([sys.executable, *args], cwd=REPO, capture_output=True, text=True,
                          timeout=120)


def test_the_tool_refuses_what_it_cannot_use(wide_board, tmp_path):
    picture, _ = wide_board
    out = tmp_path / 'm.yaml'
    blank = tmp_path / 'blank.png'
    cv2.imwrite(str(blank), np.full((480, 640, 3), 120, np.uint8))
    common = ['--square', '0.025', '--board-ahead', '0.2', '--calibration', 'duckiebot', '-o',
              str(out)]
    cases = [
        (['--ground', str(blank), '--pattern', '9x6'], 'no 9x6 chessboard found'),
        (['--ground', str(picture), '--pattern', '6x9'], 'the board lies the wrong way round'),
        (['--ground', str(picture), '--pattern', '9x6', '--calibration', 'lecture'],
         'fits the picture badly'),
        (['--ground', str(picture), '--pattern', '9x6', '--calibration', 'none'],
         'needs the intrinsics'),
        (['--ground', str(tmp_path / 'missing.png'), '--pattern', '9x6'],
         'is not a readable image'),
    ]
    for argv, message in cases:
        proc = cli('calibration.py', *common, *argv)
        assert proc.returncode == 2, (argv, proc.stderr)
        assert message in proc.stderr and 'Traceback' not in proc.stderr, (argv, proc.stderr)
        assert not out.exists()
    proc = cli('calibration.py', '--ground', str(picture), '--pattern', '9x6', '--square',
               '0.025', '-o', str(out))
    assert proc.returncode == 2 and '--board-ahead' in proc.stderr


def test_a_fit_no_kobuki_camera_could_have_is_refused():
    """A picture upside down, or a board said to be four times as big and nearer than it is:
    the poses that fit are not on a Kobuki (rolled 180 degrees; 2.75 m behind it)."""
    camera, true, pattern, square, ahead = CASES['level webcam']
    image = chessboard_view(camera, true, pattern, square, ahead)
    with pytest.raises(MountingError, match='no camera on a Kobuki has'):
        solve_mounting(cv2.rotate(image, cv2.ROTATE_180), camera, pattern, square, ahead)
    with pytest.raises(MountingError, match='behind the robot.s centre'):
        solve_mounting(image, camera, pattern, square * 4, 0.05)


@pytest.mark.parametrize('text, field', [
    ('height: 0.2\npitch_deg: 3\nroll_deg: 0\n', 'forward'),
    ('height: 0.2\npitch_deg: 3\nroll_deg: 0\nforward: 0.1\nyaw: 2\n', 'yaw'),
    ('height: -0.2\npitch_deg: 3\nroll_deg: 0\nforward: 0.1\n', 'height'),
    ('height: 0.2\npitch_deg: high\nroll_deg: 0\nforward: 0.1\n', 'pitch_deg'),
    ('height: 0.2\npitch_deg: [\n', 'cannot read'),
])
def test_a_bad_mounting_file_names_the_field(tmp_path, text, field):
    path = tmp_path / 'mounting.yaml'
    path.write_text(text)
    with pytest.raises(MountingError, match=field):
        read_mounting(str(path))
    proc = cli(NODE, '--source', SAMPLES, '--dry-run', '--controller', 'improved', '--mounting',
               str(path))
    assert proc.returncode == 2 and field in proc.stderr and 'Traceback' not in proc.stderr


def floor_homography(matrix, mounting):
    """Duckietown's extrinsic calibration of a camera at `mounting`, built independently of the
    tool: the rectified image's pixels (camera matrix `matrix`) of a floor grid, and the
    homography OpenCV fits from them to the floor."""
    x, y = np.meshgrid(np.linspace(0.15, 0.6, 6), np.linspace(-0.2, 0.2, 5))
    u, v, ok = floor_to_pixels(x.ravel(), y.ravel(), matrix, mounting)
    assert ok.all()
    h, _ = cv2.findHomography(np.stack([u, v], axis=1), np.stack([x.ravel(), y.ravel()], axis=1))
    return h / h[2, 2]


@pytest.mark.parametrize('true', [Mounting(0.108, 19.15, 0.066), Mounting(0.12, 25.0, 0.04, 3.0),
                                  Mounting(0.20, 4.0, 0.10, -1.5)])
def test_a_duckietown_homography_gives_back_its_mounting(true):
    h = floor_homography(DUCKIEBOT_PROJECTION, true)
    result = homography_mounting(h.ravel().tolist(), DUCKIEBOT_PROJECTION, (640, 480))
    m = result.mounting
    assert m.height == pytest.approx(true.height, abs=1e-6)
    assert m.pitch_deg == pytest.approx(true.pitch_deg, abs=1e-4)
    assert m.roll_deg == pytest.approx(true.roll_deg, abs=1e-4)
    assert m.forward == pytest.approx(true.forward, abs=1e-6)
    assert abs(result.yaw_deg) < 1e-4 and abs(result.lateral) < 1e-6
    assert result.error_px < 1e-3


def test_the_newer_layout_in_image_coordinates_from_0_to_1_is_read_too(tmp_path):
    # Duckietown's version 2 files (dt_computer_vision's HomographyToolkit): the same
    # homography on coordinates divided by the image's size less one
    true = Mounting(0.11, 22.0, 0.07, 1.0)
    h = floor_homography(DUCKIEBOT_PROJECTION, true) @ np.diag([639.0, 479.0, 1.0])
    made = tmp_path / 'robot.yaml'
    made.write_text(f"version: '2'\nhomography: {(h / h[2, 2]).tolist()}\n")
    out = tmp_path / 'mounting.yaml'
    assert calibration_main(['--homography', str(made), '-o', str(out)]) == 0
    m = read_mounting(str(out))
    assert (m.height, m.forward) == pytest.approx((true.height, true.forward), abs=1e-4)
    assert (m.pitch_deg, m.roll_deg) == pytest.approx((true.pitch_deg, true.roll_deg), abs=1e-2)
    made.write_text(f'homography: {(h / h[2, 2]).tolist()}\n')  # read as pixels: refused
    assert calibration_main(['--homography', str(made), '-o', str(out), '--force']) == 2


def test_a_homography_read_with_another_camera_matrix_is_refused(tmp_path):
    # made on the image rectified with the projection matrix (as dt-core does), read with the
    # camera matrix: no camera mounting gives it
    h = floor_homography(DUCKIEBOT_PROJECTION, Mounting(0.108, 21.0, 0.066))
    assert homography_mounting(h, DUCKIEBOT_CAMERA.matrix, (640, 480)).error_px > \
        HOMOGRAPHY_ERROR_PX
    made = tmp_path / 'robot.yaml'
    made.write_text(f'homography: {h.ravel().tolist()}\n')
    intrinsics = tmp_path / 'camera.yaml'  # its projection is its camera matrix
    intrinsics.write_text(camera_info_yaml(DUCKIEBOT_CAMERA))
    out = tmp_path / 'mounting.yaml'
    assert calibration_main(['--homography', str(made), '--calibration', str(intrinsics),
                             '-o', str(out)]) == 2
    assert not out.exists()
    assert calibration_main(['--homography', str(made), '-o', str(out)]) == 0
    assert read_mounting(str(out)).pitch_deg == pytest.approx(21.0, abs=1e-3)
    # the robot's own camera_intrinsic YAML: its projection_matrix is the one read
    projection = np.hstack([DUCKIEBOT_PROJECTION, np.zeros((3, 1))]).ravel().tolist()
    intrinsics.write_text(camera_info_yaml(DUCKIEBOT_CAMERA).split('projection_matrix')[0] +
                          f'projection_matrix:\n  rows: 3\n  cols: 4\n  data: {projection}\n')
    assert calibration_main(['--homography', str(made), '--calibration', str(intrinsics),
                             '-o', str(out), '--force']) == 0
    assert read_mounting(str(out)).pitch_deg == pytest.approx(21.0, abs=1e-3)


def test_the_tool_reads_duckietowns_default_homography(tmp_path, capsys):
    # duckiefleet's calibrations/camera_extrinsic/default.yaml, read with the default
    # intrinsics' projection matrix; its horizon lies at row 119.5 of the 480 (in the
    # image's middle column), 25.4 degrees above that matrix's centre row 240.0
    made = tmp_path / 'default.yaml'
    made.write_text('homography: [-4.89775e-05, -0.0002150858, -0.1818273, 0.00099274, '
                    '1.202336e-06, -0.3280241, -0.0004281805, -0.007185673, 1]\n')
    out = tmp_path / 'mounting.yaml'
    assert calibration_main(['--homography', str(made), '-o', str(out)]) == 0
    m = read_mounting(str(out))
    assert m.pitch_deg == pytest.approx(25.3, abs=0.15)
    assert 0.09 < m.height < 0.12 and 0.05 < m.forward < 0.1
    said = capsys.readouterr()
    assert 'px apart' in said.out and 'looking 2.1 deg left' in said.err


def test_the_visual_control_mounting_is_its_homography_read_by_the_tool(tmp_path):
    # tools/robots/visual_control_mounting.yaml (tools.evaluate_real's) is what the tool makes
    # of the published homography beside it, and the node reads it
    robots = os.path.join(REPO, 'tools', 'robots')
    out = tmp_path / 'mounting.yaml'
    made = os.path.join(robots, 'visual_control_homography.yaml')
    assert calibration_main(['--homography', made, '-o', str(out)]) == 0
    kept = read_mounting(os.path.join(robots, 'visual_control_mounting.yaml'))
    assert read_mounting(str(out)) == kept


@pytest.mark.parametrize('text, says', [
    ('homography: [1, 2, 3]\n', '9 finite numbers'),
    ('homography: [1, 0, 0, 0, 1, 0, 0, 0, 0]\n', 'singular'),
    ('camera_matrix: {}\n', "no field 'homography'"),
    # a robot's in dt-core's log-calib-config (cookie.yaml): the floor seen from below
    ('homography: [3.141844e-05, -0.003669246, 0.6774592, -0.0009989715, -1.831895e-05, '
     '0.3409429, 6.832473e-05, -0.007933678, 1]\n', 'below the floor'),
])
def test_a_homography_file_the_tool_cannot_use_is_refused(tmp_path, capsys, text, says):
    made = tmp_path / 'robot.yaml'
    made.write_text(text)
    out = tmp_path / 'mounting.yaml'
    assert calibration_main(['--homography', str(made), '-o', str(out)]) == 2
    assert says in capsys.readouterr().err and not out.exists()
