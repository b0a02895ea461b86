"""The fast pipeline against detect(), the slides' calls: the same segments, frame by frame."""

import cv2
import numpy as np
import pytest

from kobuki_lane import LaneParams, calibration_camera, detect, make_controller
from lanelib.camera import LECTURE_CAMERA, undistortion_maps
from lanelib.fast import FastPipeline
from lanelib.improved import ImprovedParams
from lanelib.stages import hough_lines, region_of_interest_vertices
from tools.bench import cluttered_frame, improved_controller, sample_frames, simulator_frames


@pytest.fixture(scope='module')
def frames():
    rng = np.random.default_rng(5)
    sim = simulator_frames(200, seed=3)  # every built-in track and condition, random poses
    noisy = [np.clip(f + rng.normal(0, 25, f.shape), 0, 255).astype(np.uint8) for f in sim[:20]]
    return sample_frames() + sim + noisy + [cluttered_frame(1), cluttered_frame(2)]


@pytest.mark.parametrize('algorithm', ['1.1', '1.0'])
def test_segments_identical_to_detect(frames, algorithm):
    p = LaneParams(algorithm=algorithm)
    pipeline = FastPipeline(p, detect)
    found = 0
    for i, frame in enumerate(frames):
        reference = detect(frame, LECTURE_CAMERA, p)
        ours = pipeline(frame, LECTURE_CAMERA)
        assert np.array_equal(ours.lines, reference.lines), f'frame {i}'
        assert ours.slopes.theta == pytest.approx(reference.slopes.theta, abs=1e-9)
        found += len(reference.lines)
    assert found > len(frames)  # the frames do have segments to compare


def test_undistortion_maps_give_exactly_cv2_undistort(frames):
    maps = undistortion_maps(LECTURE_CAMERA, 640, 480)
    for frame in frames[::25]:
        assert np.array_equal(cv2.remap(frame, *maps, cv2.INTER_LINEAR),
                              calibration_camera(frame, LECTURE_CAMERA))


def test_the_whole_undistorted_image_is_still_there_for_pictures(frames):
    detection = FastPipeline(LaneParams(), detect)(frames[0], LECTURE_CAMERA)
    assert np.array_equal(detection.image, calibration_camera(frames[0], LECTURE_CAMERA))


def pieces_of(detection):
    return [(p.colour, p.x.tolist(), p.y.tolist()) for p in detection.pieces]


def test_improved_perception_band_matches_the_whole_frame(frames):
    # the improved controller undistorts only the floor band's rows; keep_stages makes it
    # undistort the whole frame: the same masks and the same pieces of tape, to the bit
    improved = make_controller('improved', LaneParams())
    found = 0
    for frame in frames[::4]:
        band = improved.perceive(frame)
        whole = improved.perceive(frame, keep_stages=True)
        (masks, first), (full, zero) = band.masks, whole.masks
        assert zero == 0 and first > 0
        for colour, mask in masks.items():
            assert np.array_equal(mask, full[colour][first:first + len(mask)]), colour
        assert pieces_of(band) == pieces_of(whole)
        found += len(band.pieces)
    assert found > len(frames[::4])  # there were pieces to compare


def whole_frame(frame, p):
    """The stages on every pixel, with p's settings (the lecture's calls, parameterised)."""
    edges = cv2.Canny(cv2.GaussianBlur(cv2.cvtColor(calibration_camera(frame, LECTURE_CAMERA),
                                                    cv2.COLOR_BGR2GRAY), (5, 5), 0),
                      p.canny_low, p.canny_high)
    mask = np.zeros_like(edges)
    cv2.fillPoly(mask, region_of_interest_vertices(640, 480), 255)
    return hough_lines(cv2.bitwise_and(edges, mask), p)


def test_hysteresis_settings_still_match_the_whole_frame(frames):
    # with canny_low < canny_high weak edges may link across rows, so no rows are skipped
    p = LaneParams(canny_low=40.0, canny_high=120.0)
    pipeline = FastPipeline(p, detect)
    for frame in frames[::10]:
        assert np.array_equal(pipeline(frame, LECTURE_CAMERA).lines, whole_frame(frame, p))


