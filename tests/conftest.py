"""Fixtures: a real roscore (Debian's ros-core) and small frame folders. Helpers shared by the
test modules are in helpers.py."""

import os
import shutil
import signal
import time

import pytest
from helpers import SAMPLES, TwistRecorder

from tools.roslive import free_port, node_env, ros_processes, start_master, stop_master


@pytest.fixture(scope='session', autouse=True)
def no_ros_process_left():
    """After the whole suite, no ROS process that it started may still run: a roscore,
    rosmaster, rosout, roslaunch, node or subscriber left behind is killed, and the suite
    fails. (Set up first, so torn down last, after the session's own roscore has stopped.)"""
    before = set(ros_processes())
    yield
    deadline = time.monotonic() + 10  # a stopped roscore takes a moment to end its children
    while True:
        left = {pid: cmd for pid, cmd in ros_processes().items() if pid not in before}
        if not left or time.monotonic() > deadline:
            break
        time.sleep(0.2)
    for pid in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    if left:
        pytest.fail('the tests left ROS processes running (now killed): ' +
                    '; '.join(f'{pid} {cmd}' for pid, cmd in sorted(left.items())))


@pytest.fixture(scope='session')
def roscore(tmp_path_factory):
    """A real ROS master for the whole session; this process is a real rospy node on it."""

    if shutil.which('roscore') is None:
        pytest.fail("roscore is not installed: run 'bash setup.sh test' (Debian's ros-core)")
    port = free_port()
    uri = f'http://localhost:{port}'
    home = str(tmp_path_factory.mktemp('ros_home'))
    env = node_env(uri, home)
    try:
        proc = start_master(port, env)
    except RuntimeError as e:
        pytest.fail(str(e))
    os.environ.update(ROS_MASTER_URI=uri, ROS_HOSTNAME='localhost', ROS_HOME=home)
    import rospy

    rospy.init_node('kobuki_lane_test_listener', anonymous=True, disable_signals=True)
    yield dict(uri=uri, env=env, home=home)
    rospy.signal_shutdown('tests done')
    stop_master(proc)


@pytest.fixture
def twist_recorder(roscore):
    rec = TwistRecorder()
    yield rec
    rec.close()


@pytest.fixture
def few_frames(tmp_path):
    """Eight sample frames (A, B and C regions) in a folder of their own."""
    folder = tmp_path / 'frames'
    folder.mkdir()
    names = sorted(os.listdir(SAMPLES))
    for name in names[::3][:8]:
        shutil.copy(os.path.join(SAMPLES, name), folder / name)
    return folder
