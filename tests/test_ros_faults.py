"""Faults and ways out against Debian's real ROS 1 (a real roscore, rospy, sensor_msgs): signals
while waiting for the base, SIGHUP, a master that does not answer, camera_info and image topics
that cannot be used, odometry's clock in a dry run, the launch file's paths (issue 24). Like
test_ros_real.py these never skip, and the Python 3.8 run (no ROS there) leaves them out."""

import math
import os
import signal
import subprocess
import sys
import time
import xmlrpc.client

import numpy as np
import pytest
from helpers import NODE, REPO, SAMPLES, read_jsonl, wait_until

from lanelib.rospy_standin import SimClock, StandInRospy
from lanelib.topics import TopicError, TopicSource, camera_from_topic
from tools.roslive import CameraDriver, LoggedProcess, free_port, start_master, stop_master


def node(env, *args, **popen):
    return subprocess.Popen([sys.executable, NODE, *args], env=env, cwd=REPO, text=True,
                            **{'stdout': subprocess.DEVNULL, 'stderr': subprocess.PIPE, **popen})


def bag_is_whole(path):
    """The bag opens in Debian's rosbag without a reindex; its message count."""
    import rosbag

    with rosbag.Bag(str(path)) as bag:
        return bag.get_message_count()


def test_sighup_stops_the_robot_and_leaves_a_whole_bag(roscore, twist_recorder, tmp_path):
    """Before: SIGHUP (the ssh session to the robot gone) killed the node at once, exit 129,
    the last Twist 0.05 forward and the bag unindexed. Now it is a stop like SIGTERM's."""
    bag = tmp_path / 'run.bag'
    proc = node(roscore['env'], '--source', SAMPLES, '--bag', str(bag))
    twist_recorder.wait_for(4, timeout=20)
    proc.send_signal(signal.SIGHUP)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 129, err
    assert 'ended: SIGHUP' in err
    messages = twist_recorder.wait_for(10 ** 6, timeout=1.0)
    assert len(messages) >= 4 and messages[-1][1:] == (0.0, 0.0)
    assert bag_is_whole(bag) >= 4


def publishers(uri, topic):
    code, _, state = xmlrpc.client.ServerProxy(uri).getSystemState('/test')
    return [nodes for name, nodes in state[0] if name == topic]


@pytest.mark.parametrize('how', ['SIGINT', 'rosnode kill'])
def test_the_wait_for_the_base_ends_at_ctrl_c_and_rosnode_kill(roscore, tmp_path, how):
    """Before: Ctrl-C while no base had subscribed yet ended the process 2 s later saying "the
    frame in progress had not ended" (there was none), with no summary and the bag unindexed;
    rosnode kill was ignored until the wait (up to an hour) was over."""
    port = free_port()
    uri = f'http://localhost:{port}'
    env = dict(roscore['env'], ROS_MASTER_URI=uri)
    master = start_master(port, env)  # no base subscribes on this one
    bag = tmp_path / 'wait.bag'
    try:
        proc = node(env, '--source', SAMPLES, '--wait-for-base', '600', '--bag', str(bag),
                    stdout=subprocess.PIPE)
        wait_until(lambda: publishers(uri, '/mobile_base/commands/velocity'), 30,
                   'the node to be waiting for its base')
        time.sleep(0.5)
        asked = time.monotonic()
        if how == 'SIGINT':
            proc.send_signal(signal.SIGINT)
        else:
            subprocess.run(['rosnode', 'kill', '/kobuki_lane'], env=env, capture_output=True,
                           timeout=30, check=True)
        out, err = proc.communicate(timeout=20)
        took = time.monotonic() - asked
    finally:
        if proc.poll() is None:
            proc.kill()
        stop_master(master)
    assert took < 5.0
    assert proc.returncode == (130 if how == 'SIGINT' else 0), err
    assert f"ended: {'SIGINT' if how == 'SIGINT' else 'ROS shutdown'}" in err  # the summary
    assert 'had not ended' not in err and 'publishing anyway' not in out + err
    assert bag_is_whole(bag) == 1  # the one stop sent


def test_ctrl_c_while_a_master_does_not_answer_is_130(silent_server):
    """Before: rosgraph's master check swallowed Ctrl-C, and the node said "no ROS master"
    with exit status 2."""
    env = dict(os.environ, ROS_MASTER_URI=f'http://127.0.0.1:{silent_server.port}')
    proc = node(env, '--source', SAMPLES)
    wait_until(lambda: silent_server.accepted() > 0, 30, 'the node to ask the master')
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 130, err
    assert 'interrupted while connecting to the ROS master' in err and 'Traceback' not in err


# ---------------------------------------------------------------- case 5: one clock

