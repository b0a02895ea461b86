"""The simulator, the track files and the improved controller."""

import json
import math
import os
from dataclasses import replace

import cv2
import numpy as np
import pytest
from helpers import SAMPLES

import simulate
from kobuki_lane import LaneParams, make_controller
from kobuki_lane import main as node_main
from lanelib import lanefit
from lanelib.camera import LECTURE_CAMERA
from lanelib.estimate import LaneEstimate, measure
from lanelib.geometry import Mounting, camera_axes
from lanelib.improved import ImprovedParams
from lanelib.memory import LaneMemory
from lanelib.robot import ODOM_TOPIC, STOP, arc_step
from lanelib.rospy_standin import Odometry as OdometryMessage
from lanelib.rospy_standin import SimClock, StandInRospy
from lanelib.sim.base import BaseLimits, DiffDriveBase
from lanelib.sim.simulator import TrackSimulator, apply_variant, improved_params, odometry_message
from lanelib.sim.tracks import TrackError, from_dict, load_track, with_world
from lanelib.sim.world import WORLDS, FloorCamera, FloorMap, Scene, Track
from lanelib.topics import Odometry

SHORT = {'lane_width': 0.35, 'tape_width': 0.03,
         'segments': [{'straight': 1.0}, {'arc': {'radius': 1.5, 'angle_deg': 45}},
                      {'straight': 0.6}]}


def drive(base, v, omega, seconds, period=0.25):
    """Publish (v, omega) at 4 Hz for `seconds`, as the node does."""
    for _ in range(int(round(seconds / period))):
        base.command(base.t, v, omega)
        base.advance(base.t + period)


def test_arc_kinematics_match_the_closed_form():
    base = DiffDriveBase((0.0, 0.0, 0.0), BaseLimits(latency=0.0))
    v, omega, t = 0.2, 0.5, 3.0
    drive(base, v, omega, t)
    r = v / omega
    assert base.x == pytest.approx(r * math.sin(omega * t), abs=1e-9)
    assert base.y == pytest.approx(r * (1 - math.cos(omega * t)), abs=1e-9)
    assert base.yaw == pytest.approx(omega * t, abs=1e-9)
    assert base.distance == pytest.approx(v * t, abs=1e-9)


def test_straight_kinematics_and_kobuki_limits():
    base = DiffDriveBase((1.0, 2.0, math.pi / 2), BaseLimits(latency=0.0))
    drive(base, 0.3, 0.0, 2.0)
    assert (base.x, base.y) == (pytest.approx(1.0, abs=1e-9), pytest.approx(2.6, abs=1e-9))
    drive(base, 5.0, 10.0, 0.5)
    assert base.v == 0.7 and base.omega == pytest.approx(math.pi)


def test_command_timeout_stops_the_base_after_0_6_s():
    base = DiffDriveBase((0.0, 0.0, 0.0), BaseLimits(latency=0.0))
    base.command(0.0, 0.2, 0.0)
    base.advance(3.0)
    assert base.v == 0.0
    assert base.distance == pytest.approx(0.2 * 0.6, abs=0.2 * 0.011)


def test_latency_and_acceleration_limit():
    base = DiffDriveBase((0.0, 0.0, 0.0), BaseLimits(latency=0.1, accel=0.5))
    base.command(0.0, 0.4, 0.0)
    base.advance(0.1)
    assert base.v == 0.0  # not at the wheels yet
    base.advance(0.3)
    assert base.v == pytest.approx(0.1, abs=1e-9)  # 0.2 s at 0.5 m/s^2


@pytest.mark.parametrize('mounting', [Mounting(), Mounting(0.3, 15.0, 0.05)])
def test_renderer_agrees_with_cv2_project_points(mounting):
    track = Track(segments=[{'straight': 6.0}], start=(-1.0, 0.0, 0.0))
    pose = (0.3, 0.02, math.radians(3))
    img = FloorCamera(LECTURE_CAMERA, mounting).render(FloorMap(track), pose, Scene(noise=0))
    x_cam, y_cam, z_cam = camera_axes(mounting.pitch_deg)
    rot = np.stack([x_cam, y_cam, z_cam])  # robot -> camera
    lens = np.array([mounting.forward, 0.0, mounting.height])
    c, s = math.cos(pose[2]), math.sin(pose[2])
    for along in (0.9, 1.3, 2.0):
        for world_y, expect_tape in ((0.175, True), (-0.175, True), (0.0, False)):
            dx, dy = along - pose[0], world_y - pose[1]
            robot = np.array([c * dx + s * dy, -s * dx + c * dy, 0.0])
            rvec, _ = cv2.Rodrigues(rot)
            uv, _ = cv2.projectPoints(robot.reshape(1, 3), rvec, -rot @ lens,
                                      LECTURE_CAMERA.matrix, LECTURE_CAMERA.distortion)
            u, v = uv.ravel()
            if not (0 <= u < 640 and 0 <= v < 480):
                continue
            value = img[int(round(v)), int(round(u)), 0]
            assert (value > 200) == expect_tape, (along, world_y, u, v, value)


@pytest.fixture(scope='module')
def straight_scene():
    track = Track(segments=[{'straight': 8.0}], start=(-1.0, 0.0, 0.0))
    return track, FloorMap(track), FloorCamera(LECTURE_CAMERA)


@pytest.mark.parametrize('offset, yaw_deg', [(0.0, 0.0), (0.06, 0.0), (-0.06, 0.0), (0.0, 6.0),
                                             (0.0, -6.0), (0.04, -4.0), (-0.04, 4.0)])
def test_offset_and_heading_at_known_poses(straight_scene, offset, yaw_deg):
    track, floor_map, camera = straight_scene
    img = camera.render(floor_map, track.pose_at(1.0, offset, math.radians(yaw_deg)),
                        Scene(noise=3), np.random.default_rng(1))
    ctl = make_controller('improved', LaneParams())
    est, _ = measure(ctl.perceive(img).pieces, ctl.profile, ctl.p)
    assert est.left >= 1 and est.right >= 1
    assert est.offset == pytest.approx(offset, abs=0.02)
    assert math.degrees(est.heading) == pytest.approx(yaw_deg, abs=2.0)
    assert abs(est.curvature) < 0.15


