"""Lane profiles, colour masks, pieces of tape, and the choice of the robot's own lane."""

import math
import warnings

import cv2
import numpy as np
import pytest

from kobuki_lane import LaneParams, main
from lanelib import lanefit
from lanelib.colour import ELONGATION, Piece, colour_masks, floor_boxes, tape_pieces, view_sides
from lanelib.geometry import Mounting, floor_to_pixels
from lanelib.improved import ImprovedController, ImprovedParams
from lanelib.lanefit import find_lane, signed_distance
from lanelib.lanes import BUILTIN, LaneError, load_lane
from tests.helpers import SAMPLES

DT = BUILTIN['duckietown']


# ---------------------------------------------------------------- profiles

def test_builtin_profiles_carry_their_published_dimensions():
    assert BUILTIN['lecture'].lane_width == 0.35
    assert (DT.lane_width, DT.left.colour, DT.left.style, DT.right.colour) == \
        (0.2375, 'yellow', 'dashed', 'white')
    assert (DT.left.width, DT.right.width) == (0.025, 0.05)  # 1 in and 2 in tape
    auto = BUILTIN['autorace']
    assert (auto.lane_width, auto.left.colour, auto.right.colour) == (0.285, 'yellow', 'white')
    assert DT.sides('yellow') == [1] and DT.sides('white') == [-1]
    assert BUILTIN['lecture'].sides('any') == [1, -1]


def test_a_lane_file_is_read(tmp_path):
    path = tmp_path / 'mine.yaml'
    path.write_text('lane_width: 0.3\nleft: {colour: white, style: dashed, width: 0.02}\n'
                    'right: {colour: yellow}\n')
    lane = load_lane(str(path))
    assert lane.lane_width == 0.3 and lane.left.colour == 'white' and lane.left.width == 0.02
    assert lane.right.colour == 'yellow' and lane.right.width == 0.03  # the default tape
    assert lane.colours == ['white', 'yellow']


@pytest.mark.parametrize('text, message', [
    ('lane_width: -1\nleft: {}\nright: {}', 'mine.yaml.lane_width must be a positive number'),
    ('left: {}\nright: {}', 'mine.yaml.lane_width is missing'),
    ('lane_width: 0.3\nleft: {colour: blue}\nright: {}', "mine.yaml.left.colour must be white, "
                                                          "yellow or any, not 'blue'"),
    ('lane_width: 0.3\nleft: {}\nright: {style: dotted}', 'mine.yaml.right.style must be solid'),
    ('lane_width: 0.3\nleft: {width: 0}\nright: {}', 'mine.yaml.left.width must be a tape'),
    ('lane_width: 0.05\nleft: {width: 0.03}\nright: {width: 0.03}', 'do not fit in lane_width'),
    ('lane_width: 0.3\nleft: {}\nright: {}\nlanes: 2', 'unknown key(s) lanes'),
    ('lane_width: [0.3', 'cannot read as YAML'),
])
def test_a_bad_lane_file_names_the_field(tmp_path, text, message):
    path = tmp_path / 'mine.yaml'
    path.write_text(text)
    with pytest.raises(LaneError, match=None) as e:
        load_lane(str(path))
    assert message in str(e.value)


def test_the_node_refuses_a_bad_lane_with_status_2(tmp_path, capsys):
    path = tmp_path / 'mine.yaml'
    path.write_text('lane_width: 0.3\nleft: {colour: blue}\nright: {}')
    for lane, message in ((str(path), "left.colour must be white, yellow or any, not 'blue'"),
                          ('kerb', "lane 'kerb' is neither a built-in profile")):
        with pytest.raises(SystemExit) as e:
            main(['--source', SAMPLES, '--dry-run', '--controller', 'improved', '--lane', lane])
        assert e.value.code == 2
        assert message in capsys.readouterr().err


# ---------------------------------------------------------------- colour

def floor_scene(floor=(90, 90, 90), tapes=(), size=(240, 320)):
    """A flat floor with vertical stripes of tape: (column, width px, BGR colour)."""
    image = np.zeros(size + (3,), np.uint8)
    image[:] = floor
    for column, width, colour in tapes:
        image[:, column:column + width] = colour
    return image


WHITE, YELLOW, RED = (235, 235, 235), (40, 200, 220), (40, 40, 210)


def columns_under(scene, light):
    """The image columns each colour mask holds, the scene lit by `light` (a gain, or one per
    BGR channel) and judged over the whole frame."""
    lit = np.clip(scene * np.asarray(light), 0, 255).astype(np.uint8)
    masks = colour_masks(lit, np.full(lit.shape[:2], 255, np.uint8))
    return {name: set(np.flatnonzero(mask.any(axis=0))) for name, mask in masks.items()}


@pytest.mark.parametrize('light', [0.35, 1.0, 1.6], ids=['dim room', 'lab', 'bright sun'])
@pytest.mark.parametrize('cast', [(1.0, 1.0, 1.0), (0.8, 0.95, 1.25)], ids=['neutral', 'warm'])
def test_colours_are_found_in_the_light_that_is_there(light, cast):
    scene = floor_scene(tapes=[(60, 12, WHITE), (150, 12, YELLOW), (240, 12, RED)])
    columns = columns_under(scene, light * np.array(cast))
    assert columns['white'] == set(range(60, 72))
    assert columns['yellow'] == set(range(150, 162))
    assert columns['red'] == set(range(240, 252))
    assert set(range(60, 72)) <= columns['any']  # white is lighter than the floor: a tape
    assert not columns['any'] & set(range(240, 252))  # red tape on grey is not lighter