ODOM_THEN_SILENT = '''
import time, rospy
from nav_msgs.msg import Odometry
rospy.init_node('odometry', anonymous=True, disable_signals=True)
pub = rospy.Publisher('/odom', Odometry, queue_size=10)
while pub.get_num_connections() == 0:
    time.sleep(0.05)
msg = Odometry()
msg.pose.pose.orientation.w = 1.0
end = time.monotonic() + 2.0
while time.monotonic() < end:
    pub.publish(msg)
    time.sleep(0.05)
print('silent', flush=True)
while True:
    time.sleep(0.1)
'''


def test_a_dry_run_on_a_topic_sees_odometry_go_silent(roscore, tmp_path):
    """Before: in a dry run with a ros: source, the controller's clock was the stand-in's
    monotonic time and odometry's the ROS time, so odometry never went stale: silent odometry
    was followed frozen. One clock now: its silence is said, as without --dry-run."""
    paths = [os.path.join(SAMPLES, name) for name in sorted(os.listdir(SAMPLES))[:6]]
    driver = CameraDriver(roscore['env'], tmp_path / 'driver.log', '/cam/image_raw', paths,
                          hold=1.0)
    odometry = LoggedProcess(roscore['env'], tmp_path / 'odom.log', ODOM_THEN_SILENT)
    try:
        proc = subprocess.run([sys.executable, NODE, '--source', 'ros:/cam/image_raw',
                               '--dry-run', '--controller', 'improved', '--odom', '/odom',
                               '--calibration', 'lecture', '--camera-retry', '1'],
                              env=roscore['env'], cwd=REPO, capture_output=True, text=True,
                              timeout=60)
    finally:
        driver.close()
        odometry.close()
    log = proc.stdout + proc.stderr
    assert 'odometry on /odom: the lane memory follows it' in log, log
    assert 'no odometry on /odom for 0.5 s' in log
    assert log.index('follows it') < log.index('no odometry on /odom for 0.5 s')


# ---------------------------------------------------------------- case 9: camera_info

class InfoOnly:
    """As much of rospy as camera_from_topic asks: one camera_info message."""

    ROSException = RuntimeError

    def __init__(self, info):
        self.info = info

    def wait_for_message(self, topic, kind, timeout):
        return self.info

    def get_published_topics(self):
        return [('/cam/camera_info', 'sensor_msgs/CameraInfo')]


class NoInfo(InfoOnly):
    """A master whose camera driver has not published its camera_info yet."""

    def wait_for_message(self, topic, kind, timeout):
        self.waited = timeout
        raise self.ROSException('timeout exceeded')


def test_odometry_not_yet_come_at_the_start_is_said_so_not_as_a_silence():
    """At the start nothing has come: "for 0.5 s" was said at the first frame, which was not
    so; the silence of odometry that had come is said as before."""
    from lanelib.topics import Odometry

    said = []

    class Rospy:
        def Subscriber(self, topic, msg_type, callback, queue_size=None):  # noqa: N802
            self.callback = callback
            return self

        def logwarn(self, fmt, *args):
            said.append(fmt % args)

        loginfo = logwarn

    now = [0.0]
    odometry = Odometry(Rospy(), '/odom', msg_type=object, clock=lambda: now[0])
    assert odometry.pose(0.0) is None
    assert said == ['no odometry on /odom yet: the lane memory dead-reckons on the commands '
                    'sent until it comes']
    from nav_msgs.msg import Odometry as Message

    odometry.rospy.callback(Message())
    now[0] = 0.1
    assert odometry.pose(0.1) == (0.0, 0.0, 0.0)
    assert odometry.pose(1.0) is None
    assert said[1:] == ['odometry on /odom: the lane memory follows it',
                        'no odometry on /odom for 0.5 s: the lane memory dead-reckons on the '
                        'commands sent']


def test_no_camera_info_in_time_names_the_wait_and_the_flag_that_sets_it():
    """Before: a simulator slow to load its map published its camera_info after the 10 s
    waited, and the error did not say which flag waits longer (gym-duckietown's MOOC_modcon)."""
    master = NoInfo(None)
    with pytest.raises(TopicError) as e:
        camera_from_topic(master, '/cam/image_raw', 25.0)
    assert master.waited == 25.0
    said = str(e.value)
    assert 'no sensor_msgs/CameraInfo on /cam/camera_info within 25 s' in said
    assert '--open-timeout' in said and '/cam/camera_info (sensor_msgs/CameraInfo)' in said


def camera_info(K=None, D=None, model='plumb_bob'):
    from sensor_msgs.msg import CameraInfo

    return CameraInfo(width=640, height=480, distortion_model=model,
                      K=K or [600.0, 0, 320, 0, 600.0, 240, 0, 0, 1],
                      D=[-0.1, 0.01, 0.0, 0.0, 0.0] if D is None else D)


