"""A speed-up of kobuki_lane.detect(): the same segments, frame by frame, in a third of the time.

detect() runs the slides' calls on the whole frame, and cv2.undistort rebuilds its maps on
every call. FastPipeline does only the work that can change a segment: the undistortion maps
are made once; only the part of the frame near the mask is undistorted (from a BGRA copy:
remap is faster on 4 channels), and gray, blur and Canny run on two rectangles that hold the
mask's rows plus the few pixels their edges depend on (Layout._pieces). Hough still gets a
full-size image, zero off the mask, so its accumulator is the one the lecture's call builds.
tests/test_pipeline.py checks the segments are identical to detect()'s; tools/bench.py
measures the gain.

What it cannot speed up it hands to detect() (its `reference`): pictures of every stage, and
Canny with canny_low != canny_high, whose hysteresis can link weak edges from far away.
"""

import cv2
import numpy as np

from lanelib.camera import undistortion_maps
from lanelib.stages import (
    Detection,
    as_bgr,
    hough_lines,
    region_of_interest,
    region_of_interest_vertices,
    slope_sum,
)


class Layout:
    """What stays the same from frame to frame for one frame size, camera and mask: the
    undistortion maps (cv2.undistort rebuilds them on every call), the mask, the part of the
    frame it reaches and the buffers."""

    STRIPS = 8  # the band is undistorted in this many strips, each only as wide as the mask
    # needs there (tools/bench.py: more strips cost more in calls than they save in pixels)

    def __init__(self, width, height, camera, p):
        self.key = (width, height, p.algorithm, p.blur_kernel)
        self.camera = camera
        self.maps = None
        if camera is not None:
            self.maps = undistortion_maps(camera, width, height)
        if p.algorithm == '1.1':  # the lecture's function applied to an all-kept image
            self.mask = region_of_interest(np.full((height, width), 255, np.uint8),
                                           region_of_interest_vertices(width, height))
        else:
            self.mask = None
        rows = (np.flatnonzero(self.mask.any(axis=1)) if self.mask is not None
                else np.arange(height))
        self.top, self.bottom = (int(rows[0]), int(rows[-1]) + 1) if rows.size else (0, 0)
        # an edge pixel depends on the blurred pixels 2 px away (Sobel, then non-maximum
        # suppression) and those on the gray ones blur_kernel // 2 px away
        self.margin = p.blur_kernel // 2 + 3
        self.first = max(self.top - self.margin, 0)
        self.last = min(self.bottom + self.margin, height)
        if self.mask is None:  # algorithm 1.0: every pixel, in one piece
            self.strips = [(0, height, 0, width)] if height and width else []
            self.pieces = [((0, height, 0, width),) * 3] if height and width else []
        else:
            self.strips = self._strips(width, height)
            self.pieces = self._pieces(width, height)
        # remap is about a third faster on 4 channels than on 3, and each channel comes out the
        # same, so the strips are undistorted from a BGRA copy of the part of the frame they
        # read (tools/bench.py: 0.26 against 0.36 ms, the copy included)
        self.band = self.source = self.bgra = None
        if self.maps is not None:
            self.band = np.zeros((self.last - self.first, width, 4), np.uint8)
            self.source = self._source(width, height)
            self.bgra = np.zeros((height, width, 4), np.uint8)
        self.edges = np.zeros((height, width), np.uint8)  # Hough's input; zero off the band

    def _strips(self, width, height):
        """(first row, last row, first column, last column) of each strip of the band."""
        bounds = np.linspace(self.first, self.last, self.STRIPS + 1).astype(int)
        strips = []
        for a, b in zip(bounds[:-1], bounds[1:]):
            near = self.mask[max(a - self.margin, 0):min(b + self.margin, height)]
            cols = np.flatnonzero(near.any(axis=0))
            if b > a and cols.size:
                strips.append((int(a), int(b), max(int(cols[0]) - self.margin, 0),
                               min(int(cols[-1]) + 1 + self.margin, width)))
        return strips

    def _source(self, width, height):
        """Rows and columns of the frame the strips' bilinear interpolation reads."""
        m1 = self.maps[0]
        xy = [m1[a:b, x0:x1].reshape(-1, 2) for a, b, x0, x1 in self.strips]
        if not xy:
            return 0, 0, 0, 0
        xy = np.concatenate(xy)
        (x0, y0), (x1, y1) = xy.min(axis=0), xy.max(axis=0) + 2  # the pixel and the next
        return (int(np.clip(y0, 0, height)), int(np.clip(y1, 0, height)),
                int(np.clip(x0, 0, width)), int(np.clip(x1, 0, width)))

    def _pieces(self, width, height):
        """The band's rows split in two where that leaves the fewest pixels to gray, blur and
        edge (for the triangle, where it is half as wide as at the bottom). Per piece: rows a:b
        and columns c0:c1 the mask reaches; the rectangle grayed and blurred (the margin round
        it); the rectangle edged (3 px round it: an edge depends on the blurred pixels 2 px
        away). Each rectangle is its own image to OpenCV, so its border only touches pixels
        outside the part that is kept. tools/bench.py: the split saves about 4 % of the frame's
        time, a third piece nothing more."""
        m = self.margin
        kept = self.mask.any(axis=1)
        lo = np.where(kept, (self.mask != 0).argmax(axis=1), width)  # first and last column
        hi = np.where(kept, width - (self.mask[:, ::-1] != 0).argmax(axis=1), 0)  # kept + 1

        def piece(a, b):
            c0, c1 = int(lo[a:b].min(initial=width)), int(hi[a:b].max(initial=0))
            if c1 <= c0:
                return None
            gray = (max(a - m, 0), min(b + m, height), max(c0 - m, 0), min(c1 + m, width))
            edge = (max(a - 3, gray[0]), min(b + 3, gray[1]), max(c0 - 3, gray[2]),
                    min(c1 + 3, gray[3]))
            return (a, b, c0, c1), gray, edge

        def area(pieces):
            return sum((g1 - g0) * (gc1 - gc0) for _, (g0, g1, gc0, gc1), _ in pieces)

        best = [q for q in [piece(self.top, self.bottom)] if q]
        for at in range(self.top + 1, self.bottom):
            two = [q for q in (piece(self.top, at), piece(at, self.bottom)) if q]
            if area(two) < area(best):
                best = two
        return best

    def matches(self, width, height, camera, p):
        return (self.key == (width, height, p.algorithm, p.blur_kernel)
                and self.camera is camera)

    def undistort(self, raw):
        """The whole undistorted frame."""
        if self.maps is None:
            return raw
        return cv2.remap(raw, *self.maps, cv2.INTER_LINEAR)

    def undistort_band(self, raw):
        """Rows first:last of the undistorted frame, as BGRA, right wherever the mask's edges
        can depend on them (elsewhere whatever an earlier frame left)."""
        if self.maps is None:
            return raw[self.first:self.last]
        m1, m2 = self.maps
        y0, y1, x0, x1 = self.source
        cv2.cvtColor(raw[y0:y1, x0:x1], cv2.COLOR_BGR2BGRA, dst=self.bgra[y0:y1, x0:x1])
        for a, b, x0, x1 in self.strips:
            cv2.remap(self.bgra, m1[a:b, x0:x1], m2[a:b, x0:x1], cv2.INTER_LINEAR,
                      dst=self.band[a - self.first:b - self.first, x0:x1])
        return self.band


