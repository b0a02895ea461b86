"""Real ROS 1 helpers for the tests and the soak: a roscore that can be killed and restarted,
a Twist subscriber in a process of its own that logs what it receives, and a camera driver
that publishes pictures on an image topic.

Both need Debian's ros-core and python3-rospy (`bash setup.sh test` installs them).
"""

import os
import signal
import socket
import subprocess
import sys
import time
import xmlrpc.client

from tools.common import REPO

VELOCITY = '/mobile_base/commands/velocity'


def free_port():
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def node_env(master_uri, ros_home, base=None):
    """Environment for a node process: this python's bin first on PATH, the repo as a package,
    logs under ros_home, everything on localhost."""
    env = dict(os.environ if base is None else base)
    env.update(ROS_MASTER_URI=master_uri, ROS_HOME=ros_home, ROS_LOG_DIR=ros_home,
               ROS_PACKAGE_PATH=REPO, PYTHONUNBUFFERED='1',
               PATH=os.path.dirname(sys.executable) + os.pathsep + env.get('PATH', ''))
    env.pop('ROS_IP', None)
    env['ROS_HOSTNAME'] = 'localhost'
    return env


def start_master(port, env, timeout=30.0):
    """roscore on `port` in its own process group; returns once it answers."""
    proc = subprocess.Popen(['roscore', '-p', str(port)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.STDOUT, start_new_session=True)
    uri = f'http://localhost:{port}'
    deadline = time.monotonic() + timeout
    # answering is not enough: it must be this roscore's master, not one already there
    while master_pid(uri) not in process_tree(proc.pid):
        if proc.poll() is not None or time.monotonic() > deadline:
            stop_master(proc, signal.SIGKILL)
            raise RuntimeError(f'roscore did not come up on port {port} (another master '
                               'there?)')
        time.sleep(0.1)
    return proc


def master_pid(uri):
    """The process id of the master answering at uri, or None."""
    try:
        code, _, pid = xmlrpc.client.ServerProxy(uri).getPid('/roslive')
        return pid if code == 1 else None
    except (OSError, xmlrpc.client.Error):
        return None


def process_tree(pid):
    """pid and all its descendants (Linux /proc), parents first."""
    children = {}
    for entry in os.listdir('/proc'):
        if entry.isdigit():
            try:
                with open(f'/proc/{entry}/stat') as f:
                    ppid = int(f.read().rsplit(')', 1)[1].split()[1])
            except (OSError, ValueError, IndexError):
                continue  # gone meanwhile
            children.setdefault(ppid, []).append(int(entry))
    tree, todo = [], [pid]
    while todo:
        tree.append(todo.pop(0))
        todo.extend(children.get(tree[-1], []))
    return tree


SESSION_MARK = 'KOBUKI_LANE_TEST_SESSION'  # in the environment of everything a test run starts


def marked_processes(mark, name=SESSION_MARK):
    """{pid: command line} of the processes whose environment holds name=mark: those a test
    run started (its mark is in the environment they were started with, and in that of what
    they started in turn, even once their parent has gone). Nobody else's process is listed:
    one whose environment cannot be read (another user's) is not ours."""
    wanted = f'{name}={mark}'.encode()
    found, me = {}, os.getpid()
    for entry in os.listdir('/proc'):
        if not entry.isdigit() or int(entry) == me:
            continue
        try:
            with open(f'/proc/{entry}/environ', 'rb') as f:
                if wanted not in f.read().split(b'\0'):
                    continue
            with open(f'/proc/{entry}/cmdline', 'rb') as f:
                cmd = f.read().replace(b'\0', b' ').decode(errors='replace').strip()
        except OSError:  # gone meanwhile, or not ours to read
            continue
        if cmd:  # (a zombie has no command line left)
            found[int(entry)] = cmd[:200]
    return found


def end_what_was_started(mark, wait=10.0):
    """Wait up to `wait` seconds for the processes started with `mark` in their environment
    to end (a stopped roscore takes a moment to end its children), then SIGKILL those still
    there; returns them ({pid: command line}). Nothing without the mark is touched."""
    deadline = time.monotonic() + wait
    while True:
        left = marked_processes(mark)
        if not left or time.monotonic() > deadline:
            break
        time.sleep(0.2)
    for pid in left:
        try:
            os.kill(pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
    return left


def stop_master(proc, sig=signal.SIGTERM, timeout=20.0):
    """SIGTERM: roscore shuts down rosmaster and rosout itself. SIGKILL: a crash of the master's
    machine; roslaunch starts rosmaster and rosout in sessions of their own, so every process
    of the tree is killed, not only roscore's group."""
    tree = process_tree(proc.pid) if sig == signal.SIGKILL else [proc.pid]
    for pid in tree:
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            pass
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        stop_master(proc, signal.SIGKILL)


SUBSCRIBER = f'''
import sys, time, rospy
from geometry_msgs.msg import Twist
rospy.init_node('listener', anonymous=True, disable_signals=True)
rospy.Subscriber('{VELOCITY}', Twist,
                 lambda m: print(time.time(), m.linear.x, m.angular.z, flush=True),
                 queue_size=100)
print('ready', flush=True)
while True:
    time.sleep(0.1)
'''


class LoggedProcess:
    """A python -c script in a process group of its own writing its output to `log`; close()
    kills the group. (A process's rospy belongs to one master session.)"""

    def __init__(self, env, log, script, *args, stderr=subprocess.DEVNULL):
        self.log = open(log, 'w+')
        self.proc = subprocess.Popen([sys.executable, '-c', script, *args], env=env,
                                     stdout=self.log, stderr=stderr, start_new_session=True)

    def close(self):
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait()
        self.log.close()


class Listener(LoggedProcess):
    """A subscriber to the velocity topic in its own process; each line of `log` is
    `receive-time linear.x angular.z`."""

    def __init__(self, env, log):
        super().__init__(env, log, SUBSCRIBER)

    def ready(self):
        self.log.flush()
        with open(self.log.name) as f:
            return f.readline().startswith('ready')

    def messages(self):
        """[(wall time received, linear.x, angular.z)] so far."""
        self.log.flush()
        with open(self.log.name) as f:
            # a line without its newline may still be being written
            rows = [line.split() for line in f
                    if line.endswith('\n') and not line.startswith('ready')]
        return [(float(t), float(x), float(z)) for t, x, z in rows]

    def wait_for(self, count, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and len(self.messages()) < count:
            time.sleep(0.1)
        return self.messages()


CAMERA = '''
import json, sys, time
import cv2, rospy
from sensor_msgs.msg import CameraInfo, CompressedImage, Image
topic, paths, hold, hz, info = json.loads(sys.argv[1])
rospy.init_node('camera_driver', anonymous=True, disable_signals=True)
compressed = topic.endswith('/compressed')
pub = rospy.Publisher(topic, CompressedImage if compressed else Image, queue_size=1)
base = topic[:-len('/compressed')] if compressed else topic
info_pub = rospy.Publisher(base.rsplit('/', 1)[0] + '/camera_info', CameraInfo, queue_size=1,
                           latch=True)
if info:
    msg = CameraInfo(width=info['width'], height=info['height'], K=info['K'], D=info['D'],
                     distortion_model='plumb_bob')
    msg.header.frame_id = 'test_camera'
    info_pub.publish(msg)
while pub.get_num_connections() == 0:  # a driver runs before the node; wait for it here
    time.sleep(0.05)
print('connected', flush=True)
for i, path in enumerate(paths):
    if compressed:
        msg = CompressedImage(format='jpeg', data=open(path, 'rb').read())
    else:
        frame = cv2.imread(path, cv2.IMREAD_COLOR)
        msg = Image(height=frame.shape[0], width=frame.shape[1], encoding='bgr8',
                    step=frame.shape[1] * 3, data=frame.tobytes())
    msg.header.stamp = rospy.Time(i + 1)
    end = time.monotonic() + hold
    while time.monotonic() < end:
        pub.publish(msg)
        time.sleep(1.0 / hz)
print('done', flush=True)
while True:  # silent now, but still there, as a driver whose camera stopped
    time.sleep(0.1)
'''


class CameraDriver(LoggedProcess):
    """A camera driver in its own process, as usb_cam or astra_camera would be: publishes each
    of `paths` on `topic` (Image bgr8, or CompressedImage JPEG for a topic ending in
    /compressed) at `hz` for `hold` seconds, header stamp i + 1 s for the i-th, once the node
    has subscribed; then goes silent. info: camera_info fields (width, height, K, D) latched
    beside the topic, or None. Its log says 'connected' and 'done' when it gets there."""

    def __init__(self, env, log, topic, paths, hold=0.75, hz=10.0, info=None):
        import json

        super().__init__(env, log, CAMERA,
                         json.dumps([topic, [str(p) for p in paths], hold, hz, info]),
                         stderr=subprocess.STDOUT)

    def said(self, word):
        self.log.flush()
        with open(self.log.name) as f:
            return any(line.strip() == word for line in f)