def test_frame_size_and_camera_changes_rebuild_the_layout(frames):
    pipeline = FastPipeline(LaneParams(), detect)
    small = cv2.resize(frames[3], (320, 240))
    a = pipeline(small, LECTURE_CAMERA).lines
    pipeline(frames[3], LECTURE_CAMERA)
    b = pipeline(small, LECTURE_CAMERA).lines
    c = FastPipeline(LaneParams(), detect)(small, None).lines
    d = pipeline(small, None).lines
    assert np.array_equal(a, b) and np.array_equal(c, d)


def test_improved_perception_does_not_read_dense_texture(frames):
    # random texture and 300 random lines: the lecture's pipeline finds segments in it, the
    # improved controller no piece as wide and as long as a tape, so it never starts driving
    improved = make_controller('improved', LaneParams())
    cluttered = improved.perceive(cluttered_frame(4))
    assert cluttered.pieces == []
    assert improved(cluttered).decision == 'none'
    tape = improved.perceive(frames[0])
    assert not tape.cluttered and len(tape.pieces) > 2
    assert improved(tape).decision != 'none'
    assert len(FastPipeline(LaneParams(), detect)(cluttered_frame(4), LECTURE_CAMERA).lines) > 0


def test_improved_perception_reads_at_most_max_pieces(frames):
    improved = make_controller('improved', LaneParams(), improved=ImprovedParams(max_pieces=3))
    detection = improved.perceive(frames[0])
    assert detection.cluttered and len(detection.pieces) == 3
    everything = make_controller('improved', LaneParams()).perceive(frames[0]).pieces
    assert [p.length for p in detection.pieces] == sorted(p.length for p in everything)[:-4:-1]


def test_the_benchmarks_literal_dry_run_is_the_nodes_main_with_the_slides_calls(capsys):
    """tools.bench times kobuki_lane.main() with the literal pipeline swapped in through
    make_controller; it must keep up with that function's arguments."""
    from helpers import SAMPLES

    from tools.bench import literal_dry_run

    assert literal_dry_run(['--source', SAMPLES, '--dry-run', '--quiet', '--progress',
                            'off']) == 0
    assert 'straight 28' in capsys.readouterr().err


def test_the_benchmark_drives_a_preset_with_the_settings_the_node_resolves_from_it():
    # tools.bench's 'driving with --robot duckiebot' row: the preset's settings, as
    # `--robot duckiebot --controller improved` gives them, but the simulated camera's mounting
    from lanelib.sim.tracks import load_track, with_world
    from lanelib.sim.world import WORLDS
    from simulate import robot_settings

    spec = with_world(load_track('s_bend'), WORLDS['duckietown'])
    params, improved = robot_settings('duckiebot', spec)
    assert params.rate == 8  # the preset's loop rate, not the lecture's 4 Hz
    assert (improved.lane, improved.v_max, improved.roi_near, improved.bend_belief,
            improved.pitch_tolerance, improved.one_line_width) == (
        'duckietown', 1.25, 0.42, 1.0, 4.0, 'measured')
    assert (improved.camera_height, improved.camera_pitch) == (spec.mounting.height,
                                                                spec.mounting.pitch_deg)
    assert improved.lane_width == spec.track.lane_width


def test_the_benchmark_judges_every_driving_row_against_the_aim_by_its_median_and_p95():
    from tools.bench import against_aim

    def row(median, p95):
        return dict(total=dict(median_ms=median, p95_ms=p95))

    rows = dict(Kobuki=row(6.8, 7.5), duckiebot=row(6.0, 8.1))
    aim = against_aim(rows, 3.4)
    assert (aim['slowest_median_ms'], aim['largest_p95_ms'], aim['under_aim']) == (6.8, 8.1, True)
    assert aim['over_literal'] == dict(Kobuki=2.0, duckiebot=1.76)
    # one row's p95 over the aim is enough to miss it, and so is one row's median
    assert not against_aim(dict(rows, odometry=row(6.5, 10.2)), 3.4)['under_aim']
    assert not against_aim(dict(rows, odometry=row(10.0, 10.0)), 3.4)['under_aim']
    assert against_aim(rows, 3.4, aim_ms=8.0)['under_aim'] is False


