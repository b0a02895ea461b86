"""Tables of defaults: dataclass fields that carry their unit, their help and their check.

One table turns into command-line flags (`add_arguments`), is filled from flags, private ROS
parameters and defaults in that order (`resolve`), and is checked (`validate`).
"""

import dataclasses
import math


def setting(default, help, unit='', check=None, choices=None):
    """One row of a defaults table: value, unit, where it comes from, and its check."""
    return dataclasses.field(default=default,
                             metadata=dict(help=help, unit=unit, check=check, choices=choices))


def between(low, high, odd=False):
    """A check: low <= x <= high (and odd, for a kernel size). Its range is shown in --help and
    in the error that refuses a value outside it."""
    def check(x):
        return (math.isfinite(x) and low <= x <= high and
                (not odd or (x == int(x) and int(x) % 2 == 1)))
    check.range = f"{'odd, ' if odd else ''}{low:g} to {high:g}"
    check.bounds = (low, high)
    return check


def above(low, high):
    """A check: low < x <= high."""
    def check(x):
        return math.isfinite(x) and low < x <= high
    check.range = f'more than {low:g}, at most {high:g}'
    check.bounds = (low, high)
    return check


def positive(x):
    return math.isfinite(x) and x > 0


def finite(x):
    return math.isfinite(x)


def non_negative(x):
    return math.isfinite(x) and x >= 0


def fraction(x):
    return math.isfinite(x) and 0 < x <= 1


# the interval each plain check allows (its ends may be excluded): the bounds live tuning
# offers (lanelib/tuning.py)
positive.bounds = (0.0, math.inf)
finite.bounds = (-math.inf, math.inf)
non_negative.bounds = (0.0, math.inf)
fraction.bounds = (0.0, 1.0)


def bounds(field):
    """(low, high) a row of a defaults table allows, from its check; infinite where it has
    no end."""
    return getattr(field.metadata['check'], 'bounds', (-math.inf, math.inf))


def value_type(f):
    """The Python type of a row's values: str, int or float."""
    name = f.type if isinstance(f.type, str) else f.type.__name__
    return {'str': str, 'int': int}.get(name, float)


def validate(params, origins=None):
    """Raise ValueError naming the first setting that is out of range, and where its value came
    from when `origins` ({name: where}) says."""
    origins = origins or {}
    for f in dataclasses.fields(params):
        value, meta = getattr(params, f.name), f.metadata
        source = f' (from {origins[f.name]})' if origins.get(f.name) else ''
        if meta['choices'] and value not in meta['choices']:
            raise ValueError(f"{f.name} must be one of {', '.join(meta['choices'])}, "
                             f'not {value!r}{source}')
        try:
            ok = not meta['check'] or meta['check'](value)
        except ValueError as e:  # a check that says itself what is wrong
            raise ValueError(f'{f.name}: {e}{source}') from None
        if not ok:
            within = getattr(meta['check'], 'range', None)
            raise ValueError(f'{f.name} = {value!r} is out of range'
                             f'{f" ({within})" if within else ""}: {meta["help"]}{source}')
    return params


def add_arguments(group, table):
    """A --flag for every row of `table` (a dataclass), defaulting to None (not given)."""
    for f in dataclasses.fields(table):
        meta, kind = f.metadata, value_type(f)
        unit = f' [{meta["unit"]}]' if meta['unit'] else ''
        default = f.default if kind is str else f'{f.default:g}'
        within = getattr(meta['check'], 'range', None)
        group.add_argument('--' + f.name.replace('_', '-'), dest=f.name, type=kind, default=None,
                           choices=meta['choices'], metavar=None if meta['choices'] else 'X',
                           help=f'{meta["help"]}{unit}; default {default}'
                                f'{f"; {within}" if within else ""}')


PARAMETER = ('the private ROS parameter ~{name}: _{name}:=... on the command line, a launch '
             "file, or one an earlier run left on the parameter server ('rosparam delete "
             "/kobuki_lane/{name}' removes it)")


def resolve(table, args, get_param, layers=()):
    """Flag given > private ROS parameter (~name) > the first of `layers` that has it (each
    (values, where): a mounting file, a robot preset) > the table's default; a ValueError that
    names the setting, where its value came from, and its range when the value is out of it
    or of the wrong kind."""
    values, came = {}, {}
    for f in dataclasses.fields(table):
        flag = getattr(args, f.name)
        layer = next(((given, where) for given, where in layers if f.name in given), None)
        fallback = layer[0][f.name] if layer else f.default
        value = flag if flag is not None else get_param('~' + f.name, fallback)
        came[f.name] = ('--' + f.name.replace('_', '-') if flag is not None else
                        PARAMETER.format(name=f.name) if value is not fallback else
                        layer[1] if layer else None)
        kind = value_type(f)
        if kind in (int, float) and isinstance(value, str):
            value = _number(value)  # a number as text: a launch file's str, or 1e3 for rospy
        if kind in (int, float) and (isinstance(value, bool) or
                                     not isinstance(value, (int, float))):
            raise ValueError(f'{f.name} = {value!r} is not a number (from '
                             f'{came[f.name] or "the default"}): {f.metadata["help"]}')
        if kind is int and not (math.isfinite(value) and value == int(value)):
            raise ValueError(f'{f.name} = {value!r} is not a whole number (from '
                             f'{came[f.name] or "the default"}): {f.metadata["help"]}')
        if kind is float:
            value = float(value)
        elif kind is int:
            value = int(value)
        elif kind is str:
            value = str(value)
        values[f.name] = value
    return validate(table(**values), came)


def _number(text):
    """The int or float `text` spells, or text itself when it spells none."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def unknown(names, tables, others=()):
    """Of the private parameter names given, those no table (nor `others`) has, each with the
    likeliest name meant ('' when none is close)."""
    import difflib

    known = {f.name for table in tables for f in dataclasses.fields(table)} | set(others)
    return [(name, (difflib.get_close_matches(name, known, n=1) or [''])[0])
            for name in sorted(set(names) - known)]
