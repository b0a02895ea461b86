"""Colour for the improved controller: which pixels are white, yellow or red tape, in the light
that is actually there, and the tape pieces they make on the floor.

The thresholds adapt to each frame instead of being fixed for one room. The road is taken as
grey and the light's colour as what makes it look otherwise: the road's colour is the floor
band's commonest (the peak of its a*, b* histogram: grass, sky or a mat at the side, which move
a median, do not move it), and each pixel is judged as it would look had a gain per channel made
the road grey (von Kries). A light multiplies every channel, so white tape under a yellow light
is the road's own yellow, brighter, and comes out white; subtracting the road's a*, b* instead
(as before) left it yellow on a dark road, whose a*, b* are small for the same light. The gains
only raise a channel, so a pixel the camera clipped stays white. Brightness is judged against
the floor around the pixel (a box a fifth of the image wide, the wall and the empty border
undistortion leaves not counted), so dim rooms, bright sun, glare and shadows shift the
threshold with them:

    white   brighter than its surroundings by 2.5 times their typical variation (at least 20
            Lab levels) and than the floor by 25, with little colour (chroma below 25)
    any     a tape of any colour but red lighter than the floor: brighter than its
            surroundings and the floor as white is, whatever its colour (a floor's dark seams
            are not tape; nor is dark tape on a light floor, which this does not look for)
    yellow  b* (yellow-blue) above 25, more yellow than red or green, and brighter than the
            floor
    red     a* (red-green) above 25, more red than yellow (stop lines: never a lane line)

(a*, b* as the road made grey would show them, from neutral.) The gains are applied only where
a colour may be: a first look scales the road's a*, b* to each pixel's lightness (a grey
surface's grow with L* + 16 under one light: Lab's cube root of a gain) and keeps the pixels
within NEAR of each test; the exact test runs on those alone.
"""

import math

import cv2
import numpy as np

from lanelib.geometry import pixels_to_floor

BOX = 0.2  # [image widths] the surroundings a pixel's brightness is judged against
# a piece is longer than it is wide by at least this: 1.5 for a solid line (a blob, a glint or a
# sheet of paper is not a line), 1.2 for a dashed one, whose dashes are short by design
# (Duckietown's: 2 by 1 in) and measure barely 1.5 times their width once the mask's blur has
# widened them and a camera pitched a little off has shortened them (gym-duckietown with
# domain rand: 0.041 to 0.047 m by 0.029 to 0.032, half the dashes in view of a frame)
ELONGATION = {'solid': 1.5, 'dashed': 1.2}
CAST = 4.0  # [gain] a channel of the road's colour is raised at most this much (a road with
# almost none of a channel says little of the light's colour there)
NEAR = 16  # [Lab levels] the first look's margin: where the exact test holds, its a*, b* fell
# short of the exact by at most 14 (the real frames' and gym-duckietown's first frames' lower
# halves, with domain rand)
LAB_BLACK = 16 * 255 / 100  # L* + 16 in 8-bit levels: Lab's cube root of the luminance
POINTS = 3  # points that stand for a piece when the lane is fitted (Piece.summary)


def colour_masks(bgr, roi, colours=None, surroundings=None):
    """{'white', 'yellow', 'red', 'any'}: uint8 masks (255 = that colour) of a BGR image, with
    the floor's colour and brightness taken from the pixels where roi is set. colours: only
    these (and 'red', which 'any' needs and the pictures show); surroundings: floor_boxes(roi),
    when the caller keeps it for every frame of a size (it depends on the mask alone)."""
    wanted = {'white', 'yellow', 'red', 'any'} if colours is None else {*colours, 'red'}
    lab = cv2.cvtColor(bgr, cv2.COLOR_BGR2LAB)
    light, a, b = cv2.split(lab)
    floor, count = surroundings if surroundings is not None else floor_boxes(roi)
    # the surroundings: the floor around the pixel (not the wall, nor the border that
    # undistortion leaves empty), summed in integers so that a band of rows gives exactly
    # what the whole frame gives
    around = _box_sum(light * floor, floor.shape[1]).astype(np.float32) / count
    local = light.astype(np.float32) - around
    spread = 1.5 * _median(cv2.convertScaleAbs(local), floor) + 1.0
    bright = _median(light, floor)
    contrast = max(20.0, 2.5 * spread)
    road = _commonest(a, b, floor)
    # a first look, cheap and close: a grey surface's a*, b* (128 in 8 bits) are the light's
    # and grow with its L* + 16 (Lab's cube root of a gain per channel), so the road's are
    # scaled to each pixel's lightness; the exact tests run once, where any colour may be
    scale = (np.arange(256) + LAB_BLACK) / (bright + LAB_BLACK)
    maybe = {'red': a > cv2.LUT(light, _first_look(road[0], scale))}
    if wanted & {'white', 'any'}:
        maybe['any'] = (local > contrast) & (light > bright + 25)
    if 'yellow' in wanted:
        maybe['yellow'] = (b > cv2.LUT(light, _first_look(road[1], scale))) & (light > bright)
    at = np.flatnonzero(np.logical_or.reduce(list(maybe.values())))
    ea, eb = _balanced(bgr, bright, road, at)
    found = {'red': maybe['red'].ravel()[at] & (ea > 25) & (ea > np.abs(eb))}
    if 'any' in maybe:
        found['any'] = maybe['any'].ravel()[at] & ~found['red']
        found['white'] = found['any'] & (ea ** 2 + eb ** 2 < 625)
    if 'yellow' in maybe:
        found['yellow'] = maybe['yellow'].ravel()[at] & (eb > 25) & (2 * eb > 3 * np.abs(ea))
    masks = {}
    for name in ('white', 'yellow', 'red', 'any'):
        if name in wanted:
            masks[name] = np.zeros(light.shape, np.uint8)
            masks[name].ravel()[at[found[name]]] = 255
    return masks


