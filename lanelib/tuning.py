"""Live tuning on ROS: a dynamic_reconfigure server for the settings the lecture says are found
by trying (its threshold, Canny, Hough and speeds) and the improved controller's gains and
speeds. Change them in rqt_reconfigure (`rosrun rqt_reconfigure rqt_reconfigure`) or with
`rosservice call /kobuki_lane/set_parameters "config: {doubles: [{name: threshold, value: 8}]}"`
(Debian's dynparam script does not run); a change takes effect on the next frame and is logged.

The description is made from the defaults tables when the node starts (name, help, unit,
range, and the value the run started with as the default), so no .cfg file writes them again
and no catkin build step is needed. Only the running controller's settings are offered. A
change is checked as a flag would be (settings.validate) and refused, with a warning, when it
does not pass. Nothing is written to the parameter server: the next run starts from its
flags, parameters and preset again, not from what was tried here. Dry runs have no server.
"""

import dataclasses
import math
import threading

from lanelib.settings import bounds, validate, value_type

LECTURE = ('threshold', 'canny_low', 'canny_high', 'hough_threshold', 'min_line_length',
           'max_line_gap', 'slope_min', 'turn_linear', 'turn_angular', 'straight_linear')
IMPROVED = ('v_max', 'v_min', 'curve_slowdown', 'unsure_slowdown', 'lookahead', 'lookahead_min',
            'lateral_gain', 'omega_max', 'smoothing', 'search_rate')
TYPES = {int: 'int', float: 'double'}


def parameter(field, value, level):
    """One dynamic_reconfigure parameter description for a row of a defaults table."""
    kind = value_type(field)
    low, high = bounds(field)
    if kind is int:  # dynamic_reconfigure's int is 32 bits
        low, high = int(max(low, -2 ** 31)), int(min(high, 2 ** 31 - 1))
    unit = field.metadata['unit']
    return dict(name=field.name, type=TYPES[kind], default=kind(value), level=level,
                description=field.metadata['help'] + (f' [{unit}]' if unit else ''),
                min=kind(low), max=kind(high), edit_method='', srcline=0, srcfile='',
                ctype=TYPES[kind], cconsttype='const ' + TYPES[kind])


def config_type(params, names):
    """What dynamic_reconfigure's Server takes as its `type` (a generated XConfig module
    otherwise): the description of `names` of the table instance `params`, its values the
    defaults."""
    fields = {f.name: f for f in dataclasses.fields(params)}
    described = [parameter(fields[name], getattr(params, name), 1) for name in names]
    group = dict(name='Default', type='', state=True, cstate='true', id=0, parent=0,
                 parameters=described, groups=[], srcline=0, srcfile='', parentname='Default',
                 field='default', upper='DEFAULT', lower='groups')
    group['class'], group['parentclass'] = 'DEFAULT', ''
    by = {key: {p['name']: p[key] for p in described} for key in ('min', 'max', 'default',
                                                                    'level', 'type')}
    return type('KobukiLaneConfig', (), dict(
        config_description=group, min=by['min'], max=by['max'], defaults=by['default'],
        level=by['level'], type=by['type'], all_level=1))


class Tuning:
    """The server for one run. controller: LectureRule or ImprovedController, each with
    tuned_settings() (the table instance whose rows can change) and retune(new instance);
    log: rospy (loginfo, logwarn). serve=False: no server (the callback alone, for tests)."""

    def __init__(self, rospy, controller, log=None, serve=True):
        self.controller, self.log = controller, log or rospy
        self.names = IMPROVED if controller.name == 'improved' else LECTURE
        self.lock = threading.Lock()
        self.pending = None  # settings changed and not yet in force
        self.changes = 0
        kind = config_type(controller.tuned_settings(), self.names)
        self.server = self._serve(kind) if serve else None

    def _serve(self, kind):
        from dynamic_reconfigure.server import Server

        class Quiet(Server):  # neither read nor leave values on the parameter server
            def _copy_from_parameter_server(self):
                pass

            def _copy_to_parameter_server(self):
                pass

        return Quiet(kind, self._changed)

    def apply(self):
        """Put a change in force: the loop calls this before each frame, so that a frame is
        decided on one set of settings, never on half of a change."""
        with self.lock:
            new, self.pending = self.pending, None
        if new is not None:
            self.controller.retune(new)

    def _changed(self, config, level):
        """dynamic_reconfigure's callback: the values wanted; returns those now in force."""
        with self.lock:
            current = self.pending or self.controller.tuned_settings()
        wanted = {name: config[name] for name in self.names}
        changed = {name: value for name, value in wanted.items()
                   if not _same(getattr(current, name), value)}
        if changed:
            try:
                new = validate(dataclasses.replace(current, **changed))
            except (ValueError, TypeError) as e:
                self.log.logwarn('live tuning refused (%s); the settings stay as they were', e)
                new = current
            else:
                with self.lock:
                    self.pending = new
                    self.changes += 1
                self.log.loginfo('live tuning: %s (from the next frame)', ', '.join(
                    f'{name} {getattr(current, name):g} -> {value:g}'
                    for name, value in changed.items()))
            for name in self.names:
                config[name] = getattr(new, name)
        return config


def _same(a, b):
    return a == b or (isinstance(a, float) and math.isclose(a, b, rel_tol=1e-12))
