"""Fixtures: a real roscore (Debian's ros-core) and small frame folders. Helpers shared by the
test modules are in helpers.py."""

import os

# numpy's BLAS one thread, as the node runs it (see kobuki_lane.py): set before numpy loads.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

import shutil
import socket
import threading
import uuid

import pytest
from helpers import SAMPLES, TwistRecorder

from tools.roslive import (
    SESSION_MARK,
    end_what_was_started,
    free_port,
    node_env,
    start_master,
    stop_master,
)


@pytest.fixture(scope='session', autouse=True)
def no_ros_process_left():
    """After the whole suite, no process that it started may still run: a roscore, rosmaster,
    rosout, roslaunch, node or subscriber left behind is killed, and the suite fails. What the
    suite started is known by a mark in its environment (tools.roslive.marked_processes), so a
    node, a roscore or anything else running beside the tests is never touched. (Set up first,
    so torn down last, after the session's own roscore has stopped.)"""
    mark = uuid.uuid4().hex
    os.environ[SESSION_MARK] = mark  # inherited by everything the tests start
    yield
    left = end_what_was_started(mark)
    if left:
        pytest.fail('the tests left processes running (now killed): ' +
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
def no_private_params(roscore):
    """Private parameters stay on the master after a node ends (roslaunch, rosparam and
    _name:=value set them there); each test that uses this starts without any of the nodes'
    the tests run (/kobuki_lane, and in the namespaces robot1 and robot2)."""
    import rospy

    def clear():
        for name in ('/kobuki_lane', '/robot1', '/robot2'):
            try:
                rospy.delete_param(name)
            except KeyError:
                pass

    clear()
    yield
    clear()


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


class SilentServer:
    """A TCP server that accepts connections and never answers: a camera URL, or a ROS master,
    that hangs. `url` names it; `accepted()` says how many have connected."""

    def __init__(self):
        self.server = socket.socket()
        self.server.bind(('127.0.0.1', 0))
        self.server.listen(8)
        self.held, self.stop = [], threading.Event()
        self.port = self.server.getsockname()[1]
        self.url = f'http://127.0.0.1:{self.port}/stream.mjpg'
        self.thread = threading.Thread(target=self._accept, daemon=True)
        self.thread.start()

    def _accept(self):
        self.server.settimeout(0.2)
        while not self.stop.is_set():
            try:
                self.held.append(self.server.accept()[0])
            except OSError:
                continue

    def accepted(self):
        return len(self.held)

    def close(self):
        self.stop.set()
        self.thread.join()
        for conn in self.held:
            conn.close()
        self.server.close()


@pytest.fixture
def silent_server():
    server = SilentServer()
    yield server
    server.close()
