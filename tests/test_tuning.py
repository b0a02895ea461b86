"""Live tuning's description and its checks, without a master (the server itself is tested on
a real one in test_ros_package.py)."""

import dataclasses
import math

import pytest

from kobuki_lane import LaneParams, LectureRule
from lanelib.improved import ImprovedController, ImprovedParams
from lanelib.tuning import IMPROVED, LECTURE, Tuning, config_type


@pytest.mark.parametrize('table, names', [(LaneParams, LECTURE), (ImprovedParams, IMPROVED)])
def test_the_ranges_offered_are_the_defaults_tables(table, names):
    kind = config_type(table(), names)
    fields = {f.name: f for f in dataclasses.fields(table)}
    assert list(kind.defaults) == list(names)
    for name in names:
        check = fields[name].metadata['check']
        low, high = kind.min[name], kind.max[name]
        assert kind.defaults[name] == getattr(table(), name)
        # the ends offered are the check's own: inside passes, outside fails
        inside = [v for v in (low, high, (low + high) / 2) if math.isfinite(v)]
        assert all(check(v) or v == low for v in inside), (name, low, high)
        for outside in (low - 1, high + 1):
            if math.isfinite(outside):
                assert not check(outside), (name, outside)
        assert kind.type[name] == ('int' if fields[name].type in (int, 'int') else 'double')


class Log:
    def __init__(self):
        self.said = []

    def loginfo(self, text, *args):
        self.said.append(('info', text % args))

    def logwarn(self, text, *args):
        self.said.append(('warn', text % args))


def tuning_for(controller):
    """A Tuning without its ROS server: the callback and apply() only."""
    return Tuning(None, controller, log=Log(), serve=False)


def test_a_change_takes_effect_at_the_next_frame_and_a_bad_one_is_refused():
    rule = LectureRule(LaneParams(), camera=None)
    tuning = tuning_for(rule)
    config = dict(dataclasses.asdict(rule.p))
    config['threshold'] = 0.5
    assert tuning._changed(dict(config), -1)['threshold'] == 0.5
    assert rule.p.threshold == 6.0 and rule.pipeline.p.threshold == 6.0  # not yet
    tuning.apply()
    assert rule.p.threshold == 0.5 and rule.pipeline.p.threshold == 0.5
    assert ('info', 'live tuning: threshold 6 -> 0.5 (from the next frame)') in tuning.log.said
    config['threshold'] = math.nan  # no check passes it
    assert tuning._changed(dict(config), -1)['threshold'] == 0.5
    tuning.apply()
    assert rule.p.threshold == 0.5 and tuning.log.said[-1][0] == 'warn'


def test_the_improved_controllers_speeds_change_in_lane_widths():
    controller = ImprovedController(LaneParams(), ImprovedParams(lane='duckietown'))
    tuning = tuning_for(controller)
    config = dataclasses.asdict(controller.params)
    config['v_max'] = 2.0
    tuning._changed(config, -1)
    tuning.apply()
    assert controller.params.v_max == 2.0
    assert controller.p.v_max == pytest.approx(2.0 * 0.2375)  # lane widths/s to m/s
    assert controller.p.lane_width == pytest.approx(0.2375)