class FastPipeline:
    """detect(frame, camera, p, keep_stages), doing only the work that can change a
    segment (see the module's docstring).

    reference: kobuki_lane.detect, for what the band cannot do. mark: called after each stage
    (tools/bench.py times them).
    """

    def __init__(self, p, reference, mark=None):
        self.p = p
        self.reference = reference
        self.mark = mark or (lambda stage: None)
        self._layout = None

    def layout(self, width, height, camera):
        if self._layout is None or not self._layout.matches(width, height, camera, self.p):
            self._layout = Layout(width, height, camera, self.p)
        return self._layout

    def __call__(self, frame, camera, keep_stages=False):
        p, mark = self.p, self.mark
        if keep_stages or p.canny_low != p.canny_high:
            return self.reference(frame, camera, p, keep_stages)
        mark('start')
        raw = as_bgr(frame)
        height, width = raw.shape[:2]
        lay = self.layout(width, height, camera)
        if lay.top == lay.bottom:  # the mask keeps nothing: no segment can be found
            return self.reference(frame, camera, p, False)
        band = lay.undistort_band(raw)
        mark('undistort')
        lines = hough_lines(self.band_edges(band, lay), p)
        mark('hough')
        slopes = slope_sum(lines, p.slope_min)
        mark('slopes')
        return Detection(lines, slopes, make_image=lambda: lay.undistort(raw))

    def band_edges(self, band, lay):
        """The stages piece by piece (Layout._pieces) on rows lay.first:lay.last: Hough's
        full-size input, the mask's edges and zero elsewhere."""
        p, mark, first = self.p, self.mark, lay.first
        to_gray = cv2.COLOR_BGRA2GRAY if band.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        grays = [cv2.cvtColor(band[g0 - first:g1 - first, gc0:gc1], to_gray)
                 for _, (g0, g1, gc0, gc1), _ in lay.pieces]
        mark('gray')
        blurred = [cv2.GaussianBlur(gray, (p.blur_kernel, p.blur_kernel), 0) for gray in grays]
        mark('blur')
        edged = [cv2.Canny(b[e0 - g0:e1 - g0, ec0 - gc0:ec1 - gc0], p.canny_low, p.canny_high)
                 for b, (_, (g0, _, gc0, _), (e0, e1, ec0, ec1)) in zip(blurred, lay.pieces)]
        mark('canny')
        if lay.mask is None:
            mark('roi')
            return edged[0]
        for e, ((a, b, c0, c1), _, (e0, _, ec0, _)) in zip(edged, lay.pieces):
            cv2.bitwise_and(e[a - e0:b - e0, c0 - ec0:c1 - ec0], lay.mask[a:b, c0:c1],
                            dst=lay.edges[a:b, c0:c1])
        mark('roi')
        return lay.edges