def test_the_benchmark_times_the_improved_perception_with_the_lane_profile_asked_for():
    frame = sample_frames()[0]
    for lane, colours in (('lecture', {'any', 'red'}), ('duckietown', {'white', 'yellow', 'red'})):
        stages = []
        read = improved_controller(stages.append, lane)
        controller = read(frame)
        assert controller.profile.name == lane
        assert set(controller.perceive(frame).masks[0]) == colours
        assert stages[:4] == ['start', 'undistort', 'colour', 'pieces']


def test_a_frame_read_at_half_its_width_gives_the_same_lane():
    # --read-width 320: the Duckiebot's 640 x 480 frames read at 320 x 240, the camera matrix
    # shrunk with them, so the lane on the floor is where the whole frame has it
    import math
    from dataclasses import replace

    from lanelib.camera import CAMERAS
    from lanelib.sim.tracks import load_track, with_world
    from lanelib.sim.world import WORLDS, FloorCamera, FloorMap
    from simulate import robot_settings

    spec = with_world(load_track('s_bend'), WORLDS['duckietown'])
    params, improved = robot_settings('duckiebot', spec)
    assert improved.read_width == 320  # as the preset reads them (docs/benchmarks.md)
    camera = CAMERAS[spec.camera]
    view = FloorCamera(camera, spec.mounting)
    floor = FloorMap(spec.track, spec.gaps, spec.dashes)
    rng = np.random.default_rng(0)
    for s, offset, yaw in [(0.5, 0.03, 5.0), (0.8, -0.03, -6.0), (3.0, -0.02, 0.0)]:
        frame = view.render(floor, spec.track.pose_at(s, offset, math.radians(yaw)),
                            spec.scene, rng)
        lanes = {}
        for width in (0, 320, 1000):  # 1000: wider than the frame, which is read as it comes
            controller = make_controller('improved', params, camera,
                                         replace(improved, read_width=width))
            controller(controller.perceive(frame))
            lanes[width] = controller.estimate, controller.view.key[1:3]  # the size read
        (whole, seen), (half, shrunk), (same, as_is) = lanes[0], lanes[320], lanes[1000]
        assert (seen, shrunk, as_is) == ((640, 480), (320, 240), (640, 480))
        assert half.offset == pytest.approx(whole.offset, abs=0.005)
        assert half.heading == pytest.approx(whole.heading, abs=math.radians(1))
        assert half.curvature == pytest.approx(whole.curvature, abs=0.1)
        assert (same.offset, same.heading) == (whole.offset, whole.heading)
        assert whole.offset == pytest.approx(offset, abs=0.02)  # the pose rendered


def test_maps_that_read_two_columns_as_one_average_them_as_inter_area_does():
    # column_binning 2 undistorts a 640 x 480 frame straight into 320 x 480 (no shrunk copy
    # made): each pixel read half way between two columns, which the linear remap averages,
    # as cv2.resize's INTER_AREA does; read at 2 x, every other column, it would not be
    from lanelib.camera import Camera
    plain = Camera('plain', LECTURE_CAMERA.matrix, np.zeros(5), (640, 480))  # no distortion
    stripes = np.zeros((480, 640, 3), np.uint8)
    stripes[:, ::2] = 200  # every other column lit: binned, every pixel 100
    rng = np.random.default_rng(0)
    noisy = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
    maps = undistortion_maps(plain, 320, 480, source=(640, 480))
    for frame in (stripes, noisy):
        read = cv2.remap(frame, *maps, cv2.INTER_LINEAR)
        area = cv2.resize(frame, (320, 480), interpolation=cv2.INTER_AREA)
        assert read.shape == area.shape
        assert np.abs(read[:, :-1].astype(int) - area[:, :-1]).max() <= 1  # rounding
    assert np.all(cv2.remap(stripes, *maps, cv2.INTER_LINEAR)[:, :-1] == 100)
    # with the lecture camera's distortion, close to a shrunk frame undistorted
    frame = simulator_frames(1, seed=4)[0]
    read = cv2.remap(frame, *undistortion_maps(LECTURE_CAMERA, 320, 480, source=(640, 480)),
                     cv2.INTER_LINEAR)
    shrunk = cv2.remap(cv2.resize(frame, (320, 480), interpolation=cv2.INTER_AREA),
                       *undistortion_maps(LECTURE_CAMERA, 320, 480), cv2.INTER_LINEAR)
    assert np.mean(np.abs(read.astype(int) - shrunk)) < 2