@pytest.mark.parametrize('light', [0.6, 1.0, 1.3], ids=['dim', 'lit', 'clipping'])
@pytest.mark.parametrize('cast', [(0.5, 0.9, 1.0), (0.6, 1.0, 0.8), (1.0, 0.7, 0.9)],
                         ids=['yellow light', 'green light', 'magenta light'])
def test_a_coloured_light_does_not_colour_white_tape(light, cast):
    # a light multiplies every channel: on a dark road, white tape under a yellow light is
    # the road's colour times more light, so it looks yellow by an offset in a*, b* (gym-
    # duckietown's domain randomisation: the robot never moved), grey once the road is
    scene = floor_scene(floor=(60, 60, 60),
                        tapes=[(60, 12, WHITE), (150, 12, YELLOW), (240, 12, RED)])
    columns = columns_under(scene, light * np.array(cast))
    assert columns['white'] == set(range(60, 72))
    assert columns['yellow'] == set(range(150, 162))
    assert columns['red'] == set(range(240, 252))


def test_grass_beside_the_road_neither_sets_its_colour_nor_becomes_white():
    # the light's colour is the road's commonest colour, not the band's median: with nearly
    # half the band in speckled grass, under a yellow light, the tapes on the road are found
    # as they are and no speck of grass is white
    rng = np.random.default_rng(1)
    scene = floor_scene(floor=(60, 60, 60), tapes=[(40, 12, WHITE), (110, 12, YELLOW)])
    grass = np.stack([rng.integers(20, 60, (240, 150)), rng.integers(90, 200, (240, 150)),
                      rng.integers(30, 90, (240, 150))], axis=2)
    scene[:, 170:] = grass
    columns = columns_under(scene, (0.5, 0.9, 1.0))
    assert columns['white'] == set(range(40, 52))  # and no speck of grass
    assert columns['yellow'] - set(range(170, 320)) == set(range(110, 122))


@pytest.mark.parametrize('colours', [['any'], ['white', 'yellow'], ['yellow']])
def test_only_the_colours_asked_for_are_made_and_they_are_the_same(colours):
    # the controller asks for its profile's colours and keeps the floor's surroundings per
    # frame size: the masks it gets are those made in full, to the bit
    scene = floor_scene(tapes=[(60, 12, WHITE), (150, 12, YELLOW), (240, 12, RED)])
    roi = np.zeros(scene.shape[:2], np.uint8)
    roi[40:, 20:300] = 255
    full = colour_masks(scene, roi)
    some = colour_masks(scene, roi, colours, floor_boxes(roi))
    assert set(some) == {*colours, 'red'}
    for name, mask in some.items():
        assert np.array_equal(mask, full[name]), name


def test_a_floor_brighter_on_one_side_does_not_make_lines():
    ramp = np.tile(np.linspace(40, 200, 320), (240, 1))  # a lamp to one side
    scene = np.repeat(ramp[..., None], 3, axis=2).astype(np.uint8)
    scene[:, 200:212] = np.clip(scene[:, 200:212].astype(int) + 60, 0, 255)
    masks = colour_masks(scene, np.full((240, 320), 255, np.uint8))
    assert set(np.flatnonzero(masks['any'].any(axis=0))) == set(range(200, 212))


def test_the_floor_is_judged_only_where_the_mask_says():
    # the wall above the floor band is white: judged as floor, it would make the floor dark
    scene = floor_scene(tapes=[(100, 12, WHITE)])
    scene[:80] = 250
    roi = np.zeros((240, 320), np.uint8)
    roi[80:] = 255
    masks = colour_masks(scene, roi)
    assert set(np.flatnonzero(masks['white'][80:].any(axis=0))) == set(range(100, 112))


# ---------------------------------------------------------------- pieces of tape

MOUNT = Mounting(0.10, 20.0, 0.0)
K = np.array([[300.0, 0, 320], [0, 300.0, 240], [0, 0, 1]])


def painted(lines, size=(480, 640), along=(0.12, 1.5)):
    """A mask with floor strips painted on it: (y centre [m], width [m]) running ahead."""
    mask = np.zeros(size, np.uint8)
    x = np.linspace(*along, 400)
    for y, width in lines:
        left = floor_to_pixels(x, np.full_like(x, y + width / 2), K, MOUNT)
        right = floor_to_pixels(x, np.full_like(x, y - width / 2), K, MOUNT)
        polygon = np.concatenate([np.stack(left[:2], 1), np.stack(right[:2], 1)[::-1]])
        cv2.fillPoly(mask, [np.round(polygon).astype(np.int32)], 255)
    return mask


def test_tape_pieces_lie_where_the_tape_is_on_the_floor():
    pieces = tape_pieces(painted([(0.12, 0.025), (-0.12, 0.05)]), 'white', K, MOUNT, 0.05,
                         0.02, step=0.15)
    assert len(pieces) >= 8
    for piece in pieces:
        assert abs(abs(np.mean(piece.y)) - 0.12) < 0.01
        assert abs(piece.phi) < math.radians(3)  # along the line, near the camera too
        assert piece.length == pytest.approx(0.15, abs=0.05) or piece.length < 0.15


def test_pieces_much_wider_or_narrower_than_the_tape_are_not_kept():
    # a sheet of A4 paper on the floor and a seam 5 mm wide, for a 5 cm tape
    mask = painted([(0.0, 0.21)], along=(0.4, 0.697)) | painted([(-0.15, 0.005)])
    assert tape_pieces(mask, 'white', K, MOUNT, 0.05, 0.02, step=0.15) == []
    # and a tape of the right width is
    assert len(tape_pieces(painted([(0.0, 0.05)]), 'white', K, MOUNT, 0.05, 0.02, step=0.15)) > 5