@pytest.mark.parametrize('info, said', [
    (camera_info(K=[math.nan] * 9), "'K' has a value that is not finite"),
    (camera_info(K=[600.0, 0, 320, 0, 600.0, 240, 0, 0, 2]), "'K' is not a camera matrix"),
    (camera_info(D=[50.0, 0, 0, 0, 0]), "'D' [50."),
    (camera_info(model='equidistant'), "'distortion_model' is 'equidistant'"),
    (camera_info(D=[0.1] * 6), "'D' has 6 values"),
])
def test_a_camera_info_is_checked_as_a_calibration_file_is(info, said):
    """Before: K all NaN went on to five OpenCV errors; a K whose last row is not 0 0 1 and
    k1 = 50 were used (a file with them is refused); equidistant was used as plumb_bob; six
    D coefficients became five zeros."""
    with pytest.raises(TopicError) as e:
        camera_from_topic(InfoOnly(info), '/cam/image_raw', 1.0)
    assert said in str(e.value) and 'the camera_info on /cam/camera_info' in str(e.value)


def test_a_camera_info_without_distortion_is_a_camera_without_distortion():
    camera = camera_from_topic(InfoOnly(camera_info(D=[])), '/cam/image_raw', 1.0)
    assert np.array_equal(camera.distortion, np.zeros(5))


def test_a_bad_camera_info_on_a_real_topic_is_exit_2_naming_it(roscore, tmp_path):
    info = dict(width=640, height=480, K=[math.nan] * 9, D=[0.0] * 5)
    driver = CameraDriver(roscore['env'], tmp_path / 'driver.log', '/cam/image_raw',
                          [os.path.join(SAMPLES, sorted(os.listdir(SAMPLES))[0])], info=info)
    try:
        proc = subprocess.run([sys.executable, NODE, '--source', 'ros:/cam/image_raw',
                               '--calibration', 'topic', '--dry-run'], env=roscore['env'],
                              cwd=REPO, capture_output=True, text=True, timeout=60)
    finally:
        driver.close()
    assert proc.returncode == 2, proc.stderr
    assert '/cam/camera_info' in proc.stderr and 'not finite' in proc.stderr
    assert 'Traceback' not in proc.stderr and 'OpenCV' not in proc.stderr


def test_camera_retry_0_still_reads_a_latched_camera_info(roscore, tmp_path):
    """Before: --camera-retry 0 --calibration topic waited 0 s for the camera_info and always
    failed, although a latched one was there."""
    paths = [os.path.join(SAMPLES, name) for name in sorted(os.listdir(SAMPLES))[:2]]
    info = dict(width=640, height=480, K=[600.0, 0, 320, 0, 600.0, 240, 0, 0, 1], D=[0.0] * 5)
    driver = CameraDriver(roscore['env'], tmp_path / 'driver.log', '/cam/image_raw', paths,
                          info=info)
    try:
        proc = subprocess.run([sys.executable, NODE, '--source', 'ros:/cam/image_raw',
                               '--calibration', 'topic', '--camera-retry', '0', '--dry-run'],
                              env=roscore['env'], cwd=REPO, capture_output=True, text=True,
                              timeout=60)
    finally:
        driver.close()
    assert 'calibration from the first camera_info beside /cam/image_raw' in proc.stdout, \
        proc.stdout + proc.stderr
    assert 'no sensor_msgs/CameraInfo' not in proc.stderr


def test_frames_that_cannot_be_decoded_are_said_so_and_seldom():
    """Before: a driver publishing frames the node cannot decode ended in "nothing fresh is
    published" although 10 a second were; at 200 a second, 64 warnings a second."""
    from sensor_msgs.msg import Image

    ros = StandInRospy(SimClock(), quiet=True)
    source = TopicSource(ros, '/cam/image_raw', wait=0.0, warn=ros.logwarn)
    pub = ros.Publisher('/cam/image_raw', Image, queue_size=1)
    for _ in range(200):
        pub.publish(Image(height=2, width=2, encoding='32FC1', step=8, data=bytes(16)))
        assert source.read()[0] is False  # skipped, and nothing else fresh
    assert source.skipped == 200
    assert sum('skipped a frame' in text for _, text in ros.log_lines) == 1
    assert 'cannot be decoded' in source.silence() and '32FC1' in source.silence()


def test_a_launch_source_with_a_space_is_one_path(roscore, tmp_path):
    """Before: roslaunch ... source:="/tmp/my dir" was split at the space."""
    folder = tmp_path / 'my frames'
    folder.mkdir()
    for name in sorted(os.listdir(SAMPLES))[:3]:
        os.symlink(os.path.join(SAMPLES, name), folder / name)
    out = tmp_path / 'd.jsonl'
    proc = subprocess.run(['roslaunch', 'kobuki_lane', 'kobuki_lane.launch',
                           f'source:={folder}',
                           f'extra_args:=--decisions {out} --wait-for-base 0'],
                          env=roscore['env'], cwd=tmp_path, capture_output=True, text=True,
                          timeout=90)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert len(read_jsonl(out)) == 3
