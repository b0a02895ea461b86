"""Bad input that lost data, gave wrong results or a traceback: each refused in one line (exit
status 2) or used as well as it can be, with a word (issue 24, cases 4 to 6 and 9 to 12)."""

import json
import os
import subprocess
import sys

import cv2
import numpy as np
import pytest
from helpers import NODE, REPO, SAMPLES, read_jsonl

import simulate
from kobuki_lane import LaneFollower, LaneParams, LectureRule
from lanelib.bags import BagError, BagRecorder
from lanelib.camera import Camera, camera_info_yaml, read_camera_info
from lanelib.outputs import Outputs
from lanelib.robot import ODOM_TOPIC, STOP
from lanelib.rospy_standin import Odometry as OdometryMessage
from lanelib.rospy_standin import SimClock, StandInRospy, Twist
from lanelib.safety import SafeBase
from lanelib.sim.simulator import TrackSimulator, odometry_message
from lanelib.sim.tracks import load_track
from lanelib.sources import FrameCheck
from lanelib.topics import Odometry

CALIBRATION_YAML = """image_width: 640
image_height: 480
camera_name: usb_cam
camera_matrix: {rows: 3, cols: 3, data: [600.5, 0, 320.25, 0, 601.5, 240.75, 0, 0, 1]}
distortion_model: plumb_bob
distortion_coefficients: {rows: 1, cols: 5, data: [-0.1, 0.01, 0.001, -0.002, 0]}
"""


def run(program, *args, timeout=120):
    return subprocess.run([sys.executable, program, *args], cwd=REPO, capture_output=True,
                          text=True, timeout=timeout)


def one_line_error(proc, said):
    """Exit status 2, `said` in a one-line message, no traceback."""
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert said in proc.stderr, proc.stderr
    assert 'Traceback' not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


# ---------------------------------------------------------------- case 4: odometry

def published(ros, topic='/mobile_base/commands/velocity'):
    return [m for _, t, m in ros.published if t == topic]


def test_odometry_not_finite_or_jumping_is_refused_and_a_new_origin_that_holds_is_taken():
    ros = StandInRospy(SimClock(), quiet=True)
    odom = Odometry(ros, ODOM_TOPIC, msg_type=OdometryMessage)
    pub = ros.Publisher(ODOM_TOPIC, OdometryMessage, queue_size=10)

    def at(t, x, y=0.0, yaw=0.0):
        ros.clock.sleep(t - ros.get_time())
        pub.publish(odometry_message(x, y, yaw))
        return odom.pose(t)

    assert at(0.0, 1.0) == (1.0, 0.0, 0.0)
    assert at(0.1, 1.02) == (1.02, 0.0, 0.0)
    assert at(0.2, float('nan')) == (1.02, 0.0, 0.0)  # refused: the last good one
    assert at(0.3, 1e6) == (1.02, 0.0, 0.0)  # refused: 1e6 m in 0.2 s
    assert at(0.4, 1.06) == (1.06, 0.0, 0.0)
    assert odom.refused == 2
    assert sum('odometry on /odom refused' in text for _, text in ros.log_lines) == 1  # once
    # a reset of the odometry's origin: refused at first, taken once it has held for 0.5 s
    assert at(0.5, 0.0) == (1.06, 0.0, 0.0)
    assert at(0.75, 0.01) == (1.06, 0.0, 0.0)
    assert at(1.0, 0.02) == (0.02, 0.0, 0.0)