def test_a_masks_regions_are_labelled_as_in_the_whole_mask():
    # colour._labelled labels only the rectangle that holds the mask's pixels: its labels and
    # their statistics, put back in place, are those of the whole mask, wherever the
    # rectangle starts (odd rows and columns among them)
    from lanelib.colour import _labelled
    rng = np.random.default_rng(3)
    for _ in range(40):
        mask = np.zeros((120, 160), np.uint8)
        for _ in range(rng.integers(1, 8)):
            x, y = (int(v) for v in rng.integers(0, (150, 110)))
            w, h = (int(v) for v in rng.integers(1, 40, 2))
            mask[y:y + h, x:x + w] = 255 * (rng.random((min(h, 120 - y), min(w, 160 - x))) < 0.8)
        count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        got, part, part_stats, (x0, y0) = _labelled(mask)
        placed = np.zeros_like(labels)
        placed[y0:y0 + part.shape[0], x0:x0 + part.shape[1]] = part
        assert got == count and np.array_equal(placed, labels)
        moved = part_stats[1:].copy()
        moved[:, cv2.CC_STAT_LEFT] += x0
        moved[:, cv2.CC_STAT_TOP] += y0
        assert np.array_equal(moved, stats[1:])
    assert _labelled(np.zeros((10, 12), np.uint8))[0] == 1  # no pixel: no region


def test_a_dash_need_only_be_a_little_longer_than_wide_a_piece_of_solid_line_more():
    # dashes 4 cm long and 3 cm wide, 8 cm apart, running ahead on the left: what
    # gym-duckietown's 2 by 1 in dashes measure with domain rand (1.3 to 1.5 times as long)
    dashes = [painted([(0.12, 0.03)], along=(x0, x0 + 0.04)) for x0 in (0.3, 0.38, 0.46)]
    mask = dashes[0] | dashes[1] | dashes[2]
    kept = tape_pieces(mask, 'yellow', K, MOUNT, 0.025, 0.02, step=0.06,
                       elongation=ELONGATION['dashed'])
    assert len(kept) == 3
    for piece in kept:  # where the dash is, and along the line
        assert abs(np.mean(piece.y) - 0.12) < 0.01 and abs(piece.phi) < math.radians(20)
    assert tape_pieces(mask, 'yellow', K, MOUNT, 0.025, 0.02, step=0.06) == []  # solid's rule
    # a square of tape is no dash
    square = painted([(0.12, 0.04)], along=(0.3, 0.34))
    assert tape_pieces(square, 'yellow', K, MOUNT, 0.025, 0.02, step=0.06,
                       elongation=ELONGATION['dashed']) == []


def test_the_improved_perception_cuts_a_colour_only_dashed_lines_have_into_dashes(monkeypatch):
    import lanelib.perception as perception

    asked = {}

    def spy(mask, colour, *args, elongation=ELONGATION['solid'], **kw):
        asked[colour] = elongation
        return []

    monkeypatch.setattr(perception, 'tape_pieces', spy)
    frame = floor_scene()
    for lane, wanted in (('duckietown', {'yellow': 1.2, 'white': 1.5}), ('lecture', {'any': 1.5})):
        asked.clear()
        improved = ImprovedController(LaneParams(), ImprovedParams(lane=lane), camera=None)
        improved.perceive(frame)
        assert asked == wanted


def test_a_tape_the_view_cuts_keeps_its_middle():
    # a tape running out of the side of the view (the robot turned towards it): where the
    # view's edge cuts it, its pixels stop short of its far edge; those are left out
    y, width = -0.10, 0.05
    x = np.linspace(0.12, 1.5, 400)
    mask = np.zeros((480, 640), np.uint8)
    yaw = math.radians(35)  # the tape heads 35 degrees to the right of the robot
    ys = y - np.tan(yaw) * x
    left = floor_to_pixels(x, ys + width / 2 / math.cos(yaw), K, MOUNT)
    right = floor_to_pixels(x, ys - width / 2 / math.cos(yaw), K, MOUNT)
    polygon = np.concatenate([np.stack(left[:2], 1), np.stack(right[:2], 1)[::-1]])
    cv2.fillPoly(mask, [np.round(polygon).astype(np.int32)], 255)
    view = np.full_like(mask, 255)
    cut = tape_pieces(mask, 'white', K, MOUNT, 0.05, 0.02, step=0.15, side=view_sides(view))
    assert cut
    for piece in cut:  # its middle on the tape's centre line, within a tenth of its width
        centre = y - np.tan(yaw) * piece.x
        assert np.abs(np.mean(piece.y - centre)) * math.cos(yaw) < 0.005
    # without the view's edge known, the piece at the edge sits off the centre line
    uncut = tape_pieces(mask, 'white', K, MOUNT, 0.05, 0.02, step=0.15)
    worst = max(abs(np.mean(p.y - (y - np.tan(yaw) * p.x))) * math.cos(yaw) for p in uncut)
    assert worst > 0.01


def test_a_stop_line_is_never_a_lane_line():
    scene = floor_scene(tapes=[(100, 12, WHITE)])
    scene[150:170, 20:300] = (40, 40, 200)  # red, across the lane
    masks = colour_masks(scene, np.full(scene.shape[:2], 255, np.uint8))
    assert masks['red'][150:170, 20:300].mean() > 200
    assert not masks['white'][150:170, 20:300].any() and not masks['any'][150:170, 20:300].any()


# ---------------------------------------------------------------- the lane