def test_one_line_is_enough(straight_scene):
    track, _, camera = straight_scene
    gone = FloorMap(track, gaps=[dict(line='right', at=0.0, length=8.0)])
    img = camera.render(gone, track.pose_at(1.0, 0.03, 0.0), Scene(noise=0))
    ctl = make_controller('improved', LaneParams())
    est, _ = measure(ctl.perceive(img).pieces, ctl.profile, ctl.p)
    assert est.right == 0 and est.left >= 1
    assert est.offset == pytest.approx(0.03, abs=0.02)
    assert est.confidence < 1.0


def test_without_the_search_a_lane_lost_for_longer_than_the_timeout_stops_the_robot():
    ctl = make_controller('improved', LaneParams(),
                          improved=ImprovedParams(lost_timeout=0.5, search_angle=0.0))
    blank = np.full((480, 640, 3), 90, np.uint8)
    track = Track(segments=[{'straight': 8.0}], start=(-1.0, 0.0, 0.0))
    lane = FloorCamera(LECTURE_CAMERA).render(FloorMap(track), track.pose_at(1.0), Scene())
    assert ctl(ctl.perceive(lane)).linear_x > 0
    commands = [ctl(ctl.perceive(blank)) for _ in range(4)]
    assert commands[0].linear_x > 0 and commands[1].linear_x > 0  # coasting 0.25, 0.5 s
    assert commands[2].decision == 'none' and commands[2].linear_x == 0.0  # 0.75 s > 0.5 s
    assert commands[3] == STOP


def bend_frames(radius, angle_deg, seen=6):
    """The lecture's camera approaching a bend along the centre line, `seen` frames 0.05 m
    apart ending at the bend's start, then a blank floor (the lane out of view)."""
    track = Track(segments=[{'straight': 2.0}, {'arc': {'radius': radius,
                                                         'angle_deg': angle_deg}}],
                  start=(-1.0, 0.0, 0.0))
    camera, floor = FloorCamera(LECTURE_CAMERA), FloorMap(track)
    return [camera.render(floor, track.pose_at(0.7 + 0.05 * i), Scene()) for i in range(seen)]


def test_with_the_lane_lost_it_follows_the_memory_then_turns_in_place_towards_it_then_stops():
    """The lane seen bending left, then nothing: drive on along the remembered lane while it
    lasts, then turn left in place (never forward) for at most search_angle, then stop."""
    p = ImprovedParams(search_angle=60.0, search_rate=0.5)
    ctl = make_controller('improved', LaneParams(), improved=p)
    for frame in bend_frames(0.8, 90):
        assert ctl(ctl.perceive(frame)).linear_x > 0
    blank = np.full((480, 640, 3), 90, np.uint8)
    commands = [ctl(ctl.perceive(blank)) for _ in range(60)]
    words = [c.decision for c in commands]
    first_search = words.index('search')
    assert first_search * 0.25 > p.lost_timeout  # it drove on the memory past the timeout
    assert all(c.linear_x > 0 for c in commands[:first_search])
    searching = [c for c in commands if c.decision == 'search']
    assert all(c.linear_x == 0.0 and c.angular_z == p.search_rate for c in searching)
    turned = math.degrees(sum(c.angular_z for c in searching) * 0.25)
    assert p.search_angle <= turned <= p.search_angle + math.degrees(0.5 * 0.25)
    after = commands[first_search + len(searching):]
    assert after and all(c == STOP for c in after)  # the search is done: stopped for good


def test_the_search_turns_towards_a_right_bend_and_ends_when_the_lane_is_back():
    ctl = make_controller('improved', LaneParams())
    frames = bend_frames(0.8, -90)
    for frame in frames:
        ctl(ctl.perceive(frame))
    blank = np.full((480, 640, 3), 90, np.uint8)
    commands = []
    while not commands or commands[-1].decision != 'search':
        commands.append(ctl(ctl.perceive(blank)))
        assert len(commands) < 40
    assert commands[-1].angular_z < 0 and commands[-1].linear_x == 0.0  # right, in place
    back = ctl(ctl.perceive(frames[-1]))  # the lane in view again: drive on
    assert back.decision != 'search' and back.linear_x > 0


@pytest.mark.parametrize('ahead', [0.3, 0.9])
def test_the_search_turns_the_way_the_estimate_bends_not_the_remembered_arc(ahead):
    # the estimate's lane bends left; the memory holds a centre line bending right (radius
    # 1 m) from behind the robot to `ahead` metres ahead, as an arc fitted to the memory of a
    # U-turn did on wood's hairpin, where the search turned away from the lane and departed
    ctl = make_controller('improved', LaneParams())
    ctl.estimate = LaneEstimate(0.0, 0.0, 0.4, 0.5)  # curvature 0.8 / m, left
    x = np.linspace(-0.2, ahead, 60)
    ctl.memory.add(x, -x ** 2 / 2, np.ones_like(x))
    assert ctl.search_direction() == 1.0


@pytest.mark.parametrize('k', [2.25, -2.25])
def test_a_bend_too_tight_to_reach_the_look_ahead_is_searched_for_the_way_it_goes(k):
    # an arc of radius 0.44 m never gets 0.9 m from the robot: its look-ahead point is the one
    # half way round, a lane's bend away to that side. Going on round, the arc came back
    # beside the robot, the other side of it, and on the hairpin the search turned away from
    # the lane and stalled (seed 0, clean)
    b = math.copysign(math.tan(0.1), k)
    estimate = LaneEstimate(-math.copysign(0.09, k), b, k / 2 * (1 + b * b) ** 1.5, 0.5)
    assert estimate.curvature == pytest.approx(k)
    assert estimate.lateral_at(0.9) * np.sign(k) > 0.5
    ctl = make_controller('improved', LaneParams())
    ctl.estimate = estimate
    assert ctl.search_direction() == np.sign(k)


