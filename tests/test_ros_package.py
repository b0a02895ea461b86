"""kobuki_lane as a ROS package, on Debian's real ROS 1: built with catkin in a fresh workspace
(rosrun, roslaunch, rostest from it), live tuning, the topics it publishes, /diagnostics, and
two robots in two namespaces on one master. These never skip."""

import math
import os
import shutil
import subprocess
import sys
import threading
import time

import pytest
from helpers import NODE, REPO, SAMPLES, read_jsonl, wait_until

pytestmark = pytest.mark.usefixtures('no_private_params')


@pytest.fixture(scope='module')
def workspace(tmp_path_factory):
    """A catkin workspace holding the repository (as a link, as a user's checkout would be),
    built with catkin_make by the Python that has OpenCV (this one's bin first on PATH)."""
    if shutil.which('catkin_make') is None:
        pytest.fail("catkin_make is not installed: run 'bash setup.sh test' (Debian's catkin)")
    ws = tmp_path_factory.mktemp('catkin_ws')
    (ws / 'src').mkdir()
    os.symlink(REPO, ws / 'src' / 'kobuki_lane')
    env = clean_env()
    env['PWD'] = str(ws)  # catkin_make takes the workspace from PWD
    build = subprocess.run(['catkin_make'], cwd=ws, env=env, capture_output=True, text=True,
                           timeout=300)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    return ws


def clean_env(base=None):
    """The environment a user's shell has before `source devel/setup.bash`: no package path
    of ours, this Python's bin (the .venv) first on PATH."""
    env = dict(base or os.environ)
    for name in ('ROS_PACKAGE_PATH', 'CMAKE_PREFIX_PATH', 'PYTHONPATH', 'ROS_MASTER_URI'):
        env.pop(name, None)
    env['PATH'] = os.path.dirname(sys.executable) + os.pathsep + env.get('PATH', '')
    return env


def in_workspace(ws, command, env, timeout=120, cwd=None):
    """`command` (a shell line) after sourcing the workspace's devel/setup.bash, from a folder
    that is not the repository (nothing found by being in it)."""
    line = f'source {ws}/devel/setup.bash && {command}'
    env = dict(env, PWD=str(cwd or ws))
    return subprocess.run(['bash', '-c', line], cwd=cwd or ws, env=env, capture_output=True,
                          text=True, timeout=timeout)


def test_the_workspace_runs_the_node_with_rosrun_and_roslaunch(workspace, roscore, tmp_path):
    env = clean_env()
    found = in_workspace(workspace, 'rospack find kobuki_lane && '
                         'rosrun kobuki_lane kobuki_lane.py --help', env)
    assert found.returncode == 0, found.stderr
    assert found.stdout.splitlines()[0] == str(workspace / 'src' / 'kobuki_lane')
    assert '--controller' in found.stdout and '--robot' in found.stdout
    # lanelib comes from the workspace's devel space, not from the current folder
    where = in_workspace(workspace, 'python3 -c "import lanelib; print(lanelib.__file__)"',
                         env, cwd=tmp_path)
    assert where.returncode == 0 and f'{workspace}/devel/lib/python3' in where.stdout, where

    frames = tmp_path / 'frames'
    frames.mkdir()
    for name in sorted(os.listdir(SAMPLES))[:6]:
        shutil.copy(os.path.join(SAMPLES, name), frames / name)
    env['ROS_MASTER_URI'], env['ROS_HOME'] = roscore['uri'], roscore['home']
    launched = in_workspace(workspace, 'roslaunch kobuki_lane kobuki_lane.launch '
                            f'robot:=duckiebot controller:=improved source:={frames} '
                            'extra_args:="--wait-for-base 0"', env, cwd=tmp_path)
    said = launched.stdout + launched.stderr
    assert launched.returncode == 0, said[-3000:]
    assert "robot preset 'duckiebot'" in said and 'loaded into ~robot_preset' in said
    assert 'lane duckietown' in said and '8.0 Hz' in said
    assert 'ended: end of input' in said