def line_pieces(y, colour, along=(0.15, 0.8), bend=0.0, step=0.1, dashed=False):
    """Pieces of a line at lateral y, bending with curvature `bend` [1/m] (about the robot)."""
    pieces = []
    for i, s0 in enumerate(np.arange(along[0], along[1], step)):
        if dashed and i % 2:
            continue
        s = np.linspace(s0, s0 + step, 20)
        if bend:
            r = 1 / bend - y  # the line's own radius about the bend's centre (0, 1 / bend)
            angle = s / abs(1 / bend)
            x, yy = r * np.sin(angle) * np.sign(bend), 1 / bend - r * np.cos(angle)
        else:
            x, yy = s, np.full_like(s, y)
        phi = math.atan2(yy[-1] - yy[0], x[-1] - x[0])
        pieces.append(Piece(x, yy, phi, colour, float(np.hypot(np.diff(x), np.diff(yy)).sum()),
                            0.03))
    return pieces


def test_signed_distance_is_exact_for_arcs_and_lines():
    rng = np.random.default_rng(0)
    x, y = rng.uniform(0, 2, 50), rng.uniform(-1, 1, 50)
    for e, psi, k in [(0.05, 0.3, 2.0), (-0.1, -0.5, -4.0)]:
        cx, cy = -math.sin(psi) / k, e + math.cos(psi) / k
        truth = (1 / abs(k) - np.hypot(x - cx, y - cy)) * np.sign(k)
        assert np.allclose(signed_distance(x, y, e, psi, k), truth, atol=1e-12)
    assert np.allclose(signed_distance(x, y, 0.1, 0.0, 0.0), y - 0.1)


def test_the_lane_chosen_does_not_depend_on_the_order_the_pieces_come_in():
    # the pieces of a real Duckietown frame (visual_control_test.png, the duckiebot preset:
    # x, y [m], direction [rad], colour, length, width [m]): two dashes and a white piece near
    # the robot, a calibration board's edge and yellow things beyond it. A straight lane and
    # one turned 44 degrees at the robot, bending back 2.9 /m to run along the same three
    # pieces, explain them alike; the one nearer its pieces is the lane, whatever their order
    def piece(x0, y0, phi, colour, length, width):
        s = np.linspace(-length / 2, length / 2, 20)
        return Piece(x0 + s * math.cos(phi), y0 + s * math.sin(phi), phi, colour, length, width)

    pieces = [piece(0.654, -0.121, -0.143, 'yellow', 0.164, 0.019),
              piece(0.672, -0.334, -0.580, 'yellow', 0.102, 0.037),
              piece(0.247, -0.100, 0.076, 'white', 0.101, 0.032),
              piece(0.409, 0.126, 1.304, 'white', 0.097, 0.047),
              piece(0.727, -0.306, -0.349, 'yellow', 0.090, 0.016),
              piece(0.239, 0.124, -0.065, 'yellow', 0.041, 0.024),
              piece(0.300, 0.120, -0.082, 'yellow', 0.036, 0.025),
              piece(0.362, 0.196, 0.665, 'yellow', 0.034, 0.010)]
    rng = np.random.default_rng(1)
    chosen = set()
    for _ in range(30):
        fit = find_lane([pieces[i] for i in rng.permutation(len(pieces))], DT, DT.lane_width)
        chosen.add((round(fit.e, 3), round(fit.psi, 2), round(fit.k, 1)))
    assert len(chosen) == 1
    (e, psi, k), = chosen
    assert abs(psi) < 0.05 and abs(k) < 0.5  # the straight lane the near pieces run along


def test_a_straight_lane_is_found_where_it_is():
    half = DT.lane_width / 2
    pieces = line_pieces(0.03 + half, 'yellow', dashed=True) + line_pieces(0.03 - half, 'white')
    fit = find_lane(pieces, DT, DT.lane_width)
    assert fit.e == pytest.approx(0.03, abs=0.005) and abs(fit.psi) < 0.01
    assert abs(fit.k) < 0.1 and fit.width == pytest.approx(DT.lane_width, abs=0.005)
    assert set(fit.sides) == {1, -1}


def test_a_settled_fit_is_not_fitted_again_to_the_same_sides(monkeypatch):
    # a tolerance round whose pieces fall on the same sides as the round before, where the fit
    # had settled, is skipped: the lanes found are those of fitting every round, and fewer fits
    # are made (with SETTLED 0 no fit counts as settled, so every round fits)
    half = DT.lane_width / 2
    rng = np.random.default_rng(3)
    cases = []
    for across, bend in ((0.03, 0.0), (-0.02, 2.5), (0.01, -3.0)):
        pieces = (line_pieces(across + half, 'yellow', bend=bend, dashed=True) +
                  line_pieces(across - half, 'white', bend=bend))
        for p in pieces:  # a little noise, so that no fit is exact at its start
            p.summary[1][:] += rng.normal(0.0, 0.003, len(p.summary[1]))
        cases += [(pieces, None), (pieces, (across + 0.01, 0.02, bend)),
                  (line_pieces(across - half, 'white', bend=bend), None)]
    # a short white scrap 0.3 lane widths inside the right line, too short to move the lane:
    # the lane predicted settles in the first round, the scrap on its right line there and in
    # the second, off it in the third (a quarter of a lane width), which must be fitted again
    x = np.linspace(0.3, 0.4, 20)
    scrap = Piece(x, np.full_like(x, 0.03 - half + 0.3 * DT.lane_width), 0.0, 'white', 0.01, 0.03)
    straight = line_pieces(0.03 + half, 'yellow', dashed=True) + line_pieces(0.03 - half, 'white')
    cases.append((straight + [scrap], (0.03, 0.0, 0.0)))
    fitted = lanefit.fit_lanes
    counts = {}

    def counted(*args, **kwargs):
        counts[mode] = counts.get(mode, 0) + 1
        return fitted(*args, **kwargs)

    monkeypatch.setattr(lanefit, 'fit_lanes', counted)
    found = {}
    for mode, settled in (('skip', lanefit.SETTLED), ('every', 0.0)):
        monkeypatch.setattr(lanefit, 'SETTLED', settled)
        found[mode] = [find_lane(pieces, DT, DT.lane_width, prior=prior, prior_first=True)
                       for pieces, prior in cases]
    for a, b in zip(found['skip'], found['every']):
        assert (a.e, a.psi, a.k, a.width) == pytest.approx((b.e, b.psi, b.k, b.width), abs=1e-9)
        assert list(a.sides) == list(b.sides) and (a.bend is None) == (b.bend is None)
    assert counts['skip'] < counts['every']