@pytest.mark.parametrize('track, variant, seed', [
    ('s_tight', 'clean', 0), ('corner', 'clean', 0), ('hairpin', 'clean', 0),
    ('hairpin', 'noise 10', 1)])
def test_bends_the_lens_loses_the_lane_on_are_completed_never_searching_forward(
        track, variant, seed):
    """The lecture's level webcam on an S-bend whose 0.7 m bend follows at once, a 0.5 m bend
    and a 0.5 m U-turn: the lane leaves the view, and the run completes, 0 departures; while
    searching the robot never moves forward. (The U-turn with noise, seed 1, departed while
    each lane found after a search was pulled towards the arc fitted to the memory, turned
    the wrong way at a bend's entry, instead of the estimate moved with the robot.)"""
    sent = []

    def recording(name, spec, params):
        ctl = simulate.controller_for(name, spec, params)
        decide = ctl.__call__

        class Recorded:
            def __getattr__(self, attr):
                return getattr(ctl, attr)

            def __call__(self, detection, t=None):
                command = decide(detection, t)
                sent.append(command)
                return command

        return Recorded()

    spec = apply_variant(load_track(track), variant)
    result = simulate.run(spec, 'improved', seed=seed, controller_factory=recording)
    assert result['completed'] and result['departures'] == 0
    searching = [c for c in sent if c.decision == 'search']
    assert searching, 'the lane never left the view: the test tests nothing'
    assert all(c.linear_x == 0.0 and c.angular_z != 0.0 for c in searching)


def test_wood_corner_with_a_gap_in_its_outer_tape_is_completed():
    """Wood's pitched camera on the 0.5 m corner with 20 cm of its outer tape missing where
    the bend begins: beyond the gap that tape has turned across the view, a lane width left of
    where it was, and was taken for the left line of a straight lane; the robot drove out of
    the bend on the outside (53 % along, seed 0)."""
    spec = apply_variant(with_world(load_track('corner'), WORLDS['wood']), 'gap 20 cm')
    result = simulate.run(spec, 'improved', seed=0)
    assert result['completed'] and result['departures'] == 0


def test_the_improved_controller_completes_a_short_track():
    result = simulate.run(from_dict(dict(SHORT), 'short'), 'improved')
    assert result['completed'] and result['departures'] == 0
    assert result['rms_offset_m'] < 0.05 and result['mean_speed_mps'] > 0.1


def test_lane_memory_keeps_points_where_they_are_on_the_floor():
    # points seen 1 m ahead, then driven to with the simulator's own base: they must come out
    # where the base's pose says they are
    memory = LaneMemory(10.0)
    base = DiffDriveBase((0.0, 0.0, 0.0), BaseLimits(latency=0.0))
    seen = np.array([1.0, 1.2, 1.4]), np.array([0.1, 0.0, -0.1])
    memory.add(*seen, np.ones(3))
    for v, omega in [(0.2, 0.0), (0.2, 0.4), (0.1, -0.6), (0.0, 0.5)]:
        memory.move(v, omega, 0.25)
        drive(base, v, omega, 0.25)
    x, y, _ = memory.local()
    dx, dy = seen[0] - base.x, seen[1] - base.y
    c, s = math.cos(base.yaw), math.sin(base.yaw)
    assert np.allclose(x, c * dx + s * dy, atol=1e-9)
    assert np.allclose(y, -s * dx + c * dy, atol=1e-9)
    memory.move(0.0, 0.0, 10.0)  # older than `seconds`: forgotten
    assert memory.local()[0].size == 0


def straight_lane_frame():
    track = Track(segments=[{'straight': 8.0}], start=(-1.0, 0.0, 0.0))
    return FloorCamera(LECTURE_CAMERA).render(FloorMap(track), track.pose_at(1.0), Scene())


def test_the_memory_moves_with_what_was_sent_for_as_long_as_it_took():
    """On a loaded robot frames come later than the rate says, and a held robot does not move
    whatever the controller asked: the lane memory follows the frames' times and the commands
    that went out (the real-time soak lost the lane at bends without this)."""
    frame = straight_lane_frame()
    ctl = make_controller('improved', LaneParams())
    command = ctl(ctl.perceive(frame), 10.0)
    assert command.linear_x > 0
    ctl(ctl.perceive(frame), 10.6)  # 0.6 s later, not the loop's 0.25
    moved = arc_step(0.0, 0.0, 0.0, command.linear_x, command.angular_z, 0.6)
    assert np.allclose(ctl.memory.pose, moved, atol=1e-12)
    ctl.sent(STOP)  # the loop held the robot: it stood still
    ctl(ctl.perceive(frame), 10.85)
    assert np.allclose(ctl.memory.pose, moved, atol=1e-12)
    untimed = make_controller('improved', LaneParams())
    first = untimed(untimed.perceive(frame))
    untimed(untimed.perceive(frame))  # no times: one loop period, 0.25 s
    assert np.allclose(untimed.memory.pose,
                       arc_step(0.0, 0.0, 0.0, first.linear_x, first.angular_z, 0.25), atol=1e-12)