def test_a_second_of_nan_odometry_and_a_1e6_m_jump_with_the_lane_in_view_change_nothing(
        tmp_path):
    """Before: about 1 s of NaN odometry made the robot stop, turn in place about 50 degrees
    (search), stop, then drive on; a jump of 1e6 m gave three frames at -1.5 rad/s and a
    search; the records held NaN, which is not JSON."""
    spec = load_track('oval')
    ros = StandInRospy(SimClock(), quiet=True)
    sim = TrackSimulator(spec, ros, seed=0, time_limit=14.0, odometry=True)
    faulty = ros.Publisher('/faulty_odom', OdometryMessage, queue_size=10)

    def relay(msg):
        t = ros.get_time()
        if 4.0 <= t < 5.0:
            msg = odometry_message(float('nan'), 0.0, 0.0)
        elif 8.0 <= t < 8.2:
            msg = odometry_message(1e6, 0.0, 0.0)
        faulty.publish(msg)

    ros.Subscriber(ODOM_TOPIC, OdometryMessage, relay)
    odom = Odometry(ros, '/faulty_odom', msg_type=OdometryMessage)
    p = LaneParams()
    ctl = simulate.controller_for('improved', spec, p, odometry=odom)
    records = tmp_path / 'd.jsonl'
    with open(records, 'w') as decisions:
        LaneFollower(ros, sim, ctl, SafeBase(ros, Twist), Outputs(p, decisions=decisions),
                     p.rate).run()
    lines = records.read_text().splitlines()
    rows = [json.loads(line, parse_constant=lambda c: pytest.fail(f'{c} in a record'))
            for line in lines]
    assert len(rows) > 50
    assert {r['decision'] for r in rows} <= {'left', 'right', 'straight'}
    assert all(r['linear_x'] > 0 for r in rows)  # never stopped, never searched
    assert max(abs(r['angular_z']) for r in rows) < 1.0
    assert sim.departure_points == []
    assert any('odometry on /faulty_odom refused' in text for _, text in ros.log_lines)


# ---------------------------------------------------------------- case 6: inputs kept

@pytest.fixture
def board(tmp_path):
    picture = tmp_path / 'board.png'
    assert simulate.main(['--world', 'duckietown', '--chessboard', str(picture), '--pattern',
                          '9x6', '--square', '0.025', '--board-ahead', '0.2']) == 0
    return picture


def test_calibration_py_never_writes_over_its_input_nor_an_existing_file(tmp_path, board):
    """Before: -o onto the --calibration file replaced the intrinsics with a mounting; onto
    the picture, the picture; onto one of the --images, that picture. All exit 0."""
    camera = tmp_path / 'cam.yaml'
    camera.write_text(CALIBRATION_YAML)
    kept = {path: path.read_bytes() for path in (camera, board)}
    ground = ['calibration.py', '--ground', str(board), '--pattern', '9x6', '--square',
              '0.025', '--board-ahead', '0.2', '--calibration', 'duckiebot']
    one_line_error(run(*ground, '--calibration', str(camera), '-o', str(camera)),
                   'is the --calibration file itself')
    one_line_error(run(*ground, '-o', str(board)), 'is the --ground picture itself')
    one_line_error(run('calibration.py', '--images', str(tmp_path / '*.png'), '-o', str(board)),
                   'is the --images picture itself')
    existing = tmp_path / 'mounting.yaml'
    existing.write_text('# mine\n')
    one_line_error(run(*ground, '-o', str(existing)), 'exists already')
    assert existing.read_text() == '# mine\n'
    assert {path: path.read_bytes() for path in kept} == kept
    written = run(*ground, '-o', str(existing), '--force')
    assert written.returncode == 0, written.stderr
    assert 'pitch_deg' in existing.read_text()


def test_simulate_py_never_writes_over_its_input_nor_an_existing_file(tmp_path):
    track = tmp_path / 'my.json'
    track.write_text(json.dumps(dict(lane_width=0.35, tape_width=0.03,
                                     segments=[{'straight': 1.0}])))
    mounting = tmp_path / 'm.yaml'
    mounting.write_text('height: 0.2\npitch_deg: 0\nroll_deg: 0\nforward: 0.1\n')
    kept = {path: path.read_text() for path in (track, mounting)}
    one_line_error(run('simulate.py', '--track', str(track), '--json', str(track)),
                   'is the --track file itself')
    one_line_error(run('simulate.py', '--mounting', str(mounting), '--controller', 'improved',
                       '--json', str(mounting)), 'is the --mounting file itself')
    out = tmp_path / 'out.json'
    out.write_text('{}')
    one_line_error(run('simulate.py', '--track', str(track), '--json', str(out)),
                   'exists already')
    assert {path: path.read_text() for path in kept} == kept and out.read_text() == '{}'


# ---------------------------------------------------------------- case 10: every frame's size