def test_a_bend_is_one_lane():
    pieces = (line_pieces(DT.lane_width / 2, 'yellow', bend=2.5) +
              line_pieces(-DT.lane_width / 2, 'white', bend=2.5))
    fit = find_lane(pieces, DT, DT.lane_width)
    assert fit.k == pytest.approx(2.5, rel=0.1) and abs(fit.e) < 0.01
    assert all(fit.sides != 0)


def test_the_neighbouring_lane_and_a_wrong_colour_are_not_the_robots():
    # a two-lane road: the robot in the right lane; the left lane's white edge further left
    w = DT.lane_width
    own = line_pieces(w / 2, 'yellow', dashed=True) + line_pieces(-w / 2, 'white')
    neighbour = line_pieces(1.5 * w, 'white')
    fit = find_lane(own + neighbour, DT, w)
    assert abs(fit.e) < 0.01
    assert list(fit.sides[len(own):]) == [0] * len(neighbour)
    # the same lines for a profile with two white lines: still the lane the robot is in
    assert abs(find_lane(own + neighbour, BUILTIN['lecture'], w).e) < 0.01


def test_one_line_places_the_lane_half_a_width_beside_it():
    fit = find_lane(line_pieces(-0.08, 'white'), DT, DT.lane_width)
    assert fit.e == pytest.approx(-0.08 + DT.lane_width / 2, abs=0.005)
    assert fit.width == pytest.approx(DT.lane_width, abs=1e-6)


def test_lines_further_apart_than_the_profile_are_measured_not_tilted():
    # a camera pitched a little off sees the lines 20 % further apart; the left line is seen
    # only far ahead, the right one only near: held to the profile's width, the lane tilts
    w = 1.2 * DT.lane_width
    pieces = (line_pieces(w / 2, 'yellow', along=(0.45, 0.8)) +
              line_pieces(-w / 2, 'white', along=(0.15, 0.45)))
    fit = find_lane(pieces, DT, DT.lane_width)
    fixed = find_lane(pieces, DT, DT.lane_width, width_tolerance=0.0)
    assert fit.width > 1.12 * DT.lane_width and fixed.width == DT.lane_width
    assert abs(fit.e) < 0.01 and abs(math.degrees(fit.psi)) < 1.0
    assert abs(fixed.e) > 0.03 and abs(math.degrees(fixed.psi)) > 3.0


def drawn_by_a_camera_pitched_off(pieces, stretch):
    """The pieces as a camera pitched a little more than its mounting says draws them: the
    floor stretched by 1 / (1 - stretch x) at x ahead (x, y both)."""
    out = []
    for p in pieces:
        scale = 1.0 / (1.0 - stretch * p.x)
        x, y = p.x * scale, p.y * scale
        out.append(Piece(x, y, math.atan2(y[-1] - y[0], x[-1] - x[0]), p.colour,
                         float(np.hypot(np.diff(x), np.diff(y)).sum()), p.width))
    return out


def test_lines_splayed_by_a_pitch_off_the_mounting_are_fitted_splayed_not_tilted():
    # a camera pitched 3 degrees more than its mounting says, 0.1 m up: the floor drawn 1.4
    # times as far ahead at 0.8 m, and the lines splayed. The left line is seen only far ahead,
    # the right one only near: fitted parallel the lane tilts (5.6 degrees); with the spread
    # free (a 4 degree tolerance) it is nearly where it is (1.1 degrees: the spread is pulled
    # a little towards none, the mounting as given), its width at the robot the profile's
    stretch = math.tan(math.radians(3.0)) / 0.10
    w = DT.lane_width
    pieces = drawn_by_a_camera_pitched_off(
        line_pieces(w / 2, 'yellow', along=(0.4, 0.7)) +
        line_pieces(-w / 2, 'white', along=(0.12, 0.4)), stretch)
    limit = w * math.tan(math.radians(4.0)) / 0.10
    free = find_lane(pieces, DT, w, spread_limit=limit)
    parallel = find_lane(pieces, DT, w)
    assert abs(free.e) < 0.01 and abs(math.degrees(free.psi)) < 1.5
    assert free.width == pytest.approx(w, rel=0.05)
    assert free.spread == pytest.approx(w * stretch, rel=0.25)
    assert parallel.spread == 0.0
    assert abs(math.degrees(parallel.psi)) > 3.0
    # one line alone, with no lane expected, is not splayed (the spread is pulled towards
    # none), and its splay is a tilt (the controller corrects the pitch: test_estimate.py)
    right = [p for p in pieces if p.colour == 'white']
    alone = find_lane(right, DT, w, spread_limit=limit)
    assert abs(alone.spread) < 1e-3 and abs(math.degrees(alone.psi)) > 2.5


