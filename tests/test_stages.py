"""Each stage of the lecture's pipeline on synthetic images and segment sets with known answers."""

import math

import cv2
import numpy as np
import pytest

from kobuki_lane import LaneParams, LectureRule, calibration_camera, detect
from lanelib.camera import LECTURE_CAMERA
from lanelib.geometry import Mounting
from lanelib.robot import STOP
from lanelib.sim.world import FloorCamera, FloorMap, Scene, Track
from lanelib.stages import (
    Detection,
    as_bgr,
    hough_lines,
    region_of_interest,
    region_of_interest_vertices,
    slope_sum,
)


def lecture_loop(lines):
    """The slides' slope loop, line for line (vertical segments left out: it crashes on them)."""
    theta = 0
    right_slope, rc, left_slope, lc = 0, 1, 0, 1
    for x in range(0, len(lines)):
        for x1, y1, x2, y2 in lines[x]:
            theta = theta + math.atan2((y2 - y1), (x2 - x1))
            slope = (y2 - y1) / (x2 - x1)
            if math.fabs(slope) < 0.5:
                continue
            if slope <= 0:
                left_slope += slope
                lc += 1
            else:
                rc += 1
                right_slope += slope
    if rc > 1:
        rc -= 1
    if lc > 1:
        lc -= 1
    return theta, (left_slope / lc) + (right_slope / rc)


def test_roi_triangle_is_the_lectures_and_scales_with_the_frame():
    assert region_of_interest_vertices(640, 480).tolist() == [[[0, 480], [320, 240], [640, 480]]]
    assert region_of_interest_vertices(1280, 720).tolist() == [[[0, 720], [640, 360], [1280, 720]]]
    assert region_of_interest_vertices(3, 1).tolist() == [[[0, 1], [1, 0], [3, 1]]]


def test_region_of_interest_keeps_only_the_triangle():
    img = np.full((480, 640), 255, np.uint8)
    out = region_of_interest(img, region_of_interest_vertices(640, 480))
    assert out[470, 320] == 255 and out[300, 320] == 255  # inside, below the apex
    assert out[10, 10] == 0 and out[10, 630] == 0 and out[200, 320] == 0  # above it
    assert out[479, 1] == 255 and out[470, 20] == 255 and out[470, 5] == 0  # the slanted side
    # about half of the lower half of the frame survives
    assert abs(np.count_nonzero(out) / (640 * 240) - 0.5) < 0.02


def test_hough_finds_a_drawn_segment_and_returns_empty_not_none():
    p = LaneParams()
    edges = np.zeros((480, 640), np.uint8)
    assert hough_lines(edges, p).shape == (0, 4)
    cv2.line(edges, (100, 450), (300, 250), 255, 1)  # 200 px at 45 degrees
    lines = hough_lines(edges, p)
    assert len(lines) >= 1
    for x1, y1, x2, y2 in lines:
        angle = math.degrees(math.atan2(y2 - y1, x2 - x1)) % 180
        assert abs(angle - 135) < 4  # within the pi/60 (3 degree) accumulator step
        assert min(x1, x2) >= 95 and max(x1, x2) <= 305


@pytest.mark.parametrize('seed', range(20))
def test_slope_sum_equals_the_lectures_loop(seed):
    rng = np.random.default_rng(seed)
    lines = rng.integers(0, 640, size=(rng.integers(1, 30), 1, 4))
    lines = lines[lines[:, 0, 0] != lines[:, 0, 2]]  # the lecture's loop crashes on vertical ones
    theta, value = lecture_loop(lines)
    s = slope_sum(lines)
    assert s.theta == pytest.approx(theta, abs=1e-12)
    assert s.value == pytest.approx(value, abs=1e-12)


def test_vertical_segments_count_in_theta_but_in_no_slope_group():
    lines = np.array([[10, 400, 10, 100], [200, 100, 200, 400], [0, 100, 100, 300]])
    s = slope_sum(lines)
    assert s.theta == pytest.approx(-math.pi / 2 + math.pi / 2 + math.atan2(200, 100))
    assert s.vertical == 2
    assert (s.left_count, s.right_count) == (0, 1)
    assert s.value == pytest.approx(2.0)


def test_shallow_segments_join_neither_group_and_value_is_per_group_mean():
    lines = np.array([[0, 0, 100, 10],  # slope 0.1: skipped
                      [0, 100, 100, 0], [0, 300, 100, 100],  # slopes -1, -2: left
                      [0, 0, 100, 300]])  # slope 3: right
    s = slope_sum(lines)
    assert (s.left_count, s.right_count) == (2, 1)
    assert s.value == pytest.approx((-1 - 2) / 2 + 3 / 1)