def test_the_memory_follows_odometry_not_the_commands_while_it_comes():
    """Odometry says the robot moved 0.1 m and turned 0.2 rad while the command said 0.3 m/s
    straight: the memory follows odometry; when odometry stops for more than 0.5 s it
    dead-reckons on the commands again, and both changes are logged."""
    ros = StandInRospy(SimClock(), quiet=True)
    odom = Odometry(ros, ODOM_TOPIC, msg_type=OdometryMessage)
    pub = ros.Publisher(ODOM_TOPIC, OdometryMessage, queue_size=10)
    ctl = make_controller('improved', LaneParams(), odometry=odom)
    frame = straight_lane_frame()
    pub.publish(odometry_message(1.0, 2.0, 0.5))
    command = ctl(ctl.perceive(frame), 0.0)
    assert command.linear_x > 0
    ros.clock.sleep(0.25)
    pub.publish(odometry_message(1.0 + 0.1 * math.cos(0.5), 2.0 + 0.1 * math.sin(0.5), 0.7))
    ctl(ctl.perceive(frame), 0.25)
    assert np.allclose(ctl.memory.pose, [0.1, 0.0, 0.2], atol=1e-9)  # not 0.25 s of command
    assert any('the lane memory follows it' in text for _, text in ros.log_lines)
    sent = ctl.last
    ros.clock.sleep(0.75)  # odometry silent for 0.75 s: dead reckoning on what was sent
    ctl(ctl.perceive(frame), 1.0)
    expected = arc_step(0.1, 0.0, 0.2, *sent, 0.75)
    assert np.allclose(ctl.memory.pose, expected, atol=1e-9)
    assert any('no odometry on /odom for 0.5 s' in text for _, text in ros.log_lines)


def test_the_simulated_base_publishes_its_odometry_with_slip():
    spec = from_dict(dict(SHORT), 'short')
    run = simulate.run(spec, 'improved', odometry=True, time_limit=3,
                       limits=BaseLimits(slip=0.1))
    assert run['distance_m'] > 0.3
    ros = StandInRospy(SimClock(), quiet=True)
    got = []
    ros.Subscriber(ODOM_TOPIC, OdometryMessage, got.append)
    sim = TrackSimulator(spec, ros, odometry=True, limits=BaseLimits(slip=0.1, latency=0.0))
    sim.base.command(0.0, 0.2, 0.0)
    ros.clock.sleep(0.5)  # (within the driver's 0.6 s command timeout)
    sim.read()
    assert got and got[-1].pose.pose.position.x == pytest.approx(0.1 * 1.1, abs=1e-6)
    assert sim.base.distance == pytest.approx(0.1, abs=1e-6)


def test_lane_memory_or_the_bend_holds_the_line_into_a_tight_bend(monkeypatch):
    # the camera sees the floor from 0.6 m ahead: with neither memory nor a bend in the lane
    # found, the bend's entry is steered on one arc extrapolated from there; memory steers on
    # the centre line seen earlier, the bend on an arc that begins where the bend does
    spec = {'lane_width': 0.35, 'tape_width': 0.03,
            'segments': [{'straight': 1.5}, {'arc': {'radius': 0.9, 'angle_deg': 90}},
                         {'straight': 0.8}]}
    with_memory = simulate.run(from_dict(dict(spec), 'bend'), 'improved')
    assert with_memory['completed'] and with_memory['max_offset_m'] < 0.03

    def without(name, spec, params):
        improved = replace(improved_params(spec), memory=0.0, roi_far=2.0 / 0.35,
                           curve_slowdown=0.8 / 0.35)
        return make_controller(name, params, LECTURE_CAMERA, improved)

    bend_only = simulate.run(from_dict(dict(spec), 'bend'), 'improved',
                             controller_factory=without)
    assert bend_only['completed'] and bend_only['max_offset_m'] < 0.03
    monkeypatch.setattr(lanefit, 'BEND_GAIN', 0.0)  # no bend: the one arc
    neither = simulate.run(from_dict(dict(spec), 'bend'), 'improved',
                           controller_factory=without)
    # measured: 2.25 cm with memory, 2.2 cm with the bend alone, 4.15 cm with neither
    assert neither['max_offset_m'] > 1.5 * with_memory['max_offset_m']


def test_a_run_is_deterministic_for_a_seed():
    spec = dict(SHORT, scene={'noise': 10})
    first = simulate.run(from_dict(dict(spec), 'short'), 'improved', seed=3, time_limit=4)
    second = simulate.run(from_dict(dict(spec), 'short'), 'improved', seed=3, time_limit=4)
    assert first == second


def test_departure_ends_the_run_unless_told_to_continue():
    spec = from_dict(dict(SHORT), 'short')
    # the lecture's rule goes straight at 0.05 m/s and leaves the lane on the arc
    result = simulate.run(spec, 'lecture', time_limit=60)
    assert not result['completed'] and result['ended'] in ('departure', 'stalled')


@pytest.mark.parametrize('doc, field', [
    ({}, 'segments is missing'),
    ({'segments': []}, 'segments must be a non-empty list'),
    ({'segments': [{'straight': -1}]}, 'segments[0].straight must be positive'),
    ({'segments': [{'arc': {'radius': 1.0}}]}, 'segments[0].arc.angle_deg is missing'),
    ({'segments': [{'arc': {'radius': 0, 'angle_deg': 90}}]}, 'segments[0].arc.radius'),
    ({'segments': [{'spiral': 2}]}, 'segments[0] must be'),
    ({'segments': [{'straight': 1}], 'lane_width': 'wide'}, 'lane_width must be a number'),
    ({'segments': [{'straight': 1}], 'colour': 'red'}, 'unknown key(s) colour'),
    ({'segments': [{'straight': 1}], 'scene': {'gaps': [{'line': 'middle', 'at': 1,
                                                         'length': 0.2}]}},
     'scene.gaps[0].line must be left, right or both'),
    ({'segments': [{'straight': 1}], 'camera': {'height': 0}}, 'camera.height must be positive'),
    # issue 16, case 10: accepted before, nonsense after
    ({'segments': [{'arc': {'radius': 0.15, 'angle_deg': 90}}]},
     'segments[0].arc.radius 0.15 m is not more than half the lane width'),
    ({'segments': [{'arc': {'radius': 1, 'angle_deg': 100000}}]}, 'at most 720 either way'),
    ({'segments': [{'straight': 1}], 'scene': {'floor': 300}}, 'scene.floor is a brightness'),
])
def test_malformed_tracks_name_the_field(doc, field):
    with pytest.raises(TrackError) as e:
        from_dict(doc, 'bad.yaml')
    assert field in str(e.value)


