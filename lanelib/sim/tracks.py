"""Track files for the simulator: YAML or JSON, validated, plus the built-in tracks.

    lane_width: 0.35            # [m] between tape centres
    tape_width: 0.03            # [m]
    segments:                   # the centre line, from (0, 0) heading +x
      - straight: 1.5           # [m]
      - arc: {radius: 0.8, angle_deg: 90}    # positive turns left, negative right
    camera: {model: lecture, height: 0.20, pitch_deg: 0}   # optional: camera and mounting
                                # (also forward [m] and roll_deg)
    world: duckietown           # optional: what the floor looks like (lecture, wood,
                                # duckietown, autorace), or {base: NAME, lighting: 0.4, ...}
    scene:                                   # optional
      noise: 10                 # frame noise sigma [grey levels]
      gradient: 60              # lighting gradient across the frame [grey levels]
      glare: 80                 # a bright patch [grey levels]
      floor: 95                 # floor brightness; tape: 235
      gaps: [{line: left, at: 2.0, length: 0.2}]    # tape missing [m along the track]
      dashes: {line: left, on: 0.1, off: 0.1}       # dashed tape [m]
"""

import json
import math
import os
from dataclasses import dataclass, field, replace

from lanelib.camera import CAMERAS
from lanelib.files import read_yaml
from lanelib.geometry import Mounting
from lanelib.sim.world import WORLDS, Scene, Track, World, segment_shape


class TrackError(ValueError):
    """A track file that cannot be used; the message names the file and the field."""


LANE_TRACKS = {
    # regions A (straight), B (left) and C (right) of the lecture's slide at 08:30
    'lecture': dict(segments=[{'straight': 2.0}, {'arc': {'radius': 1.2, 'angle_deg': 90}},
                              {'arc': {'radius': 1.2, 'angle_deg': -90}}, {'straight': 1.5}]),
    'oval': dict(segments=[{'straight': 2.0}, {'arc': {'radius': 1.0, 'angle_deg': 180}},
                           {'straight': 2.0}, {'arc': {'radius': 1.0, 'angle_deg': 180}}]),
    's_bend': dict(segments=[{'straight': 1.0}, {'arc': {'radius': 1.0, 'angle_deg': 120}},
                             {'arc': {'radius': 1.0, 'angle_deg': -120}}, {'straight': 1.0}]),
    # radius 0.9 m: on these bends the 39 degree lens, which sees the floor from 0.6 m ahead,
    # keeps only the outer tape in view. Measured: at 0.8 m the improved controller departs,
    # at 0.7 m the whole lane leaves the view.
    'tight': dict(segments=[{'straight': 1.0}, {'arc': {'radius': 0.9, 'angle_deg': 180}},
                            {'arc': {'radius': 0.9, 'angle_deg': -180}}, {'straight': 1.0}]),
}
# Bends the lecture's lens loses the lane on: the improved controller follows the lane it
# remembers and then searches (lanelib/improved.py). s_tight: the second bend, radius 0.7 m,
# follows the first at once, and at the inflection the lane leaves the view; corner: a 0.5 m
# bend of 90 degrees; hairpin: a U-turn of radius 0.5 m, where from the centre line no tape is
# in view at all.
SEARCH_TRACKS = {
    's_tight': dict(segments=[{'straight': 1.0}, {'arc': {'radius': 1.0, 'angle_deg': 120}},
                              {'arc': {'radius': 0.7, 'angle_deg': -120}}, {'straight': 1.0}]),
    'corner': dict(segments=[{'straight': 1.0}, {'arc': {'radius': 0.5, 'angle_deg': 90}},
                             {'straight': 1.5}]),
    'hairpin': dict(segments=[{'straight': 1.0}, {'arc': {'radius': 0.5, 'angle_deg': 180}},
                              {'straight': 1.0}]),
}
BUILTIN = {**LANE_TRACKS, **SEARCH_TRACKS}


@dataclass
class TrackSpec:
    """A track file, checked: geometry, mounting, scene, and the name it goes by."""

    name: str
    track: Track
    mounting: Mounting = field(default_factory=Mounting)
    scene: Scene = field(default_factory=Scene)
    gaps: list = field(default_factory=list)  # [{'line', 'at', 'length'}]
    dashes: dict = None  # {'line', 'on', 'off'}
    world: World = field(default_factory=World)
    camera: str = 'lecture'  # lanelib.camera.CAMERAS

    @property
    def closed(self):
        """True when the centre line ends where it starts, heading the same way (a loop)."""
        c = self.track.centre
        heading = (c[-1, 2] - c[0, 2]) % (2 * math.pi)
        return (math.hypot(c[-1, 0] - c[0, 0], c[-1, 1] - c[0, 1]) < 0.05
                and min(heading, 2 * math.pi - heading) < 0.05)


