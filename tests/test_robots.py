"""Robot presets (--robot): one flag for a robot's camera, mounting, lane and rate; flags,
private parameters and a mounting file outrank them (lanelib/robots.py)."""

import os

import pytest
from helpers import SAMPLES, read_jsonl

from kobuki_lane import LaneParams, build_parser, main
from lanelib.improved import ImprovedParams
from lanelib.node import settings_from
from lanelib.robots import RobotError, load_robot
from lanelib.safety import Safety

KNOWN = {f for table in (LaneParams, ImprovedParams, Safety)
         for f in table.__dataclass_fields__}


def settings(*argv, params=None):
    args = build_parser().parse_args(['--controller', 'improved', *argv])
    given = dict(params or {})
    found = settings_from(args, lambda name, default=None: given.get(name.lstrip('~'), default),
                          LaneParams)
    return found, args


def test_kobuki_is_the_defaults_and_duckiebot_says_where_its_numbers_come_from():
    assert load_robot('kobuki', KNOWN).settings == {}
    duckiebot = load_robot('duckiebot', KNOWN).settings
    assert duckiebot['lane'] == 'duckietown' and duckiebot['calibration'] == 'duckiebot'
    assert 0.05 < duckiebot['camera_height'] < 0.2 and 10 < duckiebot['camera_pitch'] < 30
    (params, safety, name, improved, robot), args = settings()
    assert improved == ImprovedParams() and params == LaneParams() and robot.name == 'kobuki'
    assert args.calibration == 'lecture'


def test_a_preset_sets_the_camera_lane_and_rate_and_flags_outrank_it(tmp_path):
    (params, _, _, improved, robot), args = settings('--robot', 'duckiebot')
    assert improved.lane == 'duckietown' and args.calibration == 'duckiebot'
    assert improved.camera_pitch == robot.settings['camera_pitch']
    (_, _, _, improved, _), args = settings('--robot', 'duckiebot', '--camera-pitch', '12',
                                            '--calibration', 'none')
    assert improved.camera_pitch == 12.0 and args.calibration == 'none'
    (_, _, _, improved, _), _ = settings('--robot', 'duckiebot', params={'camera_height': 0.3})
    assert improved.camera_height == 0.3  # a private parameter outranks it too
    mounting = tmp_path / 'm.yaml'
    mounting.write_text('height: 0.12\npitch_deg: 18\nroll_deg: 0\nforward: 0.05\n')
    (_, _, _, improved, _), _ = settings('--robot', 'duckiebot', '--mounting', str(mounting))
    assert (improved.camera_height, improved.camera_pitch) == (0.12, 18.0)  # and the file


def test_every_controller_setting_the_duckiebot_preset_names_reaches_the_controller():
    """Each improved-controller number in config/duckiebot.yaml (its speeds, curve_slowdown,
    one_line_width, turn_gate...) is what the controller runs with, unless a flag says
    otherwise: none is read and then dropped."""
    preset = load_robot('duckiebot', KNOWN).settings
    named = {key: value for key, value in preset.items()
             if key in ImprovedParams.__dataclass_fields__}
    assert {'curve_slowdown', 'unsure_slowdown', 'one_line_width', 'turn_gate',
            'bend_belief'} <= set(named)
    (_, _, _, improved, _), _ = settings('--robot', 'duckiebot')
    for key, value in named.items():
        assert getattr(improved, key) == value, key
        assert value != getattr(ImprovedParams(), key), f'{key} is the default: not needed'
    (_, _, _, improved, _), _ = settings('--robot', 'duckiebot', '--curve-slowdown', '2')
    assert improved.curve_slowdown == 2.0


def test_a_preset_file_of_ones_own_with_paths_beside_it(tmp_path):
    (tmp_path / 'lane.yaml').write_text(
        'lane_width: 0.3\nleft: {colour: white, width: 0.02}\n'
        'right: {colour: white, width: 0.02}\n')
    preset = tmp_path / 'mine.yaml'
    preset.write_text('lane: lane.yaml\nrate: 8\nv_max: 1.2\ncamera_pitch: 10\n')
    (params, _, _, improved, robot), _ = settings('--robot', str(preset))
    assert params.rate == 8.0 and improved.v_max == 1.2 and improved.camera_pitch == 10.0
    assert improved.lane == str(tmp_path / 'lane.yaml') and robot.name == 'mine'


@pytest.mark.parametrize('text, said', [
    ('camera_pich: 10\n', "unknown setting 'camera_pich' (did you mean camera_pitch?)"),
    ('- 1\n', 'a robot preset is a mapping'),
    ('camera_pitch: 95\n', 'camera_pitch = 95.0 is out of range'),
    ('rate: fast\n', "rate = 'fast' is not a number"),
])
def test_a_bad_preset_is_refused_naming_what_is_wrong(tmp_path, text, said):
    preset = tmp_path / 'bad.yaml'
    preset.write_text(text)
    with pytest.raises((RobotError, ValueError), match=said.replace('(', r'\(').replace(
            ')', r'\)').replace('?', r'\?')):
        settings('--robot', str(preset))
    with pytest.raises(RobotError, match='neither a built-in preset'):
        settings('--robot', 'roomba')


def test_the_node_says_which_preset_and_what_it_set(tmp_path, capsys):
    out = tmp_path / 'd.jsonl'
    assert main(['--source', SAMPLES, '--dry-run', '--robot', 'duckiebot', '--controller',
                 'improved', '--decisions', str(out)]) == 0
    said = capsys.readouterr().out
    assert "robot preset 'duckiebot'" in said and 'lane duckietown' in said
    assert 'calibration duckiebot' in said
    assert len(read_jsonl(out)) == len(os.listdir(SAMPLES))