def test_track_files_yaml_json_and_builtins(tmp_path):
    (tmp_path / 't.json').write_text(json.dumps(SHORT))
    (tmp_path / 't.yaml').write_text('segments:\n  - straight: 1.0\n  - arc: {radius: 1.5, '
                                     'angle_deg: 45}\n  - straight: 0.6\n')
    a, b = load_track(str(tmp_path / 't.json')), load_track(str(tmp_path / 't.yaml'))
    assert a.track.length == pytest.approx(b.track.length) == pytest.approx(1.6 + 1.5 * math.pi / 4)
    assert load_track('oval').closed and not load_track('lecture').closed
    with pytest.raises(TrackError, match='neither a built-in track'):
        load_track(str(tmp_path / 'missing.yaml'))
    (tmp_path / 'bad.yaml').write_text('segments: [unclosed')
    with pytest.raises(TrackError, match='cannot read'):
        load_track(str(tmp_path / 'bad.yaml'))


def test_the_documented_dashes_yaml_reads_and_segment_errors_are_clean(tmp_path):
    # issue 16, case 11: YAML 1.1 reads the keys on and off as booleans
    (tmp_path / 'd.yaml').write_text('segments:\n  - straight: 2.0\n'
                                     'scene:\n  dashes: {line: left, on: 0.1, off: 0.15}\n')
    spec = load_track(str(tmp_path / 'd.yaml'))
    assert spec.dashes == {'line': 'left', 'on': 0.1, 'off': 0.15}
    (tmp_path / 'e.yaml').write_text('segments:\n  - curve: 1.0\n')
    with pytest.raises(TrackError) as e:
        load_track(str(tmp_path / 'e.yaml'))
    assert str(e.value).endswith('{arc: {radius: m, angle_deg: deg}}')


def test_simulate_command_line_writes_json_plot_and_video(tmp_path, capsys):
    track = tmp_path / 'short.json'
    track.write_text(json.dumps(SHORT))
    out = tmp_path / 'out.json'
    assert simulate.main(['--track', str(track), '--controller', 'improved', '--json', str(out),
                          '--plot', str(tmp_path / 'p.png'), '--video', str(tmp_path / 'v.avi'),
                          '--noise', '5']) == 0
    result = json.loads(out.read_text())
    for key in ('track', 'controller', 'completed', 'progress', 'distance_m', 'time_s',
                'mean_speed_mps', 'rms_offset_m', 'max_offset_m', 'departures'):
        assert key in result
    plot = cv2.imread(str(tmp_path / 'p.png'))
    assert plot is not None and plot.shape[1] > 300
    cap = cv2.VideoCapture(str(tmp_path / 'v.avi'))
    ok, frame = cap.read()
    assert ok and frame.shape[1] > 640  # onboard view and top-down side by side
    assert 'completed' in capsys.readouterr().out


def test_simulate_rejects_a_bad_track_with_status_2(tmp_path, capsys):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('segments: [{straight: -2}]')
    with pytest.raises(SystemExit) as e:
        simulate.main(['--track', str(bad)])
    assert e.value.code == 2
    assert 'segments[0].straight must be positive' in capsys.readouterr().err


@pytest.mark.parametrize('args', [['--noise', 'nan'], ['--noise', '-1'], ['--latency', '-1'],
                                  ['--accel', 'nan'], ['--camera-height', '0'],
                                  ['--camera-pitch', '90'], ['--start-offset', 'inf'],
                                  ['--time-limit', '0'], ['--time-limit', 'nan'],
                                  ['--seed', '-1'], ['--jobs', '0']])
def test_simulate_refuses_nonsense_numbers_at_start(args, capsys):
    # issue 16, cases 9 and 10: these ran and exited 0 ('RMS nan cm') or raised a traceback
    with pytest.raises(SystemExit) as e:
        simulate.main(['--track', 'lecture', *args])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert args[0] in err and 'Traceback' not in err


def test_simulate_refuses_outputs_it_cannot_write_before_the_run(tmp_path, capsys):
    # issue 16, case 9: --json onto a folder was a traceback, --plot without an extension a
    # cv2.error after the whole run (and the JSON never written)
    for args, message in ((['--json', str(tmp_path)], 'is a folder'),
                          (['--plot', str(tmp_path / 'p')], 'ending in .png'),
                          (['--video', str(tmp_path / 'v.mkv')], 'ending in .avi')):
        with pytest.raises(SystemExit) as e:
            simulate.main(['--track', 'lecture', *args])
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert message in err and 'Traceback' not in err, err


def test_the_node_runs_the_improved_controller(tmp_path):
    out = tmp_path / 'd.jsonl'
    assert node_main(['--source', SAMPLES, '--dry-run', '--controller', 'improved',
                      '--decisions', str(out), '--quiet']) == 0
    records = [json.loads(line) for line in out.read_text().splitlines()]
    p = ImprovedParams().in_metres(0.35)
    for r in records:
        assert {'offset_m', 'heading_rad', 'confidence'} <= set(r)
        assert r['decision'] in ('left', 'right', 'straight')
    # the decision word says where the lane's centre lies at the look-ahead distance, as
    # the controller's estimate has it, or, where that is within the lane and the lane is
    # seen further, how far it bends away from the line it starts along by the farthest
    # point seen (up to the floor band's end); check it against the recorded estimate
    bent = 0
    for r in records:
        bend = None if r['bend_m'] is None else (r['bend_m'], r['bend_curvature'])
        est = LaneEstimate(-r['offset_m'], -math.tan(r['heading_rad']), 0.0, 1.0, bend=bend)
        est.c = r['curvature'] * (1 + est.b ** 2) ** 1.5 / 2
        y = est.lateral_at(p.lookahead)
        turn = p.turn_offset * 0.35
        if abs(abs(y) - turn) <= 0.005:  # the records are rounded
            continue
        if abs(y) < turn and r['seen_m'] > p.lookahead:
            x, far, _ = est.point_at(min(r['seen_m'], p.roi_far))
            psi = math.atan(est.b)
            y = (far - est.a) * math.cos(psi) - x * math.sin(psi)  # from the tangent line
            bent += abs(y) > turn
            if abs(abs(y) - turn) <= 0.005:
                continue
        assert r['decision'] == ('left' if y > turn else 'right' if y < -turn
                                 else 'straight'), (r, y)
    assert bent  # some frames see their bend only beyond the look-ahead
    assert all(r['linear_x'] > 0 for r in records)