def test_the_improved_controller_reads_two_columns_as_one_and_finds_the_same_lane():
    # the default column_binning 2: the lecture world's 640 x 480 frames read at 320 x 480,
    # every row kept, the camera matrix's columns halved: on its straights (a single frame
    # of a bend is the search's to guess) the lane where it was rendered, as with every
    # column; with no calibration the frame is shrunk so; the pictures are stretched back to
    # the frame's width
    import math
    from dataclasses import replace

    from lanelib.camera import CAMERAS
    from lanelib.sim.tracks import load_track, with_world
    from lanelib.sim.world import WORLDS, FloorCamera, FloorMap
    from simulate import improved_params

    spec = with_world(load_track('lecture'), WORLDS['lecture'])
    improved = improved_params(spec)
    assert improved.column_binning == 2 and ImprovedParams().column_binning == 2
    camera = CAMERAS[spec.camera]
    view = FloorCamera(camera, spec.mounting)
    floor = FloorMap(spec.track, spec.gaps, spec.dashes)
    rng = np.random.default_rng(1)
    for s, offset, yaw in [(0.0, 0.03, 5.0), (0.5, -0.03, -6.0), (6.0, 0.0, 0.0)]:
        frame = view.render(floor, spec.track.pose_at(s, offset, math.radians(yaw)),
                            spec.scene, rng)
        sizes = {}
        for binning in (1, 2):
            controller = make_controller('improved', LaneParams(), camera,
                                         replace(improved, column_binning=binning))
            controller(controller.perceive(frame))
            sizes[binning] = controller.view.key[1:]
            estimate = controller.estimate
            assert estimate.offset == pytest.approx(offset, abs=0.015)  # the pose rendered
            assert math.degrees(estimate.heading) == pytest.approx(yaw, abs=1.5)
        assert sizes == {1: (640, 480, None), 2: (320, 480, (640, 480))}
    detection = controller.perceive(frame, keep_stages=True)
    assert detection.image.shape[:2] == (480, 320)
    command = controller(detection)
    for _, _, picture in controller.pictures(detection, command):  # as wide as the frame
        assert picture.shape[1] == 640
    assert controller.draw(detection, command).shape[1] == 640
    bare = make_controller('improved', LaneParams(), None, improved)  # frames as they come
    bare(bare.perceive(frame))
    assert bare.view.key[1:] == (320, 480, (640, 480)) and bare.view.maps is None
    detection = bare.perceive(frame, keep_stages=True)
    assert detection.image.shape[:2] == (480, 320)
    for _, _, picture in bare.pictures(detection, bare(detection)):  # the raw frame's too
        assert picture.shape[1] == 640
    # shrunk to read_width as well: one resize from the frame to the size read, not a
    # shrunk copy resized again
    small = make_controller('improved', LaneParams(), None, replace(improved, read_width=320))
    small(small.perceive(frame))
    assert small.view.key[1:] == (160, 240, (320, 240))
    once = cv2.resize(frame, (160, 240), interpolation=cv2.INTER_AREA)
    twice = cv2.resize(cv2.resize(frame, (320, 240), interpolation=cv2.INTER_AREA), (160, 240),
                       interpolation=cv2.INTER_AREA)
    assert not np.array_equal(once, twice)  # the frame tells them apart
    assert np.array_equal(small.view.read(frame), once)
    assert np.array_equal(small.perceive(frame, keep_stages=True).image, once)
