"""Shared fixtures: a real roscore (Debian's ros-core) and small frame folders."""

import os
import shutil
import sys
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


def run_as_nobody(main, argv):
    """main(argv) in a forked child that, if we are root, becomes 'nobody' first
    (root may write anywhere; on a robot the node is not root). Returns (status, output).
    The child runs the already imported code, so it needs no access to this checkout."""
    import pwd

    nobody = pwd.getpwnam('nobody')
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns into pytest
        code = 99
        try:
            os.dup2(w, 1)
            os.dup2(w, 2)
            # pytest has replaced sys.stdout and sys.stderr; write to the pipe instead
            sys.stdout = sys.stderr = open(1, 'w', closefd=False)
            if os.geteuid() == 0:
                os.setgroups([])
                os.setgid(nobody.pw_gid)
                os.setuid(nobody.pw_uid)
            try:
                code = main(argv) or 0
            except SystemExit as e:
                code = e.code if isinstance(e.code, int) else 1
        finally:
            sys.stdout.flush()
            os._exit(code)
    os.close(w)
    with os.fdopen(r) as f:
        output = f.read()
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), output
