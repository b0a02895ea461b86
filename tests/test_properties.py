"""Property tests: any image through the whole pipeline and both controllers, and any segment
set through the lecture's rule."""

import math

import numpy as np
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from kobuki_lane import LaneFollower, LaneParams, LectureRule, make_controller
from lanelib.camera import LECTURE_CAMERA
from lanelib.robot import MAX_ANGULAR, MAX_LINEAR
from lanelib.rospy_standin import SimClock, StandInRospy, Twist
from lanelib.safety import SafeBase
from lanelib.stages import Detection, slope_sum

WORDS = {'left', 'right', 'straight', 'none'}


@st.composite
def images(draw):
    big = draw(st.booleans())
    h = draw(st.integers(1, 1080 if big else 64))
    w = draw(st.integers(1, 1920 if big else 64))
    channels = draw(st.sampled_from([1, 3, 4]))
    dtype = draw(st.sampled_from([np.uint8, np.uint16]))
    top = 255 if dtype == np.uint8 else 65535
    kind = draw(st.sampled_from(['flat', 'noise', 'stripes', 'lines']))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    shape = (h, w) if channels == 1 else (h, w, channels)
    if kind == 'flat':
        img = np.full(shape, draw(st.integers(0, top)), dtype)
    elif kind == 'noise':
        img = rng.integers(0, top + 1, shape, dtype=dtype)
    elif kind == 'stripes':
        period = draw(st.integers(1, 40))
        angle = draw(st.floats(0, math.pi))
        y, x = np.mgrid[0:h, 0:w]
        band = ((x * math.cos(angle) + y * math.sin(angle)) // period) % 2
        img = (band * top).astype(dtype)
        if channels > 1:
            img = np.repeat(img[..., None], channels, axis=2)
    else:
        img = np.zeros(shape, dtype)
        for _ in range(draw(st.integers(1, 30))):
            x1, x2 = rng.integers(0, w, 2)
            y1, y2 = rng.integers(0, h, 2)
            n = int(max(abs(x2 - x1), abs(y2 - y1))) + 1
            img[np.linspace(y1, y2, n).astype(int), np.linspace(x1, x2, n).astype(int)] = top
    return img


def follower(controller_name, algorithm, camera):
    ros = StandInRospy(SimClock(), quiet=True, keep=10)
    p = LaneParams(algorithm=algorithm)
    controller = make_controller(controller_name, p, camera)
    return ros, LaneFollower(ros, None, controller, SafeBase(ros, Twist), rate=p.rate)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frame=images(), controller=st.sampled_from(['lecture', 'improved']),
       algorithm=st.sampled_from(['1.1', '1.0']),
       camera=st.sampled_from([LECTURE_CAMERA, None]))
@example(frame=np.random.default_rng(0).integers(0, 256, (1080, 1920, 3), dtype=np.uint8),
         controller='improved', algorithm='1.1', camera=LECTURE_CAMERA)
@example(frame=np.random.default_rng(0).integers(0, 256, (1080, 1920, 3), dtype=np.uint8),
         controller='lecture', algorithm='1.0', camera=LECTURE_CAMERA)
@example(frame=np.zeros((1, 1), np.uint8), controller='improved', algorithm='1.1',
         camera=LECTURE_CAMERA)
def test_any_image_gives_a_safe_command(frame, controller, algorithm, camera):
    ros, f = follower(controller, algorithm, camera)
    record = f.step(frame, 'x')
    _, _, twist = ros.published[-1]
    assert record['decision'] in WORDS
    assert math.isfinite(twist.linear.x) and math.isfinite(twist.angular.z)
    assert abs(twist.linear.x) <= MAX_LINEAR
    assert abs(twist.angular.z) <= MAX_ANGULAR
    assert (twist.linear.x, twist.angular.z) == (record['linear_x'], record['angular_z'])


segments = st.lists(st.tuples(*[st.integers(-2000, 2000)] * 4), max_size=40)


@settings(max_examples=300, deadline=None)
@given(lines=segments)
def test_the_lectures_rule_holds_exactly(lines):
    p = LaneParams()
    arr = np.array(lines, np.int32).reshape(-1, 4)
    s = slope_sum(arr, p.slope_min)
    theta = sum(math.atan2(y2 - y1, x2 - x1) for x1, y1, x2, y2 in lines)
    assert math.isclose(s.theta, theta, abs_tol=1e-9)
    decision = LectureRule(p)(Detection(arr, s)).decision
    if not lines:
        assert decision == 'none'
    elif s.theta > 6:
        assert decision == 'left'
    elif s.theta < -6:
        assert decision == 'right'
    elif abs(s.theta) < 6:
        assert decision == 'straight'
    else:
        assert decision == 'none'