def _number(value, where, positive=False, nonnegative=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise TrackError(f'{where} must be a number, not {value!r}')
    if positive and value <= 0:
        raise TrackError(f'{where} must be positive, not {value!r}')
    if nonnegative and value < 0:
        raise TrackError(f'{where} must not be negative, not {value!r}')
    return float(value)


def _mapping(value, where, allowed):
    if not isinstance(value, dict):
        raise TrackError(f'{where} must be a mapping')
    unknown = set(value) - set(allowed)
    if unknown:
        raise TrackError(f"{where} has unknown key(s) {', '.join(sorted(map(str, unknown)))}; "
                         f"expected {', '.join(allowed)}")
    return value


def _segments(value, where):
    if not isinstance(value, list) or not value:
        raise TrackError(f'{where}.segments must be a non-empty list')
    out = []
    for i, seg in enumerate(value):
        here = f'{where}.segments[{i}]'
        if not isinstance(seg, dict) or len(seg) != 1 or next(iter(seg)) not in ('straight', 'arc'):
            raise TrackError(f'{here} must be {{straight: metres}} or '
                             '{arc: {radius: m, angle_deg: deg}}')
        if 'straight' in seg:
            out.append({'straight': _number(seg['straight'], f'{here}.straight', positive=True)})
        else:
            arc = _mapping(seg['arc'], f'{here}.arc', ('radius', 'angle_deg'))
            for key in ('radius', 'angle_deg'):
                if key not in arc:
                    raise TrackError(f'{here}.arc.{key} is missing')
            angle = _number(arc['angle_deg'], f'{here}.arc.angle_deg')
            if angle == 0 or abs(angle) > 720:
                raise TrackError(f'{here}.arc.angle_deg must not be 0, and at most 720 either '
                                 f'way (two turns), not {angle:g}')
            out.append({'arc': {'radius': _number(arc['radius'], f'{here}.arc.radius',
                                                  positive=True), 'angle_deg': angle}})
    return out


def _line_choice(value, where):
    if value not in ('left', 'right', 'both'):
        raise TrackError(f"{where} must be left, right or both, not {value!r}")
    return value


def from_dict(doc, name='track'):
    """Check a parsed track document and build its TrackSpec."""
    doc = _mapping(doc, name, ('name', 'lane_width', 'tape_width', 'segments', 'camera', 'scene',
                               'world'))
    if 'segments' not in doc:
        raise TrackError(f'{name}.segments is missing')
    lane = _number(doc.get('lane_width', 0.35), f'{name}.lane_width', positive=True)
    tape = _number(doc.get('tape_width', 0.03), f'{name}.tape_width', positive=True)
    if tape >= lane:
        raise TrackError(f'{name}.tape_width must be smaller than lane_width')
    segments = _segments(doc['segments'], name)
    if sum(segment_shape(seg)[0] for seg in segments) > 1000:
        raise TrackError(f'{name}.segments are more than 1 km long')
    track = Track(lane_width=lane, tape_width=tape, segments=segments)
    world = _world(doc.get('world', 'lecture'), f'{name}.world')
    cam = dict(_mapping(doc.get('camera', {}), f'{name}.camera',
                        ('model', 'height', 'pitch_deg', 'forward', 'roll_deg')))
    model = cam.pop('model', None)
    if model is not None and model not in CAMERAS:
        raise TrackError(f"{name}.camera.model must be one of {', '.join(CAMERAS)}, not "
                         f'{model!r}')
    mounting = Mounting(**{k: _number(v, f'{name}.camera.{k}') for k, v in cam.items()})
    if mounting.height <= 0:
        raise TrackError(f'{name}.camera.height must be positive')
    scene_keys = ('noise', 'gradient', 'glare', 'floor', 'tape', 'max_range', 'wall')
    sc = _mapping(doc.get('scene', {}), f'{name}.scene', scene_keys + ('gaps', 'dashes'))
    scene = Scene(**{k: _number(sc[k], f'{name}.scene.{k}', nonnegative=True)
                     for k in scene_keys if k in sc})
    for key in ('floor', 'tape', 'wall', 'gradient', 'glare'):
        if getattr(scene, key) > 255:
            raise TrackError(f'{name}.scene.{key} is a brightness, 0 to 255, not '
                             f'{getattr(scene, key):g}')
    if scene.noise > 100 or not 0.5 <= scene.max_range <= 100:
        raise TrackError(f'{name}.scene: noise is 0 to 100 grey levels and max_range 0.5 to '
                         '100 m')
    gaps = []
    for i, gap in enumerate(sc.get('gaps', []) or []):
        here = f'{name}.scene.gaps[{i}]'
        gap = _mapping(gap, here, ('line', 'at', 'length'))
        gaps.append(dict(line=_line_choice(gap.get('line', 'left'), f'{here}.line'),
                         at=_number(gap.get('at'), f'{here}.at', nonnegative=True),
                         length=_number(gap.get('length'), f'{here}.length', positive=True)))
    dashes = None
    if sc.get('dashes') is not None:
        here = f'{name}.scene.dashes'
        d = sc['dashes']
        if isinstance(d, dict):  # YAML 1.1 reads the keys on and off as true and false
            d = {('on' if k is True else 'off' if k is False else k): v for k, v in d.items()}
        d = _mapping(d, here, ('line', 'on', 'off'))
        dashes = dict(line=_line_choice(d.get('line', 'both'), f'{here}.line'),
                      on=_number(d.get('on'), f'{here}.on', positive=True),
                      off=_number(d.get('off'), f'{here}.off', positive=True))
    spec = TrackSpec(str(doc.get('name', name)), track, mounting, scene, gaps, dashes)
    return with_world(spec, world, keep_camera=bool(cam), model=model)


def _world(value, where):
    """A world's name, or {base: NAME, field: value, ...} changing some of its fields."""
    if isinstance(value, str):
        if value not in WORLDS:
            raise TrackError(f"{where} must be one of {', '.join(WORLDS)}, not {value!r}")
        return WORLDS[value]
    keys = ('base', 'floor', 'lighting', 'shadows', 'blur', 'stop_every', 'cast')
    doc = _mapping(value, where, keys)
    world = _world(doc.get('base', 'lecture'), f'{where}.base')
    changes = {}
    for key in ('lighting', 'shadows', 'blur', 'stop_every'):
        if key in doc:
            changes[key] = _number(doc[key], f'{where}.{key}', nonnegative=True)
    for key in ('shadows', 'blur'):
        if key in changes:
            changes[key] = int(changes[key])
    if 'floor' in doc:
        if doc['floor'] not in ('plain', 'mats', 'wood'):
            raise TrackError(f"{where}.floor must be plain, mats or wood, not {doc['floor']!r}")
        changes['floor'] = doc['floor']
    if 'cast' in doc:
        cast = doc['cast']
        if not isinstance(cast, list) or len(cast) != 3:
            raise TrackError(f'{where}.cast must be [blue, green, red] gains')
        changes['cast'] = tuple(_number(g, f'{where}.cast', positive=True) for g in cast)
    if world.name == 'lecture' and changes:
        raise TrackError(f"{where}: the lecture's grey world has no such settings; "
                         'use base: wood, duckietown or autorace')
    return replace(world, **changes)


def with_world(spec, world, keep_camera=False, model=None):
    """The track in another world: its lane width, camera and mounting (unless the track file
    gave a mounting: keep_camera), and the lane profile that describes it. Raises TrackError
    for a bend too tight for the world's lines (_check_bends)."""
    track = spec.track
    if world.lane_width is not None and world.lane_width != track.lane_width:
        tape = min(track.tape_width, world.lane_width / 4)
        track = Track(lane_width=world.lane_width, tape_width=tape, segments=track.segments,
                      start=track.start)
    _check_bends(track, world, spec.name)
    mounting = spec.mounting
    if world.mounting is not None and not keep_camera:
        mounting = Mounting(*world.mounting)
    return replace(spec, track=track, mounting=mounting, world=world,
                   camera=model or world.camera)


def _check_bends(track, world, name):
    """Every bend must be wider than the lines on its inside reach from the centre line (each
    line's offset and its whole width): a tighter one would draw its inner line crossing
    itself. The lines are the world's (Duckietown's road has the other lane's edge 1.5 lane
    widths to the left), or the lecture's two tapes half a lane width either side; the lane
    width is the world's where it has one (a file's own is for the lecture's world)."""
    lane = track.lane_width
    lines = [(p.offset, p.width) for p in world.lines] or [(-0.5, track.tape_width),
                                                           (0.5, track.tape_width)]
    for i, seg in enumerate(track.segments):
        if 'arc' not in seg:
            continue
        radius, side = seg['arc']['radius'], math.copysign(1.0, seg['arc']['angle_deg'])
        inside = [(offset * side * lane + width, offset) for offset, width in lines
                  if offset * side > 0]
        reach, offset = max(inside, default=(0.0, 0.0))
        if radius <= reach:
            which = ('half the lane width and a tape' if abs(offset) == 0.5 and not world.lines
                     else f'where the {world.name} world\'s line {abs(offset):g} lane widths '
                     f"to the {'left' if offset > 0 else 'right'} reaches on its inside, with "
                     'its width')
            raise TrackError(f'{name}.segments[{i}].arc.radius {radius:g} m is not more than '
                             f'{which} ({reach:g} m, the lane {lane:g} m wide): the line would '
                             'cross itself')


def load_track(spec):
    """A built-in name ('lecture', 'oval', 's_bend', 'tight') or a YAML/JSON file path."""
    if spec in BUILTIN:
        return from_dict(dict(BUILTIN[spec]), spec)
    if not os.path.exists(spec):
        raise TrackError(f"'{spec}' is neither a built-in track ({', '.join(BUILTIN)}) "
                         'nor an existing file')
    return from_dict(read_yaml(spec, TrackError, 'YAML or JSON'), os.path.basename(spec))


def dumps(spec_name):
    """A built-in track as JSON text (to copy and edit)."""
    return json.dumps(BUILTIN[spec_name], indent=2)