def test_a_lane_with_a_line_down_its_middle_is_not_chosen():
    # a white line 5 cm right of the robot, a yellow line beyond the lane width on its left,
    # and a duck house (white) further right: the house and the yellow would make a lane
    # with both sides seen, but with the white line inside it
    w = DT.lane_width
    pieces = (line_pieces(-0.05, 'white', along=(0.15, 0.8)) +
              line_pieces(w / 2 + 0.08, 'yellow', along=(0.5, 0.7)) +
              line_pieces(-w / 2 - 0.06, 'white', along=(0.5, 0.7)))
    fit = find_lane(pieces, DT, w)
    assert fit.e == pytest.approx(-0.05 + w / 2, abs=0.01)


def rendered_duckietown_lane(**settings):
    """(image, controller): a painted Duckietown lane 2 cm left of the robot, seen by the
    pinhole camera K 0.10 m up and pitched 20 degrees, and an improved controller told so
    (`settings` added to its ImprovedParams)."""
    from lanelib.camera import Camera

    image = np.full((480, 640, 3), 60, np.uint8)
    for y, width, colour in ((0.02 + DT.lane_width / 2, 0.025, YELLOW),
                             (0.02 - DT.lane_width / 2, 0.05, WHITE)):
        image[painted([(y, width)]) > 0] = colour
    p = ImprovedParams(lane='duckietown', camera_height=0.10, camera_pitch=20.0,
                       camera_forward=0.0, roi_near=0.12 / 0.2375, roi_far=0.8 / 0.2375,
                       memory=0.0, **settings)
    return image, ImprovedController(LaneParams(), p, Camera('pinhole', K, np.zeros(5),
                                                             (640, 480)))


def test_the_controller_reads_a_rendered_duckietown_lane():
    # the colour masks, the pieces and the fit together, on a painted floor
    image, ctl = rendered_duckietown_lane()
    command = ctl(ctl.perceive(image))
    record = ctl.extra()
    assert record['offset_m'] == pytest.approx(-0.02, abs=0.01)  # robot right of centre
    assert abs(record['heading_rad']) < 0.03
    assert record['lane_width_m'] == pytest.approx(DT.lane_width, abs=0.01)
    assert command.decision == 'straight' and command.angular_z > 0  # back to the centre


def test_the_pitch_correction_puts_the_pieces_on_the_floor_once_in_perceive(monkeypatch):
    # with the camera's pitch corrected, perceive() projects the pixels with it: the pieces
    # lie where moving those found with the mounting's pitch puts them (geometry.repitched),
    # and the controller does not move them a second time
    import lanelib.improved as improved
    from lanelib.perception import repitched_pieces

    image, ctl = rendered_duckietown_lane(pitch_tolerance=4.0)
    level = ctl.perceive(image)
    ctl.pitch_error = 2.0
    turned = ctl.perceive(image)
    assert (level.pitch, turned.pitch) == (0.0, 2.0)
    moved = repitched_pieces(level.pieces, ctl.p.mounting, 2.0)

    def points(pieces, colour):
        return np.concatenate([np.stack([q.x, q.y], 1) for q in pieces if q.colour == colour])

    def line(pieces, colour):  # [m] where the line's points put it 0.2 and 0.5 m ahead
        x, y = points(pieces, colour).T
        return np.polyval(np.polyfit(x, y, 1), [0.2, 0.5])

    # (cut into pieces on the floor each sees, so not the same pieces: the same lines)
    for colour in ('white', 'yellow'):
        now, then, before = (line(d, colour) for d in (turned.pieces, moved, level.pieces))
        assert np.abs(now - then).max() < 0.002
        assert np.abs(before - then).max() > 0.005  # the correction does move them
    calls = []
    monkeypatch.setattr(improved, 'repitched_pieces',
                        lambda *args: calls.append(args[2]) or repitched_pieces(*args))
    ctl(turned)
    assert calls == []  # already where the corrected pitch puts them
    ctl.pitch_error = 2.0
    ctl(level)  # a detection made before the correction: moved by what it lacks
    assert calls == [2.0]


def test_an_expected_lane_steadies_the_offset_a_far_bend_cannot_fix():
    # one line seen only far ahead, bending: many arcs through the robot fit it nearly as
    # well; the offset and heading the lane had at the robot (from memory) pick the right one
    half = DT.lane_width / 2
    pieces = line_pieces(-half, 'white', along=(0.6, 1.0), bend=1.5)
    free = find_lane(pieces, DT, DT.lane_width)
    anchored = find_lane(pieces, DT, DT.lane_width, anchor=(0.0, 0.0))
    assert abs(anchored.e) < 0.01 and abs(anchored.psi) < math.radians(2)
    assert anchored.k == pytest.approx(1.5, rel=0.15)
    assert abs(free.e) + abs(free.psi) > abs(anchored.e) + abs(anchored.psi)


@pytest.mark.parametrize('expected', [-0.12, 0.12])
def test_one_line_of_either_side_is_given_to_the_side_the_lane_was_expected(expected):
    # a tape of any colour straight under the robot, the only line in view: the lane either
    # has it as its left line (centre half a width right) or as its right line (half a width
    # left), equally supported, the robot inside both; where the lane was expected to be at
    # the robot decides (without it, the choice went one way whatever was expected, and a
    # tape bending across the view flipped the estimate by a lane width between frames)
    lecture = BUILTIN['lecture']
    half = lecture.lane_width / 2
    pieces = line_pieces(0.0, 'any', along=(0.3, 1.0))
    fit = find_lane(pieces, lecture, lecture.lane_width, anchor=(expected, 0.0))
    assert fit.e == pytest.approx(math.copysign(half, expected), abs=0.04)  # (pulled a little)
    assert set(fit.sides) == {-1 if expected > 0 else 1}