def test_a_frame_of_another_shape_in_a_folder_is_not_acted_on(tmp_path):
    """Before: the size was checked on the first frame only; a 1280x720 frame at the end of a
    640x480 folder with a 640x480 calibration was stretched and decided "right", exit 0."""
    folder = tmp_path / 'frames'
    folder.mkdir()
    names = sorted(os.listdir(SAMPLES))[:4]
    for name in names:
        os.symlink(os.path.join(SAMPLES, name), folder / name)
    wide = cv2.resize(cv2.imread(os.path.join(SAMPLES, names[0])), (1280, 720))
    cv2.imwrite(str(folder / 'zz_wide.png'), wide)
    calibration = tmp_path / 'cam.yaml'
    calibration.write_text(CALIBRATION_YAML)
    out = tmp_path / 'd.jsonl'
    proc = run(NODE, '--source', str(folder), '--dry-run', '--calibration', str(calibration),
               '--decisions', str(out))
    assert proc.returncode == 1, proc.stderr
    assert 'is for 640x480 frames, these are 1280x720' in proc.stderr
    assert '1 of 5 frames could not be used' in proc.stderr
    records = read_jsonl(out)
    assert [r['decision'] for r in records][-1] == 'none' and 'error' in records[-1]
    assert all('error' not in r for r in records[:-1])


def test_a_live_camera_that_changes_its_size_is_stopped_for():
    """A camera switching to 1280x720 mid-run, with a 640x480 calibration: every frame of the
    new size is answered with a stop, and after max_errors of them the run ends (exit 1)."""
    small, wide = np.full((480, 640, 3), 90, np.uint8), np.full((720, 1280, 3), 90, np.uint8)

    class Switching:
        name, live, total, skipped = 'camera', True, None, 0

        def __init__(self):
            self.frames = [small] * 3 + [wide] * 10

        def read(self):
            return (True, self.frames.pop(0), 0) if self.frames else (False, None, None)

        def release(self):
            pass

    calibration = Camera('cam', np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]]),
                         np.zeros(5), (640, 480))
    ros = StandInRospy(SimClock(), quiet=True)
    p = LaneParams()
    follower = LaneFollower(ros, Switching(), LectureRule(p, calibration), SafeBase(ros, Twist),
                            rate=p.rate, check=FrameCheck(calibration, ros.logwarn))
    assert follower.run() == 'pipeline errors'
    twists = published(ros)
    assert all((t.linear.x, t.angular.z) == (STOP.linear_x, STOP.angular_z) for t in twists[3:])
    assert follower.frames == 3 + follower.base.safety.max_errors
    assert 'is for 640x480 frames, these are 1280x720' in follower.last_error


# ---------------------------------------------------------------- case 11: no tracebacks

def test_calibration_topic_without_a_topic_is_a_usage_error():
    one_line_error(run(NODE, '--source', SAMPLES, '--calibration', 'topic'),
                   '--calibration topic reads the camera_info beside a ROS image topic, live '
                   'or in a bag')


def test_a_picture_too_small_for_a_chessboard_is_said_so(tmp_path):
    tiny = tmp_path / 'tiny.png'
    cv2.imwrite(str(tiny), np.zeros((12, 16, 3), np.uint8))
    one_line_error(run('calibration.py', '--ground', str(tiny), '--board-ahead', '0.8', '-o',
                       str(tmp_path / 'm.yaml')), 'no 9x6 chessboard found')
    for i in range(3):
        cv2.imwrite(str(tmp_path / f'tiny{i}.png'), np.zeros((12, 16, 3), np.uint8))
    one_line_error(run('calibration.py', '--images', str(tmp_path / 'tiny*.png'), '-o',
                       str(tmp_path / 'c.yaml')), 'show the whole 9x6 chessboard')


def test_a_private_parameter_that_is_not_yaml_is_a_usage_error():
    one_line_error(run(NODE, '--source', SAMPLES, '--dry-run', '_threshold:=['),
                   "'_threshold:=[': the value after := is not YAML")


