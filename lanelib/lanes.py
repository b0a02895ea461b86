"""Lane profiles: what the lines of the robot's lane look like (--lane NAME or a YAML file).

A profile gives the lane width between the two lines' centres and, for each side, the line's
colour (white, yellow, or any), whether it is solid or dashed, and the tape's width (with tapes of
two widths the improved controller drives along the middle of the floor between them, a quarter
of the difference off the middle between their centres). Where a
side names a colour, the improved controller counts a line on that side only where the colour
says so, and a line of the other colour, or a line on the wrong side of it, is not its lane's.
A colour only dashed lines have is looked for in short pieces: a dash need only be a little
longer than it is wide (colour.ELONGATION), where a piece of a solid line must be half as long
again as it is wide.

Built in:
    lecture     the lecture's floor: two tape lines of any colour, 0.35 m apart (the default)
    duckietown  Duckietown's road: a yellow dashed centre line on the robot's left and a white
                solid edge line on its right. Appearance specification: 61 cm tiles, white
                tape 2 in (5 cm) wide, yellow tape 1 in (2.5 cm) wide in 2 in pieces with 1 in
                gaps; dt-core's lane_filter puts the tapes' inner edges 0.20 m apart, which is
                0.2375 m between the lines' centres. The layout itself has them further
                apart: with the white tape at the tile's edge and the yellow in its middle,
                0.28 m between the centres (gym-duckietown's road texture: 0.26 and 0.28 m).
                The improved controller measures the width between the lines it sees (within
                width_tolerance), and the duckiebot preset's distances, in lane widths, were
                measured with 0.2375 (docs/benchmarks.md)
    autorace    TurtleBot3 AutoRace: a yellow solid line on the left and a white solid line on
                the right, 15 mm wide, 285 mm apart between centres (ROBOTIS autorace_track,
                RBiz Challenge 2017 straight tile: two 500 x 15 mm lines, placed 11.22 in apart)

A YAML file has the same fields:

    lane_width: 0.2375          # [m] between the two lines' centres
    left:  {colour: yellow, style: dashed, width: 0.025}
    right: {colour: white, style: solid, width: 0.05}
"""

import math
import os
from dataclasses import dataclass

from lanelib.files import read_yaml

COLOURS = ('white', 'yellow', 'any')
STYLES = ('solid', 'dashed')


class LaneError(ValueError):
    """A lane profile that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class Line:
    colour: str = 'any'  # white | yellow | any
    style: str = 'solid'  # solid | dashed
    width: float = 0.03  # [m] the tape's width


@dataclass(frozen=True)
class LaneProfile:
    name: str
    lane_width: float  # [m] between the two lines' centres
    left: Line
    right: Line

    @property
    def colours(self):
        """The colour masks its lines are looked for in ('any': tape of any colour)."""
        return sorted({line.colour for line in (self.left, self.right)})

    def sides(self, colour):
        """The sides (+1 left, -1 right) a line of `colour` may be ('any': either)."""
        return [side for side, line in ((1, self.left), (-1, self.right))
                if colour == 'any' or line.colour in (colour, 'any')]


BUILTIN = {
    'lecture': LaneProfile('lecture', 0.35, Line('any', 'solid', 0.03), Line('any', 'solid', 0.03)),
    'duckietown': LaneProfile('duckietown', 0.2375, Line('yellow', 'dashed', 0.025),
                              Line('white', 'solid', 0.05)),
    'autorace': LaneProfile('autorace', 0.285, Line('yellow', 'solid', 0.015),
                            Line('white', 'solid', 0.015)),
}


def _line(doc, where):
    if not isinstance(doc, dict):
        raise LaneError(f'{where} must be a mapping like {{colour: white, style: solid, '
                        'width: 0.05}')
    unknown = set(doc) - {'colour', 'style', 'width'}
    if unknown:
        raise LaneError(f"{where} has unknown key(s) {', '.join(sorted(map(str, unknown)))}; "
                        'expected colour, style, width')
    colour = doc.get('colour', 'any')
    if colour not in COLOURS:
        raise LaneError(f"{where}.colour must be white, yellow or any, not {colour!r}")
    style = doc.get('style', 'solid')
    if style not in STYLES:
        raise LaneError(f"{where}.style must be solid or dashed, not {style!r}")
    width = doc.get('width', 0.03)
    if isinstance(width, bool) or not isinstance(width, (int, float)) or \
            not math.isfinite(width) or not 0 < width < 1:
        raise LaneError(f'{where}.width must be a tape width in metres (0 to 1), not {width!r}')
    return Line(colour, style, float(width))


def from_dict(doc, name):
    if not isinstance(doc, dict):
        raise LaneError(f'{name}: must be a mapping with lane_width, left and right')
    unknown = set(doc) - {'name', 'lane_width', 'left', 'right'}
    if unknown:
        raise LaneError(f"{name} has unknown key(s) {', '.join(sorted(map(str, unknown)))}; "
                        'expected lane_width, left, right')
    for key in ('lane_width', 'left', 'right'):
        if key not in doc:
            raise LaneError(f'{name}.{key} is missing')
    width = doc['lane_width']
    if isinstance(width, bool) or not isinstance(width, (int, float)) or \
            not math.isfinite(width) or width <= 0:
        raise LaneError(f'{name}.lane_width must be a positive number of metres, not {width!r}')
    left, right = _line(doc['left'], f'{name}.left'), _line(doc['right'], f'{name}.right')
    if left.width + right.width >= width:
        raise LaneError(f'{name}: the tapes ({left.width} + {right.width} m) do not fit in '
                        f'lane_width {width} m')
    return LaneProfile(str(doc.get('name', name)), float(width), left, right)


def load_lane(spec):
    """A built-in profile's name or a YAML file's path; LaneError says what is wrong."""
    if spec in BUILTIN:
        return BUILTIN[spec]
    if not os.path.isfile(spec):
        raise LaneError(f"lane '{spec}' is neither a built-in profile ({', '.join(BUILTIN)}) "
                        'nor an existing file')
    return from_dict(read_yaml(spec, LaneError), os.path.basename(spec))
