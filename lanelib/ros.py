"""ROS 1 plumbing: connecting to the master, watching it, the debug image topic, private params.

Everything here uses Debian's rospy (python3-rospy), imported only when called, so that dry
runs and tests need no ROS at all.
"""

import os
import threading
import xmlrpc.client

from lanelib.files import load_yaml
from lanelib.imagemsg import DEBUG_IMAGE, jpeg


class RosUnavailable(Exception):
    """ROS cannot be used: not installed, or no master answers. The message says what to do."""


def split_ros_args(argv):
    """Separate rospy's name:=value arguments from ours; _name:=value are private params, their
    values YAML as rospy reads them (1e3 a number too). ValueError for a value that is not."""
    import yaml

    ours, private = [], {}
    for arg in argv:
        if ':=' in arg:
            name, value = arg.split(':=', 1)
            if name.startswith('_') and not name.startswith('__'):
                try:
                    private[name[1:]] = load_yaml(value)
                except yaml.YAMLError as e:
                    raise ValueError(f"'{arg}': the value after := is not YAML ("
                                     f"{' '.join(str(e).split())}); give a number, true or "
                                     'false, or text in quotes') from None
        else:
            ours.append(arg)
    return ours, private


def private_names(ros):
    """The names of the node's private parameters: the stand-in's _name:=value, or those on
    the parameter server under the node's name."""
    if hasattr(ros, 'params'):
        return list(ros.params)
    prefix = ros.get_name() + '/'
    return sorted({name[len(prefix):].split('/')[0] for name in ros.get_param_names()
                   if name.startswith(prefix)})


def master_online(timeout=3.0):
    """True if the ROS master at ROS_MASTER_URI answers within `timeout` seconds. (rosgraph's
    is_master_online swallows every exception, Ctrl-C included.)"""
    uri = os.environ.get('ROS_MASTER_URI', 'http://localhost:11311')
    try:
        master = xmlrpc.client.ServerProxy(uri, transport=TimeoutTransport(timeout))
        code, _, _ = master.getPid('/kobuki_lane_probe')
        return code == 1
    except Exception:  # refused, timed out, not a master: no master there
        return False


def connect(dry_run, live, topics, private, quiet):
    """(ros, Twist, topic_ros): for a dry run the headless stand-in (on the wall clock for a
    live source), else the real rospy, registered; topic_ros is the real rospy that reads
    topics (a ros: source, camera_info, odometry), also in a dry run when `topics` asks for
    it, else None. RosUnavailable says what is missing."""
    if not dry_run:
        rospy, twist = connect_ros()
        return rospy, twist, rospy
    from lanelib.rospy_standin import SimClock, StandInRospy, Twist, WallClock

    ros = StandInRospy(WallClock() if live else SimClock(), params=private, quiet=quiet,
                       keep=100)
    ros.init_node('kobuki_lane')
    topic_ros = None
    if topics:
        try:
            topic_ros = connect_ros('kobuki_lane_dry_run', anonymous=True)[0]
        except RosUnavailable as e:
            raise RosUnavailable(f'{topics} reads a ROS topic, so even a dry run needs a ROS '
                                 f'master: {e}') from None
    return ros, Twist, topic_ros


def connect_ros(name='kobuki_lane', anonymous=False):
    """The real rospy and Twist, with the node registered (rospy reads _name:=value itself);
    RosUnavailable if ROS is not installed or no master answers."""
    try:
        import rospy
        from geometry_msgs.msg import Twist
    except ImportError as e:
        raise RosUnavailable(f"ROS 1 is not importable ({e}); install Debian's python3-rospy "
                             'and python3-geometry-msgs, or use --dry-run') from None
    uri = os.environ.get('ROS_MASTER_URI', 'http://localhost:11311 (ROS_MASTER_URI unset)')
    if not master_online():
        raise RosUnavailable(f'no ROS master answers at {uri}; start roscore (or roslaunch '
                             'kobuki_node minimal.launch), or use --dry-run')
    # our own signal handlers send the stop before rospy is told to shut down
    rospy.init_node(name, anonymous=anonymous, disable_signals=True)
    return rospy, Twist