def test_the_improved_controller_reads_the_samples_regions_one_frame_at_a_time():
    # in a folder run the estimate leans on the prediction from its own commands, which a
    # recorded drive did not follow; alone, each frame says where its region goes: B bends
    # left, C right; A is the straight before B, straight until B's bend comes into view
    # beyond the look-ahead, then left
    said = {}
    for name in sorted(os.listdir(SAMPLES)):
        ctl = make_controller('improved', LaneParams())
        frame = cv2.imread(os.path.join(SAMPLES, name))
        said.setdefault(name[4], []).append(ctl(ctl.perceive(frame)).decision)
    for region, word in (('B', 'left'), ('C', 'right')):
        assert said[region].count(word) > len(said[region]) / 2, (region, said[region])
    first_left = said['A'].index('left')
    assert set(said['A'][:first_left]) == {'straight'} and first_left >= 3, said['A']
    assert set(said['A'][first_left:]) == {'left'}, said['A']


@pytest.mark.parametrize('args', [['--gap', 'left:two:0.2'], ['--gap', 'middle:1:0.2'],
                                  ['--dashes', 'both:0.1'], ['--dashes', 'left:0:0.1'],
                                  ['--controller', 'clever']])
def test_simulate_rejects_bad_scene_flags(args, capsys):
    with pytest.raises(SystemExit) as e:
        simulate.main(['--track', 'lecture', *args])
    assert e.value.code == 2
    assert 'error' in capsys.readouterr().err


def test_soak_with_frequent_faults_never_moves_while_blind():
    from tools import soak

    # every fault far more often than in the benchmark (0.04 per frame at 4 Hz), so a short
    # run meets each of them
    often = {name: (0.16, span) for name, (_, span) in soak.FAULTS.items()}
    result = soak.soak('oval', 'improved', frames=160, seed=3, progress=False, faults=often)
    assert all(count > 0 for count in result['faults'].values()), result['faults']
    assert result['ended'] == 'end of input' and result['frames'] == 160
    assert result['longest_gap_s'] <= 0.5 + 1e-9
    assert result['moving_while_camera_out'] == 0
    # covered: after lost_timeout only the remembered lane is driven (it reaches 1.2 m at
    # most), then the robot turns in place, never forward again, within the search angle
    assert result['blind_forward_m'] <= ImprovedParams().in_metres(0.35).roi_far
    assert result['forward_after_search'] == 0
    assert result['search_turn_deg'] <= ImprovedParams().search_angle + 8.0
    assert result['watchdog_stops'] > 0
    assert result['frames_failed'] == result['faults']['pipeline error']  # each one raised


def test_soak_without_the_search_never_moves_once_the_lane_is_lost():
    from tools import soak

    often = {name: (0.16, span) for name, (_, span) in soak.FAULTS.items()}
    result = soak.soak('oval', 'improved', frames=160, seed=3, progress=False, faults=often,
                       tuned=dict(search_angle=0.0))
    assert result['faults']['covered camera'] > 0
    assert result['moving_after_lane_lost'] == 0


def test_soak_counts_commands_inside_fault_intervals():
    from tools import soak

    commands = [(0.0, 0.1, 0.0), (1.0, 0.1, 0.0), (1.5, 0.0, 0.0), (2.0, 0.0, 0.3), (3.0, 0.1, 0)]
    assert soak.moving(commands, [[0.5, 2.0]]) == 2
    assert soak.moving(commands, [[0.5, 2.0]], grace=0.6) == 1
    assert soak.moving(commands, [[2.5, 2.9]]) == 0
    # in [0, 10] after 1 s: 0.2 m/s for two 0.25 s periods, a 0.5 rad/s turn for three, then
    # forward once more after the search began
    lost = [(0.5, 0.3, 0.0), (1.5, 0.2, 0.1), (1.75, 0.2, 0.0), (2.0, 0.0, 0.5),
            (2.25, 0.0, 0.5), (2.5, 0.0, -0.5), (2.75, 0.1, 0.0), (11.0, 0.3, 0.0)]
    forward, turned, after = soak.blind(lost, [[0.0, 10.0]], 1.0, 4.0)
    assert forward == pytest.approx(0.125) and after == 1
    assert turned == pytest.approx(math.degrees(1.5 * 0.25), abs=0.1)


def test_a_master_is_back_when_the_nodes_watch_hears_it_even_before_the_restart_sees_it():
    """CI, 2026-11-28: the node's watch heard the restarted master 11 ms before the restart's
    own check (which also looks for the process) returned; the node resumed and a move
    published in between was counted as one made while the master was gone."""
    from types import SimpleNamespace

    from tools import soak

    world = SimpleNamespace(outages=[[10.0, 13.04], [30.0, 33.0]])
    # the watch heard a master before the kill, then 13.02 s; it had not heard the second
    watch = SimpleNamespace(period=1.0, timeout=1.0, answered=[9.0, 13.02, 29.5])
    assert soak.master_outages(world, watch) == [[10.0, 13.02], [30.0, 33.0]]
    commands = [(11.5, 0.2, 0.0), (12.5, 0.2, 0.0), (13.03, 0.2, 0.0), (32.5, 0.0, 0.4),
                (33.5, 0.2, 0.0)]
    source = SimpleNamespace(commands=commands, outages=[], covered=[])
    received = [(t, x, z) for t, x, z in commands]
    figures = soak.master_figures(world, source, received, watch)
    assert figures['moving_while_master_lost'] == 2  # 12.5 and 32.5; not 13.03
    assert figures['moving_within_master_watch'] == 1  # 11.5, before the watch could notice
    assert figures['driving_again_after_master_s']['max'] == pytest.approx(0.5)  # 33 -> 33.5