def test_one_line_is_not_given_a_side_by_the_refitted_prior_alone():
    # the lane predicted from earlier frames lies so that the one line in view is nearer its
    # left line (its bend underestimated: the outer tape of a bend sweeps across the view),
    # while the lane at the robot is known to be left of that line: the refitted prediction
    # explains all the line in view either way, so it does not end the search; the search,
    # with where the lane was expected at the robot, gives the line to the right
    lecture = BUILTIN['lecture']
    half = lecture.lane_width / 2
    pieces = line_pieces(0.0, 'any', along=(0.5, 1.0))
    fit = find_lane(pieces, lecture, lecture.lane_width, prior=(-0.15, 0.0, 0.0),
                    anchor=(0.12, 0.0))
    assert fit.e == pytest.approx(half, abs=0.04) and set(fit.sides) == {-1}


def test_the_lane_predicted_is_refitted_alike_alone_or_inside_the_search():
    # find_lane refits the lane predicted as the search's first seed, or with prior_first
    # alone before the search (each seed grows on its own): the lane found is the same
    half = DT.lane_width / 2
    both = line_pieces(half, 'yellow', dashed=True) + line_pieces(-half, 'white')
    one = line_pieces(-half, 'white')
    cases = ((both, (0.01, 0.03, 0.2), True), (one, (0.0, 0.0, 0.0), False),
             (both, (half, 0.0, 0.0), True))
    for pieces, prior, held in cases:
        inside = find_lane(pieces, DT, DT.lane_width, prior=prior)
        alone = find_lane(pieces, DT, DT.lane_width, prior=prior, prior_first=True)
        assert inside.predicted == alone.predicted == held
        assert (alone.e, alone.psi, alone.k, alone.width) == pytest.approx(
            (inside.e, inside.psi, inside.k, inside.width), abs=1e-9)
        assert list(alone.sides) == list(inside.sides)
    assert not find_lane(both, DT, DT.lane_width).predicted  # no lane predicted


def test_the_search_keeps_each_distinct_lane_once_as_numpys_unique_would():
    # lanefit._firsts stands in for np.unique(axis=0, return_index=True), sorted: the first
    # of each set of equal rows, in order (0.0 and -0.0 equal, as np.unique has them)
    from lanelib.lanefit import _firsts
    rng = np.random.default_rng(1)
    for n in (1, 2, 7, 60, 183):
        for _ in range(50):
            rows = np.round(rng.normal(0.0, 2.0, (n, 4)))
            rows[rng.random(n) < 0.3] = rows[0]
            rows[rng.random((n, 4)) < 0.1] *= -0.0
            expected = np.sort(np.unique(rows, axis=0, return_index=True)[1])
            assert list(_firsts(rows)) == list(expected)
    assert list(_firsts(np.array([[0.0, 1.0], [-0.0, 1.0], [1.0, 0.0]]))) == [0, 2]


def bending_line_pieces(y0, start, radius, along, step=0.08):
    """Pieces of a line at lateral y0, straight to x = start, then bending left round a centre
    line of `radius` [m]; `along`: the stretch of the line in view (metres along it)."""
    r = radius - y0  # the line's own radius
    pieces = []
    for s0 in np.arange(along[0], along[1] - 1e-9, step):
        s = np.linspace(s0, s0 + step, 20)
        turned = np.maximum(s - start, 0.0) / r
        x = np.where(s < start, s, start + r * np.sin(turned))
        y = np.where(s < start, y0, y0 + r * (1 - np.cos(turned)))
        pieces.append(Piece(x, y, math.atan2(y[-1] - y[0], x[-1] - x[0]), 'any',
                            float(np.hypot(np.diff(x), np.diff(y)).sum()), 0.03))
    return pieces


def test_a_line_bent_across_the_view_beyond_a_gap_is_not_the_other_line():
    # wood's 0.5 m corner with a gap in its outer tape: the right line is seen before the gap
    # and again beyond it, where it has turned 60 to 80 degrees and lies a lane width to the
    # left, where the left line would be (the inner tape is out of view). Given to the left,
    # it made a straight lane of the two, and the robot drove out of the bend. It runs across
    # the lines there, not along them: it is not the lane's
    lecture = BUILTIN['lecture']
    half = lecture.lane_width / 2
    near = bending_line_pieces(-half, 0.35, 0.5, (0.45, 0.75))
    beyond = bending_line_pieces(-half, 0.35, 0.5, (1.12, 1.36))
    assert min(math.degrees(p.phi) for p in beyond) > 65
    assert min(p.y.mean() for p in beyond) > half  # where a left line would be
    fit = find_lane(near + beyond, lecture, lecture.lane_width, anchor=(0.0, 0.0))
    assert list(fit.sides[:len(near)]) == [-1] * len(near)
    assert 1 not in fit.sides[len(near):]
    assert abs(fit.e) < 0.03 and fit.k > 0