def test_rostest_of_the_launch_file_passes(workspace, tmp_path):
    """kobuki_lane.test: Twists at 4 Hz from the launch file, a zero Twist on shutdown
    (rostest starts a master of its own)."""
    env = clean_env()
    env['ROS_HOME'] = str(tmp_path)
    ran = in_workspace(workspace, 'rostest kobuki_lane kobuki_lane.test', env, timeout=180,
                       cwd=tmp_path)
    assert ran.returncode == 0, ran.stdout[-3000:] + ran.stderr[-3000:]
    assert 'RESULT: SUCCESS' in ran.stdout and 'TESTS: 1' in ran.stdout


class Topic:
    """A subscriber in this process keeping (monotonic time, message)."""

    def __init__(self, name, kind):
        import rospy

        self.got, self.lock = [], threading.Lock()
        self.sub = rospy.Subscriber(name, kind, self._received, queue_size=1000)

    def _received(self, msg):
        with self.lock:
            self.got.append((time.monotonic(), msg))

    def messages(self):
        with self.lock:
            return list(self.got)

    def close(self):
        self.sub.unregister()


def start_node(roscore, *args, name=None):
    return subprocess.Popen([sys.executable, NODE, *args], env=roscore['env'], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_live_tuning_changes_the_next_decision(roscore, tmp_path):
    """The threshold set through dynamic_reconfigure on a real master: the frames before the
    change go straight with the lecture's 6, every frame after it is decided with 0.5."""
    import dynamic_reconfigure.client
    from std_msgs.msg import String

    decisions = tmp_path / 'tuned.jsonl'
    seen = Topic('/kobuki_lane/decision', String)
    proc = start_node(roscore, '--source', SAMPLES, '--wait-for-base', '0', '--quiet',
                      '--decisions', str(decisions))
    try:
        wait_until(lambda: len(seen.messages()) >= 4, 30, 'four decisions on the topic')
        client = dynamic_reconfigure.client.Client('/kobuki_lane', timeout=10)
        assert client.get_configuration(timeout=10)['threshold'] == 6.0
        before = time.time()  # the records' t is ROS time, the wall clock on a real master
        changed = client.update_configuration({'threshold': 0.5})
        after = time.time()
        assert changed['threshold'] == 0.5
        # a value outside the table's range is clamped to it by dynamic_reconfigure
        assert client.update_configuration({'canny_low': 5000})['canny_low'] == 2040
        client.update_configuration({'canny_low': 85})
        client.close()
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
        seen.close()
    assert proc.returncode == 0, err
    assert 'live tuning: threshold 6 -> 0.5 (from the next frame)' in out + err
    records = read_jsonl(decisions)
    earlier = [r for r in records if r['t'] < before]
    later = [r for r in records if r['t'] > after + 0.3]  # a frame under way may finish first
    assert len(earlier) >= 4 and {r['decision'] for r in earlier} == {'straight'}
    assert any(abs(r['theta']) < 6 and abs(r['theta']) > 0.5 for r in earlier)
    assert later and any(r['decision'] != 'straight' for r in later)
    for r in later:
        expected = ('left' if r['theta'] > 0.5 else 'right' if r['theta'] < -0.5 else
                    'straight')
        assert r['decision'] == expected, r


def test_the_estimate_the_decision_and_diagnostics_are_on_topics(roscore, tmp_path):
    """~lane/offset and the rest carry what the decision records hold, frame for frame;
    /diagnostics says the loop's rate and that the robot is not held."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Float64, Int32, String

    decisions = tmp_path / 'estimate.jsonl'
    topics = {name: Topic(f'/kobuki_lane/{name}', kind) for name, kind in (
        ('decision', String), ('lines', Int32), ('lane/offset', Float64),
        ('lane/heading', Float64), ('lane/confidence', Float64), ('lane/curvature', Float64))}
    health = Topic('/diagnostics', DiagnosticArray)
    time.sleep(1.0)  # the subscriptions connect when the node registers; give them a moment
    proc = start_node(roscore, '--source', SAMPLES, '--controller', 'improved',
                      '--wait-for-base', '0', '--quiet', '--decisions', str(decisions))
    try:
        out, err = proc.communicate(timeout=60)
        time.sleep(0.5)
    finally:
        if proc.poll() is None:
            proc.kill()
        for topic in list(topics.values()) + [health]:
            topic.close()
    assert proc.returncode == 0, err
    records = read_jsonl(decisions)
    got = {name: [msg.data for _, msg in topic.messages()] for name, topic in topics.items()}
    n = len(got['decision'])
    assert n >= len(records) - 3, (n, len(records))  # the first may go before connecting
    tail = records[-n:]
    assert got['decision'] == [r['decision'] for r in tail]
    assert got['lines'] == [r['lines'] for r in tail]
    for name, key in (('lane/offset', 'offset_m'), ('lane/heading', 'heading_rad'),
                      ('lane/confidence', 'confidence'), ('lane/curvature', 'curvature')):
        for value, r in zip(got[name], tail):
            if r[key] is None:
                assert math.isnan(value)
            else:
                assert value == pytest.approx(r[key], abs=1e-9), (name, value, r[key])
    assert any(r['offset_m'] is not None for r in tail)
    ours = [s for _, a in health.messages() for s in a.status if s.name == 'kobuki_lane: loop']
    assert ours, 'no kobuki_lane: loop status on /diagnostics'
    values = {v.key: v.value for v in ours[-1].values}
    assert values['rate asked [Hz]'] == '4' and values['robot held stopped'] == 'no'
    assert 3.0 < float(values['rate measured [Hz]']) < 5.0, values
    assert values['ROS master'] == 'online' and ours[-1].hardware_id == '/kobuki_lane'


LAUNCH_TWO = '''<launch>
  <group ns="robot1">
    <include file="{launch}">
      <arg name="source" value="{frames}"/>
      <arg name="params" value="{turny}"/>
      <arg name="extra_args" value="--wait-for-base 10"/>
    </include>
  </group>
  <group ns="robot2">
    <include file="{launch}">
      <arg name="source" value="{frames}"/>
      <arg name="extra_args" value="--wait-for-base 10"/>
    </include>
  </group>
</launch>
'''


def test_two_robots_in_two_namespaces_each_drive_their_own_base(roscore, few_frames,
                                                                tmp_path):
    """One launch file, two <group ns>: robot1 (a parameter file with threshold 0.5 and turn
    rate 0.3) and robot2 (the lecture's settings) each publish on their own
    mobile_base/commands/velocity, end with their own stop, and neither on the lecture's
    global topic."""
    from geometry_msgs.msg import Twist

    turny = tmp_path / 'turny.yaml'
    turny.write_text('threshold: 0.5\nturn_angular: 0.3\n')
    two = tmp_path / 'two.launch'
    two.write_text(LAUNCH_TWO.format(launch=os.path.join(REPO, 'launch', 'kobuki_lane.launch'),
                                     frames=few_frames, turny=turny))
    bases = {ns: Topic(f'/{ns}/mobile_base/commands/velocity', Twist)
             for ns in ('robot1', 'robot2')}
    lecture = Topic('/mobile_base/commands/velocity', Twist)
    try:
        launched = subprocess.run(['roslaunch', str(two)], env=roscore['env'], cwd=tmp_path,
                                  capture_output=True, text=True, timeout=120)
        time.sleep(0.5)
    finally:
        for topic in list(bases.values()) + [lecture]:
            topic.close()
    assert launched.returncode == 0, launched.stdout[-3000:] + launched.stderr[-3000:]
    got = {ns: [(m.linear.x, m.angular.z) for _, m in topic.messages()]
           for ns, topic in bases.items()}
    for ns in got:
        assert len(got[ns]) == 9, (ns, got[ns])  # 8 frames, then the stop
        assert got[ns][-1] == (0.0, 0.0)
    assert {abs(z) for _, z in got['robot1'][:-1]} >= {0.3}  # its parameter file's turns
    assert got['robot2'][:-1] == [(0.05, 0.0)] * 8  # the lecture's straight
    assert lecture.messages() == []