def _balanced(bgr, bright, road, at):
    """(a*, b*) from neutral (int32) of the pixels `at` (flat indices) as a grey road would show
    them (von Kries): each channel times the gain that makes the road's colour (lightness
    bright, road's a*, b*) grey, then in Lab. The gains only raise a channel (at most CAST), so
    a pixel the camera clipped white stays white."""
    if not len(at):
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    grey = cv2.cvtColor(np.uint8([[[round(bright), round(road[0]), round(road[1])]]]),
                        cv2.COLOR_LAB2BGR).reshape(3).astype(float)
    gains = tuple(np.minimum(grey.max() / np.maximum(grey, 1.0), CAST)) + (0.0,)
    # one row of pixels: np.take and a single row cost half what indexing and a column did
    seen = cv2.multiply(np.take(bgr.reshape(-1, 3), at, axis=0)[None], gains, dtype=cv2.CV_8U)
    lab = cv2.cvtColor(seen, cv2.COLOR_BGR2LAB)[0]
    return lab[:, 1].astype(np.int32) - 128, lab[:, 2].astype(np.int32) - 128


def _first_look(road, scale):
    """A table for cv2.LUT, by lightness: the level of a* (or b*) above which a colour's exact
    test may hold, the road's scaled as a grey surface's, plus 25 - NEAR."""
    return np.minimum(np.clip(np.rint(128 + (road - 128) * scale), 0, 255) + 25 - NEAR,
                      255).astype(np.uint8)