def test_the_soaks_watch_notes_when_it_asked_each_question_the_master_answered(monkeypatch):
    from tools import soak

    replies = iter([True, False, True])
    monkeypatch.setattr(soak.MasterWatch, 'alive', lambda self: next(replies))
    watch = soak.TimedWatch(None, None, clock=iter([5.0, 6.0, 7.0]).__next__)
    assert [watch.alive() for _ in range(3)] == [True, False, True]
    assert watch.answered == [5.0, 7.0]  # asked at 5 and 7; at 6 no answer


def test_the_plots_title_has_a_band_of_its_own_above_the_track():
    """Issue 16: the stats line of --plot was written over the track."""
    from lanelib.sim.simulator import TopDown

    ros = StandInRospy(SimClock(), quiet=True)
    sim = TrackSimulator(from_dict(dict(SHORT), 'short'), ros)
    top = TopDown(sim)
    plain, titled = top.draw(), top.draw('first line\nsecond line')
    assert titled.shape[0] == plain.shape[0] + 2 * 16 + 8
    assert np.array_equal(titled[40:], plain)  # the track itself is untouched
    assert titled[:40].max() > 200  # the text is in the band


TRACKS = os.path.join(os.path.dirname(__file__), '..', 'tools', 'tracks')


@pytest.mark.parametrize('prefix, letters', [('s_unseen', 'abc'), ('s_held', 'defgh')])
def test_the_held_out_s_bends_of_the_benchmarks_load_and_turn_both_ways(prefix, letters):
    """tools/tracks: the S-bends docs/benchmarks.md measures the improved controller on, drawn
    after it was tuned (s_unseen_*) and later still (s_held_*)."""
    import yaml

    from lanelib.sim.tracks import load_track
    folder = TRACKS
    names = sorted(n for n in os.listdir(folder) if n.startswith(prefix + '_'))
    assert names == [f'{prefix}_{c}.yaml' for c in letters]
    for name in names:
        with open(os.path.join(folder, name)) as f:
            angles = [s['arc']['angle_deg'] for s in yaml.safe_load(f)['segments']
                      if 'arc' in s]
        assert min(angles) < 0 < max(angles)
        load_track(os.path.join(folder, name))


@pytest.mark.parametrize('name, turn, radius', [('duckietown_small_loop', 1, 0.41),
                                                ('duckietown_small_loop_cw', -1, 0.175)])
def test_the_duckietown_small_loops_close_on_themselves_with_the_maps_corners(name, turn,
                                                                             radius):
    spec = load_track(os.path.join(TRACKS, name + '.yaml'))
    assert spec.world.name == 'duckietown' and spec.track.lane_width == 0.2375
    assert spec.closed  # the loop ends where it starts, heading as it started
    arcs = [s['arc'] for s in spec.track.segments if 'arc' in s]
    assert [a['angle_deg'] for a in arcs] == [turn * 90] * 4
    assert {a['radius'] for a in arcs} == {radius}
    # the lane's centre half a lane width outside (or inside) the road's, 0.2925 m round
    assert radius == pytest.approx(0.585 / 2 + turn * spec.track.lane_width / 2, abs=0.002)


@pytest.mark.parametrize('world, radius, angle, message', [
    ('duckietown', 0.3, 90, "duckietown world's line 1.5 lane widths to the left"),
    ('duckietown', 0.15, -90, "duckietown world's line 0.5 lane widths to the right"),
    ('wood', 0.19, 90, "wood world's line 0.5 lane widths to the left"),
])
def test_a_bend_too_tight_for_a_worlds_lines_is_refused_with_the_worlds_lane(world, radius,
                                                                            angle, message):
    # checked before against the file's lane (the lecture's 0.35 m by default), so a
    # Duckietown inner corner (0.175 m) was refused and Duckietown's other lane, 1.5 lane
    # widths over, was drawn crossing itself in a left bend of 0.3 m
    doc = {'world': world, 'segments': [{'arc': {'radius': radius, 'angle_deg': angle}}]}
    with pytest.raises(TrackError) as e:
        from_dict(doc, 'bad.yaml')
    assert message in str(e.value) and 'cross itself' in str(e.value)
    doc['segments'][0]['arc']['radius'] = radius + 0.11
    assert from_dict(doc, 'ok.yaml').track.segments[0]['arc']['radius'] == radius + 0.11
    # and so is a built-in track moved to a world whose lines it is too tight for
    with pytest.raises(TrackError):
        with_world(from_dict({'segments': [{'arc': {'radius': 0.3, 'angle_deg': 90}}]}, 't'),
                   WORLDS['duckietown'])


def test_the_track_says_its_curvature_and_the_simulator_where_the_robot_is_in_its_lane():
    track = Track(segments=[{'straight': 1.0}, {'arc': {'radius': 0.5, 'angle_deg': 90}},
                            {'arc': {'radius': 2.0, 'angle_deg': -45}}])
    quarter = 0.5 * math.pi / 2
    assert [track.curvature_at(s) for s in (0.5, 1.0 + quarter / 2, 1.0 + quarter + 0.1, 99)] \
        == [0.0, 2.0, -0.5, -0.5]
    spec = from_dict(dict(SHORT), 'short')
    sim = TrackSimulator(spec, StandInRospy(SimClock(), quiet=True), start_offset=0.04,
                         start_yaw=math.radians(-10))
    offset, heading, curvature = sim.truth()
    assert (offset, math.degrees(heading), curvature) == pytest.approx((0.04, -10.0, 0.0))