def test_two_runs_given_one_bag_do_not_share_it(tmp_path, monkeypatch):
    """Before: two runs started together both found no bag there, and the second one's writer
    then failed with a WriterError traceback."""
    path = str(tmp_path / 'one.bag')
    first = BagRecorder(path, '/mobile_base/commands/velocity')
    monkeypatch.setattr('lanelib.bags.os.path.exists', lambda path: False)  # as in the race
    try:
        with pytest.raises(BagError, match='exists already'):
            BagRecorder(path, '/mobile_base/commands/velocity')
    finally:
        monkeypatch.undo()
        first.close()


def test_the_tools_refuse_bad_numbers_and_labels_before_their_work(tmp_path):
    for args, said in ((['--repeats', '0'], "'0' is not a whole number from 1"),
                       (['--soak', '10'], "'10' is not a whole number from 1,000")):
        proc = subprocess.run([sys.executable, '-m', 'tools.bench', *args], cwd=REPO,
                              capture_output=True, text=True, timeout=60)
        assert proc.returncode == 2 and said in proc.stderr and 'Traceback' not in proc.stderr
    labels = tmp_path / 'labels'
    labels.mkdir()
    (labels / 'labels.csv').write_text('file,confidence,scene\na.jpg,high,x\n')
    proc = subprocess.run([sys.executable, '-m', 'tools.evaluate_real', str(labels)], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    one_line_error(proc, 'no column expected_steering')
    (labels / 'labels.csv').write_text('file,expected_steering,confidence,scene\n'
                                       'a.jpg,left,high,x\n')
    proc = subprocess.run([sys.executable, '-m', 'tools.evaluate_real', str(labels)], cwd=REPO,
                          capture_output=True, text=True, timeout=60)
    one_line_error(proc, "'a.jpg' is not a file")


# ---------------------------------------------------------------- case 12: smaller things

@pytest.mark.parametrize('source', ['ros:/', 'ros://x', 'ros:/a b'])
def test_a_topic_that_is_no_ros_name_is_a_usage_error(source):
    one_line_error(run(NODE, '--source', source, '--dry-run'), 'does not name a ROS topic')


@pytest.mark.parametrize('args, said', [
    (['--lane', 'duckietown'], "--lane sets the improved controller, but the controller is "
                               "the lecture's: add --controller improved"),
    (['--mounting', '/nonexistent.yaml'], '--mounting sets the improved controller'),
    (['--controller', 'improved', '--camera-pitch', '90'], 'camera_pitch = 90.0 is out of '
                                                          'range (-45 to 80)'),
    (['--controller', 'improved', '--camera-height', '1000'], 'camera_height = 1000.0 is out '
                                                             'of range'),
])
def test_the_improved_controllers_options_are_not_ignored_nor_out_of_bounds(args, said):
    one_line_error(run(NODE, '--source', SAMPLES, '--dry-run', *args), said)


def test_an_improved_controllers_private_parameter_with_the_lecture_is_said_to_be_ignored():
    proc = run(NODE, '--source', SAMPLES, '--dry-run', '--quiet', '_lane:=duckietown')
    assert proc.returncode == 0
    assert '~lane set the improved controller' in proc.stderr and 'ignored' in proc.stderr


def test_numbers_written_1e3_are_numbers(tmp_path):
    """Before: YAML 1.1 made 1e-05 in a JSON track and _rate:=1e3 text, "not a number"."""
    track = tmp_path / 't.json'
    track.write_text('{"lane_width": 3.5e-1, "tape_width": 3e-2, "segments": '
                     '[{"straight": 1e0}]}')
    spec = load_track(str(track))
    assert spec.track.lane_width == 0.35 and spec.track.length == pytest.approx(1.0)
    out = tmp_path / 'd.jsonl'
    proc = run(NODE, '--source', SAMPLES, '--dry-run', '--quiet', '--decisions', str(out),
               '_rate:=1e1')
    assert proc.returncode == 0, proc.stderr
    times = [r['t'] for r in read_jsonl(out)]
    assert times[1] - times[0] == pytest.approx(0.1)


def test_a_camera_name_with_a_colon_reads_back(tmp_path):
    """Before: calibration.py --name 'cam: left' wrote a YAML it could not read back."""
    path = tmp_path / 'cam.yaml'
    camera = Camera('cam: left', np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]]),
                    np.zeros(5), (640, 480))
    path.write_text(camera_info_yaml(camera))
    assert read_camera_info(str(path)).name == 'cam: left'


