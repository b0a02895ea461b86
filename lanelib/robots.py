"""Robot presets (--robot NAME|FILE; the launch file's robot:=): what belongs to a robot and its
track, in one file, so that one flag sets it.

A preset is a YAML mapping of the node's own settings, by the names its private parameters have
(`--help` lists them: rate, lane, camera_pitch, v_max, ...), holding only what differs from the
defaults tables, and `calibration` (lecture, duckiebot, topic, none, or a camera_info YAML). The
improved controller's distances and speeds are in lane widths (and lane widths per second), so a
robot on another lane needs none of them; what is left is its camera, its mounting, its lane and
what a robot of its own really does differently (its rate, its speed). Built in (config/):

    kobuki      the lecture's Kobuki with its level webcam: the defaults, nothing else
    duckiebot   a Duckiebot (DB21) on a Duckietown track (config/duckiebot.yaml says where each
                number comes from)

A path in a preset (calibration, lane, mounting) is taken from the preset's folder. What sets a
setting, first found first: a flag, a private parameter, the --mounting file, the preset, the
tables' defaults. The log line at start names the preset and what it set.
"""

import difflib
import os
from dataclasses import dataclass, field

from lanelib.files import read_yaml

CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'config')
BUILTIN = ('kobuki', 'duckiebot')
DEFAULT = 'kobuki'
PATHS = ('calibration', 'lane', 'mounting')  # values that may name a file beside the preset
OTHERS = ('calibration', 'mounting', 'odom')  # settings that are in no table


class RobotError(ValueError):
    """A preset that cannot be used; the message names the file and the key."""


@dataclass(frozen=True)
class Robot:
    name: str
    path: str
    settings: dict = field(default_factory=dict)  # setting name: value
    via: str = ''  # the parameter it was read from, when a launch file loaded it there

    def describe(self):
        """'duckiebot (config/duckiebot.yaml): calibration duckiebot, lane duckietown, ...'"""
        where = os.path.relpath(self.path) if not self.path.startswith('..') else self.path
        what = ', '.join(f'{k} {v}' for k, v in self.settings.items()) or 'the defaults'
        via = f', loaded into {self.via}' if self.via else ''
        return f"'{self.name}' ({where}{via}): {what}"


def preset_path(spec):
    """The file a --robot names: a built-in's in config/, else spec itself."""
    return os.path.join(CONFIG, f'{spec}.yaml') if spec in BUILTIN else spec


def load_robot(spec, known, loaded=None):
    """The preset `spec` names (a built-in name or a YAML file); `known`: the setting names a
    preset may set. loaded: the preset's mapping as the launch file's rosparam put it on the
    parameter server (~robot_preset), used instead of reading the file. RobotError says what
    is wrong."""
    path = preset_path(spec)
    if loaded is not None:
        return from_mapping(spec, path, loaded, known, '~robot_preset')
    if not os.path.isfile(path):
        raise RobotError(f"robot '{spec}' is neither a built-in preset ({', '.join(BUILTIN)}) "
                         'nor an existing file')
    return from_mapping(spec, path, read_yaml(path, RobotError, 'a robot preset'), known, path)


def from_mapping(spec, path, doc, known, where):
    """A Robot from a preset's mapping `doc` (None: empty), read from `where`."""
    if doc is None:
        doc = {}
    if not isinstance(doc, dict):
        raise RobotError(f'{where}: a robot preset is a mapping of settings (name: value)')
    allowed = set(known) | set(OTHERS)
    settings = {}
    for key, value in doc.items():
        if key not in allowed:
            guess = difflib.get_close_matches(str(key), allowed, n=1)
            raise RobotError(f"{where}: unknown setting '{key}'"
                             f"{f' (did you mean {guess[0]}?)' if guess else ''}; a preset holds "
                             "the node's settings by their names in --help")
        if key in PATHS and isinstance(value, str):
            beside = os.path.join(os.path.dirname(os.path.abspath(path)), value)
            value = beside if os.path.isfile(beside) else value
        settings[key] = value
    name = spec if spec in BUILTIN else os.path.splitext(os.path.basename(path))[0]
    return Robot(name, path, settings, '' if where == path else where)