def test_estimate_metrics_compare_the_estimate_with_the_truth():
    readings = [  # truth (offset, heading, k), estimate (offset, heading, k)
        (0.00, 0.0, 0.0, 0.01, math.radians(2), 0.1),
        (0.02, 0.0, 0.0, 0.02, 0.0, -0.1),
        (0.00, 0.0, 2.0, 0.03, math.radians(4), 1.0),  # a bend read half as tight
        (0.01, 0.0, -4.0, 0.01, 0.0, -2.0),
        (0.00, 0.0, 2.0, None, None, None),  # no estimate: not counted
    ]
    m = simulate.estimate_metrics(readings)
    assert m['frames'] == 4 and m['of'] == 5 and m['bend_frames'] == 2
    assert m['bend_curvature_read'] == 0.5
    assert m['straight_curvature'] == 0.0
    assert m['offset_error_cm'][0] == pytest.approx(0.5)
    assert m['heading_error_deg'][0] == pytest.approx(1.0)
    assert 'read 50% of their curvature' in simulate.describe_estimate(m)
    assert simulate.estimate_metrics([(0.0, 0.0, 0.0, None, None, None)]) is None


def test_simulate_drives_with_a_robot_preset_as_the_node_resolves_it(tmp_path, capsys):
    track = os.path.join(TRACKS, 'duckietown_small_loop.yaml')
    runs = {}
    for name, robot in (('preset', ['--robot', 'duckiebot']), ('world', [])):
        out = tmp_path / f'{name}.json'
        assert simulate.main(['--track', track, '--controller', 'improved', '--time-limit', '4',
                              '--json', str(out), *robot]) == 1  # the lap takes longer
        runs[name] = json.loads(out.read_text())
    # the preset's loop rate (config/duckiebot.yaml: 8 Hz), not the simulator's 4 Hz
    assert runs['preset']['estimate']['of'] == pytest.approx(2 * runs['world']['estimate']['of'],
                                                             abs=2)
    assert runs['preset']['estimate']['frames'] > 25
    assert 'estimate on' in capsys.readouterr().out
    # the Kobuki's preset is the simulator's own settings in the lecture's world
    kobuki, plain = tmp_path / 'k.json', tmp_path / 'p.json'
    for out, robot in ((kobuki, ['--robot', 'kobuki']), (plain, [])):
        simulate.main(['--track', 'corner', '--controller', 'improved', '--time-limit', '6',
                       '--json', str(out), *robot])
    assert json.loads(kobuki.read_text()) == json.loads(plain.read_text())
    with pytest.raises(SystemExit) as e:
        simulate.main(['--track', 'lecture', '--robot', 'no-such-robot'])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert "--robot: robot 'no-such-robot' is neither" in err and 'Traceback' not in err
    with pytest.raises(SystemExit) as e:
        simulate.main(['--benchmark', '--robot', 'duckiebot'])
    assert e.value.code == 2 and 'leave one of them out' in capsys.readouterr().err


def test_the_benchmark_drives_the_tracks_given_in_every_world_once_per_seed(tmp_path, capsys):
    """--benchmark --tracks: the improved controller alone on each track as drawn, in each
    world asked, once per seed, with a line per world of how many runs completed (how the
    S-bends drawn after tuning are scored: docs/benchmarks.md), every run started where
    --start-offset and --start-yaw say; a bad track is refused before any run, the two options
    only go with --benchmark, and the options of one run it would not use are refused."""
    track = tmp_path / 'short.yaml'
    track.write_text(json.dumps(SHORT))
    out = tmp_path / 'runs.json'
    code = simulate.main(['--benchmark', '--tracks', str(track), '--worlds', 'lecture', 'wood',
                          '--seeds', '0', '1', '--jobs', '1', '--json', str(out)])
    printed = capsys.readouterr().out
    runs = json.loads(out.read_text())
    assert [(r['world'], r['seed'], r['controller'], r['variant']) for r in runs] == [
        ('lecture', 0, 'improved', 'clean'), ('lecture', 1, 'improved', 'clean'),
        ('wood', 0, 'improved', 'clean'), ('wood', 1, 'improved', 'clean')]
    assert all(r['track'] == 'short.yaml' for r in runs)
    assert runs[0]['estimate'] != runs[1]['estimate']  # the seeds' noise differs: so do the
    # lanes read from it (the paths driven can agree to the tenth of a millimetre)
    done = {w: sum(r['completed'] for r in runs if r['world'] == w) for w in ('lecture', 'wood')}
    assert f"lecture: the improved controller completed {done['lecture']} of 2 runs" in printed
    assert f"wood: the improved controller completed {done['wood']} of 2 runs" in printed
    assert code == (0 if sum(done.values()) == 4 else 1)
    assert '| lecture | short.yaml | 1 | improved | clean |' in printed
    # every run started off the centre line, as one run's --start-offset and --start-yaw do
    moved = tmp_path / 'moved.json'
    simulate.main(['--benchmark', '--tracks', str(track), '--worlds', 'lecture', '--jobs', '1',
                   '--start-offset', '0.02', '--start-yaw', '-2', '--json', str(moved)])
    (run,) = json.loads(moved.read_text())
    assert (run['start_offset_m'], run['start_yaw_deg'], run['seed']) == (0.02, -2.0, 0)
    assert run['rms_offset_m'] != runs[0]['rms_offset_m']
    assert 'started +0.02 m and -2 degrees off the centre line' in capsys.readouterr().out
    for argv, message in ((['--benchmark', '--tracks', str(tmp_path / 'none.yaml')],
                           "--tracks: '"), (['--tracks', str(track)], 'go with --benchmark'),
                          (['--seeds', '1'], 'go with --benchmark'),
                          (['--benchmark', '--noise', '5', '--continue'],
                           '--continue, --noise: for one run; --benchmark drives its own'),
                          (['--benchmark', '--tracks', str(track), '--controller', 'improved'],
                           '--controller: for one run')):
        with pytest.raises(SystemExit) as e:
            simulate.main(argv)
        assert e.value.code == 2 and message in capsys.readouterr().err