# a frame of gym-duckietown's small_loop (seed 2, domain rand) 0.4 s before a tight right
# corner, as its pieces reach the fit (colour, phi, length, width, region, the summary's x and
# y [m]): the yellow centre line sweeping across the view to the right (the white line on the
# inside of the corner is out of view), and beyond it the far white edge across the view
CORNER_PIECES = [
    ('w', -1.5140, 0.1026, 0.0752, 1, (0.5252, 0.5273, 0.5289), (0.0865, 0.0521, 0.018)),
    ('w', -1.5490, 0.1014, 0.0745, 1, (0.5322, 0.5343, 0.5337), (-0.0115, -0.0446, -0.0792)),
    ('w', 1.5686, 0.0990, 0.0870, 1, (0.549, 0.5497, 0.5528), (-0.4653, -0.4326, -0.3988)),
    ('w', -1.5313, 0.0978, 0.0803, 1, (0.5475, 0.5493, 0.5475), (-0.3013, -0.3333, -0.3671)),
    ('w', 1.5517, 0.0980, 0.0919, 1, (0.5436, 0.545, 0.5466), (-0.2716, -0.2389, -0.2064)),
    ('w', -1.0207, 0.1031, 0.0681, 1, (0.4407, 0.4602, 0.475), (0.2943, 0.2672, 0.2353)),
    ('w', -1.5345, 0.0963, 0.0764, 1, (0.5414, 0.5414, 0.5426), (-0.1122, -0.1448, -0.1765)),
    ('w', -1.4309, 0.1018, 0.0547, 1, (0.4858, 0.4882, 0.4952), (0.2068, 0.1812, 0.1423)),
    ('w', -1.4190, 0.0927, 0.0505, 1, (0.5108, 0.5161, 0.5198), (0.171, 0.135, 0.1117)),
    ('w', -0.6851, 0.0795, 0.0603, 1, (0.3765, 0.3964, 0.4163), (0.3378, 0.3244, 0.3033)),
    ('w', 0.7093, 0.0568, 0.0534, 1, (0.5402, 0.5495, 0.5664), (-0.5125, -0.4965, -0.4837)),
    ('y', -0.6246, 0.0593, 0.0267, 8, (0.2318, 0.2463, 0.2634), (0.1258, 0.1158, 0.1025)),
    ('y', -1.2749, 0.0523, 0.0290, 7, (0.2872, 0.2918, 0.2968), (0.0686, 0.0522, 0.0353)),
    ('y', -1.4174, 0.0487, 0.0306, 5, (0.314, 0.3164, 0.3184), (-0.05, -0.0659, -0.0822)),
    ('y', -1.4355, 0.0390, 0.0309, 3, (0.3285, 0.3291, 0.3301), (-0.25, -0.2634, -0.2762)),
    ('y', -1.4950, 0.0381, 0.0325, 1, (0.3251, 0.325, 0.3258), (-0.137, -0.1498, -0.1625)),
    ('y', -1.4659, 0.0377, 0.0327, 2, (0.3274, 0.3275, 0.3279), (-0.1911, -0.2037, -0.2163)),
    ('y', -1.4190, 0.0350, 0.0302, 6, (0.3062, 0.3076, 0.3098), (0.0018, -0.01, -0.0212)),
]


def test_a_lane_bent_the_other_way_from_the_one_expected_is_weighed_down():
    """The lane expected bends right (-3.2 /m): the yellow line ahead bends right with it. The
    far white edge across the view, with the two nearest dashes, makes a lane turned 47
    degrees that bends left, and its long line outscores the yellow alone; weighed by how far
    its curvature lies from the one expected (within 1 / lane width: bend_belief 1), it does not."""
    names = {'w': 'white', 'y': 'yellow'}
    pieces = [Piece(np.array(x), np.array(y), phi, names[c], length, width, (names[c], region))
              for c, phi, length, width, region, x, y in CORNER_PIECES]
    prior = (0.0602, -0.3651, -3.189)  # e [m], psi [rad], k [1/m] of the lane expected
    settings = dict(anchor=(-0.0239, -0.6047), width=0.2434, spread_limit=0.1538)
    free = find_lane(pieces, DT, DT.lane_width, prior, **settings)
    assert free.k > 4.0 and free.psi < math.radians(-45)  # turned away, bent back: not it
    held = find_lane(pieces, DT, DT.lane_width, prior, expected=(prior[2], 1 / DT.lane_width),
                     **settings)
    assert held.k == pytest.approx(-3.4, abs=0.3) and math.radians(-35) < held.psi < 0
    assert set(held.sides[[c == 'y' for c, *_ in CORNER_PIECES]]) == {1}
    assert not held.sides[[c == 'w' for c, *_ in CORNER_PIECES]].any()


@pytest.mark.parametrize('count', [7, 9, 12, 40])
def test_the_bend_starts_parabola_is_the_weighted_least_squares_one(count):
    """lanefit._parabola solves the normal equations about the points' mean: the same line or
    parabola as np.polyfit's least squares (weights on the squared distances), whatever the
    points' distance ahead; points all at one distance (a singular system) still give one."""
    rng = np.random.default_rng(count)
    for far in (0.3, 1.5, 4.0):
        x = far + rng.uniform(0.0, 0.4, count)
        y = 0.1 - 0.3 * x + 0.8 * x ** 2 + rng.normal(0, 0.01, count)
        w = rng.uniform(0.1, 2.0, count)
        a, slope, k = lanefit._parabola(x, y, w)
        if count < 3 * lanefit.POINTS:
            s, b = np.polyfit(x, y, 1, w=np.sqrt(w))
            assert (a, slope, k) == pytest.approx((b, s, 0.0), rel=1e-6, abs=1e-9)
            continue
        c2, c1, c0 = np.polyfit(x, y, 2, w=np.sqrt(w))
        middle = c1 + 2 * c2 * np.average(x, weights=w)
        assert (a, slope, k) == pytest.approx(
            (c0, c1, 2 * c2 / (1 + middle ** 2) ** 1.5), rel=1e-6, abs=1e-9)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')  # np.polyfit's RankWarning
        out = lanefit._parabola(np.full(count, 0.5), np.linspace(0, 0.1, count), np.ones(count))
    assert all(np.isfinite(out))
