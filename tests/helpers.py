"""What several test modules share (fixtures are in conftest.py)."""

import json
import os
import sys
import threading
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SAMPLES = os.path.join(REPO, 'samples', 'track')
NODE = os.path.join(REPO, 'kobuki_lane.py')


def read_jsonl(path):
    with open(path, encoding='utf-8') as f:
        return [json.loads(line) for line in f]


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


def wait_until(condition, timeout, what):
    """Poll `condition()` until it is true; fail the test, saying `what`, after `timeout` s."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f'waited {timeout} s for {what}')
        time.sleep(0.05)


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
    # (os.waitstatus_to_exitcode is Python 3.9's; the node's tests run on 3.8 too)
    return (os.WEXITSTATUS(status) if os.WIFEXITED(status) else -os.WTERMSIG(status)), output