def _commonest(a, b, floor, step=4):
    """(a*, b*) of the floor band's commonest colour, the road's (grass, sky or a mat at the
    side do not move it, as they move a median): the peak of their histogram in step-wide bins,
    each counted with its neighbours, refined as the mean over the peak's 3 x 3 bins. From every
    other row and column, in about half the time: within 0.07 levels of all the pixels' on the
    real frames' and gym-duckietown's first frames' lower halves."""
    bins = 256 // step
    hist = cv2.calcHist([a[::2, ::2], b[::2, ::2]], [0, 1], floor[::2, ::2], [bins, bins],
                        [0, 256, 0, 256])
    near = cv2.boxFilter(hist, -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
    i, j = np.unravel_index(int(np.argmax(near)), near.shape)
    i0, j0 = max(i - 1, 0), max(j - 1, 0)
    patch = hist[i0:i + 2, j0:j + 2]
    centres = (np.arange(bins) + 0.5) * step
    total = max(float(patch.sum()), 1.0)
    return (float(patch.sum(axis=1) @ centres[i0:i + 2]) / total,
            float(patch.sum(axis=0) @ centres[j0:j + 2]) / total)


def floor_boxes(roi):
    """(floor, count): the floor as a 0/1 uint8 mask (all of it where roi has none), and how
    many floor pixels each pixel's surroundings hold (at least 1, float32): what
    colour_masks divides by, the same for every frame with this mask."""
    floor = (roi > 0).astype(np.uint8)
    if not floor.any():
        floor[:] = 1
    return floor, np.maximum(_box_sum(floor, floor.shape[1]), 1).astype(np.float32)


def _median(image, mask):
    """The median of a uint8 image where mask is set (the lower one of an even count)."""
    counts = np.cumsum(cv2.calcHist([image], [0], mask, [256], [0, 256]).ravel())
    return float(np.searchsorted(counts, counts[-1] / 2))


def _box_sum(image, width):
    """Sum of the uint8 image over a box around each pixel (zero outside), as int32: the box
    BOX times the image's `width` wide and high, an odd number of pixels."""
    box = (2 * int(BOX * width / 2) + 1,) * 2
    return cv2.boxFilter(image, cv2.CV_32S, box, normalize=False,
                         borderType=cv2.BORDER_CONSTANT)


class Piece:
    """A nearly straight piece of tape on the floor: its points (robot frame, metres), each
    weighted by the length it stands for, its direction, and its colour; and `summary`, POINTS
    points that stand for it when the lane is fitted (x, y, weight): the means of its points
    in POINTS equal runs along its axis, each weighted by its share of the length."""

    def __init__(self, x, y, phi, colour, length, width, region=None):
        self.x, self.y, self.phi, self.colour = x, y, phi, colour
        self.length, self.width = length, width
        self.region = region  # the connected region of the mask it was cut from: one tape
        n = len(x)
        self.w = np.full(n, length / n)
        order = np.argsort(x * math.cos(phi) + y * math.sin(phi))
        xs, ys = x[order], y[order]
        # the runs np.array_split makes (the first n % POINTS one longer), as slices: its
        # index arrays cost more than the sums
        q, r = divmod(n, POINTS)
        ends = [k * q + min(k, r) for k in range(POINTS + 1)]
        self.summary = (np.array([xs[a:b].sum() / (b - a) for a, b in zip(ends, ends[1:])]),
                        np.array([ys[a:b].sum() / (b - a) for a, b in zip(ends, ends[1:])]),
                        np.full(POINTS, length / POINTS))  # the means: np.mean's sum, divided


def tape_pieces(mask, colour, matrix, mounting, tape_width, min_length, step, row0=0,
                max_points=120, side=None, budget=1500, elongation=ELONGATION['solid']):
    """The pieces of a colour mask (rows row0.. of an undistorted image with camera matrix
    `matrix`) on the floor: each connected region, seen on the floor, cut across into parts
    about `step` metres long by distance ahead, and a part still longer than 1.5 `step` (a
    line running across the view) halved across its own length until none is, so that a line
    gives nearly straight pieces of about that length whichever way it runs and however it
    curves (cut every so many rows instead, a piece near the camera would be shorter than the
    tape is wide). The cuts are square to the robot's heading or to the part's axis, not to
    the tape, so a piece's ends are cut obliquely where the tape runs askew: its middle stays
    on the tape, its direction can be off by some degrees. A piece not longer
    than it is wide, much narrower or wider than the tape (an edge, a glint, a blob, a sheet
    of paper) or shorter than min_length [m] is not kept. Where a piece has pixels on `side`
    (a mask: the edge of the view, see view_sides), the view cuts the tape: the points level
    with the cut are left out (their middle is not the tape's). At most `budget` pixels of a
    region and max_points of a piece are used."""
    count, labels, stats, (x0, y0) = _labelled(mask)
    regions = []  # (label, the pixels' view cuts) of each region, its pixels projected at once
    uv = []
    for i in range(1, count):
        if stats[i, cv2.CC_STAT_AREA] < 20:
            continue
        top, height = stats[i, cv2.CC_STAT_TOP], stats[i, cv2.CC_STAT_HEIGHT]
        left, span = stats[i, cv2.CC_STAT_LEFT], stats[i, cv2.CC_STAT_WIDTH]
        rows, cols = np.nonzero(labels[top:top + height, left:left + span] == i)
        rows += top + y0
        cols += left + x0
        cut = side[rows, cols] if side is not None else np.zeros(len(rows), bool)
        use = cut.copy()  # every pixel where the view cuts the tape, and a sample of the rest
        use[::max(1, len(rows) // budget)] = True
        regions.append((i, cut[use]))
        uv.append(np.stack([cols[use], rows[use] + row0], axis=1))
    if not regions:
        return []
    # one call for every region's pixels: a call a region cost more than the projecting
    ends = np.cumsum([len(cut) for _, cut in regions])[:-1]
    floor = pixels_to_floor(np.concatenate(uv).astype(float), matrix, mounting)
    pieces = []
    for (i, cut), x, y, ok in zip(regions, *(np.split(v, ends) for v in floor)):
        x, y, cut = x[ok], y[ok], cut[ok]
        if len(x) < 10:
            continue
        # across by distance ahead first (the image's rows), then each part that is still
        # longer than that (a line running across the view) across its own length
        low, span = x.min(), np.ptp(x)
        n = max(1, int(round(span / step)))  # equal parts, none a short stub
        which = np.minimum((x - low) / max(span, 1e-9) * n, n - 1).astype(int)
        for b in range(n):
            band = np.flatnonzero(which == b)
            for part in _halves(x[band], y[band], 1.5 * step):
                piece = _piece(x[band[part]], y[band[part]], cut[band[part]], colour,
                               tape_width, min_length, max_points, (colour, i), elongation)
                if piece is not None:
                    pieces.append(piece)
    return pieces


def _labelled(mask):
    """(count, labels, stats, (x0, y0)): the 8-connected regions of a mask, as
    cv2.connectedComponentsWithStats gives them for the part of it from column x0 and row y0
    (stats' positions in that part). Grana's block-based labelling: the same labels as the
    default (Spaghetti), in two thirds of its time on the floor band's masks; on the rectangle
    that holds the mask's pixels (about half the band), from an even row and column, so that
    its 2 x 2 blocks, and so its labels, are the whole mask's."""
    x0, y0, width, height = cv2.boundingRect(mask)
    x0, y0 = x0 - x0 % 2, y0 - y0 % 2
    count, labels, stats, _ = cv2.connectedComponentsWithStatsWithAlgorithm(
        mask[y0:y0 + height + 1, x0:x0 + width + 1], 8, cv2.CV_32S, cv2.CCL_BBDT)
    return count, labels, stats, (x0, y0)


def _axis(x, y):
    """(narrow, long, c, s) of points: the variances across and along their principal axis,
    and its direction (cos, sin). The 2x2 covariance's eigenvectors in closed form (numpy's
    general ones cost more than the rest of a piece), as floats: two small arrays made for
    four numbers cost more than the numbers."""
    n = len(x)
    dx, dy = x - x.sum() / n, y - y.sum() / n  # the means, as np.mean makes them, sooner
    sxx, syy, sxy = (float(dx @ dx) / (n - 1), float(dy @ dy) / (n - 1),
                     float(dx @ dy) / (n - 1))
    half, root = (sxx + syy) / 2, math.hypot((sxx - syy) / 2, sxy)
    angle = 0.5 * math.atan2(2 * sxy, sxx - syy)  # of the longest axis
    return half - root, half + root, math.cos(angle), math.sin(angle)


def _halves(x, y, longest):
    """Index arrays of the parts of the points (x, y) made by halving them across their
    principal axis, at the middle of its extent, until no part is longer than `longest`."""
    todo, parts = [np.arange(len(x))], []
    while todo:
        part = todo.pop()
        if len(part) < 10:
            continue
        px, py = x[part], y[part]
        if math.hypot(px.max() - px.min(), py.max() - py.min()) <= longest:  # np.ptp's,
            parts.append(part)  # in fewer calls: no longer than that any way
            continue
        _, _, c, s = _axis(px, py)
        along = px * c + py * s
        low, high = along.min(), along.max()
        if high - low <= longest:
            parts.append(part)
        else:
            middle = (low + high) / 2
            todo += [part[along < middle], part[along >= middle]]
    return parts


def view_sides(view):
    """The pixels of `view` (a mask: the part of the image that is looked at) on its edge: a
    neighbour outside it, or on the image's border."""
    inner = cv2.erode(view, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT,
                      borderValue=0)
    return (view > 0) & (inner == 0)


def _piece(x, y, cut, colour, tape_width, min_length, max_points, region=None,
           elongation=ELONGATION['solid']):
    if cut.any():
        # where the view cuts the tape, the tape's cross-sections are partial and their middle
        # is off its centre: leave out the points level (along the tape) with the cut
        _, _, c, s = _axis(x, y)
        along = x * c + y * s
        whole = (along < along[cut].min()) | (along > along[cut].max())
        x, y = x[whole], y[whole]
    if len(x) < 10:
        return None
    x, y = x[::max(1, len(x) // max_points)], y[::max(1, len(x) // max_points)]
    narrow, long, c, s = _axis(x, y)
    # a uniform strip of length L has a standard deviation of L / sqrt(12) along it
    length = math.sqrt(12 * max(long, 0.0))
    width = math.sqrt(12 * max(narrow, 0.0))
    if (length < min_length or length < elongation * width or
            not 0.4 * tape_width <= width <= 3.0 * tape_width):
        return None
    if c < 0:  # pointing ahead
        c, s = -c, -s
    return Piece(x, y, math.atan2(s, c), colour, length, width, region)
