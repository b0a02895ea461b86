"""Shared fixtures: a real roscore (Debian's ros-core) and small frame folders."""

import os
import shutil
import threading
import time

import pytest

from roslive import free_port, node_env, start_master, stop_master

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SAMPLES = os.path.join(REPO, 'samples', 'track')


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


class TwistRecorder:
    """A real rospy subscriber on the velocity topic, keeping (receive time, x, z)."""

    def __init__(self, topic='/mobile_base/commands/velocity'):
        import rospy
        from geometry_msgs.msg import Twist

        self.messages = []
        self._lock = threading.Lock()
        self._sub = rospy.Subscriber(topic, Twist, self._callback, queue_size=100)

    def _callback(self, msg):
        with self._lock:
            self.messages.append((time.monotonic(), msg.linear.x, msg.angular.z))

    def wait_for(self, count, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                if len(self.messages) >= count:
                    break
            time.sleep(0.05)
        return list(self.messages)

    def close(self):
        self._sub.unregister()


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