class TimeoutTransport(xmlrpc.client.Transport):
    """XML-RPC over HTTP that gives up after `timeout` seconds (a host that vanished would
    otherwise hang the caller), without touching the process-wide socket timeout rospy uses."""

    def __init__(self, timeout):
        super().__init__()
        self.timeout = timeout

    def make_connection(self, host):
        conn = super().make_connection(host)
        conn.timeout = self.timeout
        return conn


class MasterWatch:
    """Watches the ROS master from a thread. While it is gone the robot is held stopped (the
    connection to the base is peer to peer and still works); when a master answers again the
    node's publishers are registered with it again, which rospy does not do by itself, and
    driving resumes. Both are logged. base: a safety.SafeBase."""

    def __init__(self, base, rospy, period=1.0, timeout=1.0):
        self.base, self.rospy, self.period, self.timeout = base, rospy, period, timeout
        self.uri = os.environ.get('ROS_MASTER_URI', 'http://localhost:11311')
        self.lost = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, name='master-watch', daemon=True)

    def start(self):
        self._thread.start()
        return self

    def stop(self):
        self._stop.set()

    def _master(self):
        return xmlrpc.client.ServerProxy(self.uri, transport=TimeoutTransport(self.timeout))

    def alive(self):
        try:
            code, _, _ = self._master().getPid(self.rospy.get_name())
            return code == 1
        except Exception:  # refused, reset, timed out, a bad reply: not there
            return False

    def _register_again(self):
        """Register the node's publications and subscriptions (a camera topic, odometry) with
        the master again, and tell the node who publishes what it subscribes to."""
        from rospy.impl.registration import get_topic_manager

        master, me, api = self._master(), self.rospy.get_name(), self.rospy.get_node_uri()
        manager = get_topic_manager()
        topics = manager.get_publications()
        for topic, data_type in topics:
            master.registerPublisher(me, topic, data_type, api)
        node = xmlrpc.client.ServerProxy(api, transport=TimeoutTransport(self.timeout))
        for topic, data_type in manager.get_subscriptions():
            code, _, publishers = master.registerSubscriber(me, topic, data_type, api)
            if code == 1:
                node.publisherUpdate('/master', topic, publishers)
            topics.append((topic, data_type))
        return [topic for topic, _ in topics]

    def _watch(self):
        log = self.rospy
        while not self._stop.wait(self.period):
            alive = self.alive()
            if not alive and not self.lost:
                self.lost = True
                self.base.hold('ROS master lost')
                log.logwarn('ROS master at %s does not answer: robot held stopped until it is '
                            'back', self.uri)
            elif alive and self.lost:
                try:
                    topics = self._register_again()
                except Exception as e:  # it went away again, or refused: try next time
                    log.logwarn('ROS master at %s is back but registering failed (%s); '
                                'still holding the robot stopped', self.uri, e)
                    continue
                self.lost = False
                self.base.resume()
                log.logwarn('ROS master at %s is back: registered %s again; driving again',
                            self.uri, ', '.join(topics))


def debug_publisher(rospy):
    """~debug_image/compressed: the annotated frames (or a stage's, ~debug_image), for
    rqt_image_view, each stamped with its frame's stamp and frame_id so that it matches its
    frame in a bag; the node builds them only while something subscribes. Returns (publisher,
    message maker(image, stamp [s], frame_id))."""
    from sensor_msgs.msg import CompressedImage

    def message(image, stamp, frame_id):
        msg = CompressedImage()
        msg.header.stamp = rospy.Time.from_sec(stamp)
        msg.header.frame_id = frame_id
        msg.format = 'jpeg'
        msg.data = jpeg(image)
        return msg

    return rospy.Publisher('~' + DEBUG_IMAGE, CompressedImage, queue_size=1), message


LECTURE_VELOCITY = 'mobile_base/commands/velocity'  # kobuki_node's input, in the node's namespace


def velocity_topic(rospy):
    """The name the node publishes its Twists on: cmd_vel when it is remapped (cmd_vel:=...,
    <remap from="cmd_vel" .../> in a launch file), else the lecture's
    mobile_base/commands/velocity, both in the node's namespace: /mobile_base/commands/velocity
    for a node in the root namespace, as on the slides; /robot1/mobile_base/commands/velocity
    under <group ns="robot1">."""
    plain = rospy.names.ns_join(rospy.get_namespace(), 'cmd_vel')
    remapped = rospy.resolve_name('cmd_vel') != plain
    return rospy.resolve_name('cmd_vel' if remapped else LECTURE_VELOCITY)