def rule(theta, n=3, **overrides):
    p = LaneParams(**overrides)
    lines = np.zeros((n, 4), np.int32)
    det = Detection(lines, slope_sum(np.empty((0, 4))), None)
    det.slopes.theta = theta
    return LectureRule(p)(det)


def test_the_lectures_rule_and_its_silent_cases():
    left, right, straight = rule(6.01), rule(-6.01), rule(5.99)
    assert (left.decision, left.linear_x, left.angular_z) == ('left', 0.01, 0.06)
    assert (right.decision, right.linear_x, right.angular_z) == ('right', 0.01, -0.06)
    assert (straight.decision, straight.linear_x, straight.angular_z) == ('straight', 0.05, 0.0)
    # |theta| == 6 exactly and no segments: the lecture published nothing; we stop
    assert rule(6.0) == STOP and rule(-6.0) == STOP
    assert rule(0.0, n=0) == STOP
    assert rule(2.0, threshold=1.5, turn_angular=0.2).angular_z == 0.2


def test_gray_comes_from_the_undistorted_frame():
    rng = np.random.default_rng(0)
    frame = cv2.GaussianBlur(rng.integers(0, 255, (480, 640, 3), dtype=np.uint8), (9, 9), 0)
    d = detect(frame, LECTURE_CAMERA, LaneParams(), keep_stages=True)
    undistorted = calibration_camera(frame, LECTURE_CAMERA)
    assert np.array_equal(d.stages['gray'], cv2.cvtColor(undistorted, cv2.COLOR_BGR2GRAY))
    raw_gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    assert np.mean(np.abs(d.stages['gray'].astype(int) - raw_gray)) > 5


def test_the_lectures_camera_numbers_are_exact():
    k, dist = LECTURE_CAMERA.matrix, LECTURE_CAMERA.distortion
    assert k.tolist() == [[893.45537548, 0.0, 309.61828309], [0.0, 866.99738285, 196.40832355],
                          [0.0, 0.0, 1.0]]
    assert dist.tolist() == [2.28504143e-01, -7.32838958e+00, -2.43747623e-02, 9.12080996e-03,
                             3.98425001e+01]


@pytest.mark.parametrize('frame', [
    np.full((480, 640), 128, np.uint8),
    np.full((480, 640, 1), 128, np.uint8),
    np.full((480, 640, 4), 128, np.uint8),
    np.full((480, 640, 3), 128 * 256, np.uint16),
    np.full((480, 640, 3), 0.5, np.float32),
])
def test_any_frame_type_becomes_8bit_bgr(frame):
    out = as_bgr(frame)
    assert out.shape == (480, 640, 3) and out.dtype == np.uint8
    assert abs(int(out[0, 0, 0]) - 128) <= 1


@pytest.mark.parametrize('shape', [(1, 1), (1, 1, 3), (7, 3, 4), (37, 1001, 3), (1080, 1920, 3)])
def test_unusual_sizes_go_through_the_pipeline(shape):
    frame = np.random.default_rng(1).integers(0, 255, shape, dtype=np.uint8)
    for calibration in (LECTURE_CAMERA, None):
        d = detect(frame, calibration, LaneParams())
        assert d.lines.shape[1] == 4 and math.isfinite(d.slopes.theta)


@pytest.fixture(scope='module')
def straight_view():
    track = Track(segments=[{'straight': 8.0}], start=(-1.0, 0.0, 0.0))
    camera = FloorCamera(LECTURE_CAMERA, Mounting())
    return camera.render(FloorMap(track), track.pose_at(1.0), Scene(noise=0))


def test_a_straight_lane_gives_both_lines_inside_the_roi(straight_view):
    p = LaneParams()
    d = detect(straight_view, LECTURE_CAMERA, p)
    assert d.slopes.left_count >= 1 and d.slopes.right_count >= 1
    assert LectureRule(p)(d).decision == 'straight'
    h, w = straight_view.shape[:2]
    for _x1, y1, _x2, y2 in d.lines:  # every segment lies in the triangle's band of rows
        assert min(y1, y2) >= h / 2 - 2


def test_algorithm_1_0_sees_the_wall_edges_that_1_1_masks(straight_view):
    lines_11 = detect(straight_view, LECTURE_CAMERA, LaneParams(algorithm='1.1')).lines
    lines_10 = detect(straight_view, LECTURE_CAMERA, LaneParams(algorithm='1.0')).lines
    assert len(lines_10) > len(lines_11)
    assert any(min(y1, y2) < 200 for x1, y1, x2, y2 in lines_10)  # above the triangle
