# Copyright 2026 epp_ros developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
The boom as text: a side view and a top view of the estimated and the true posture.

Plain functions of postures and a canvas size, with no terminal and no ROS: :func:`draw`
returns a :class:`Drawing` (rows of characters and a style per cell) that ``epp_demo``
shows with ``rich`` (:func:`to_rich`) and the tests read as text.

Side view: the horizontal reach from the slew axis (signed, in each boom's own vertical
plane) against the height, with the ground. Top view: the boom seen from above, the slew
axis at the centre, with the anchors and the tag-anchor links the estimator judged NLOS
(their joints red in both views). Terminal cells are about twice as tall as wide, which
both views respect, so that a metre is as long across as up.
"""
from dataclasses import dataclass
import math

import numpy as np

__all__ = ['GLYPHS', 'STYLES', 'Canvas', 'Drawing', 'side_view', 'top_view', 'draw',
           'to_rich', 'CELL_ASPECT', 'MAGNIFY', 'SIGMAS']

#: Height of a terminal cell over its width.
CELL_ASPECT = 2.0
#: The uncertainty drawn around a joint: a disc of SIGMAS predicted standard deviations,
#: magnified MAGNIFY times (a 0.1 m standard deviation is a fraction of a cell otherwise).
SIGMAS = 1.0
MAGNIFY = 10.0

#: What each part is drawn with.
GLYPHS = {'truth_line': '·', 'truth_joint': 'o', 'tip': '@', 'pivot': 'B',
          'uncertainty': '░', 'ground': '=', 'mast': '|', 'axis': '+', 'anchor': '^',
          'nlos': 'x'}
#: The style of each part (rich style names).
STYLES = {'truth': 'bright_black', 'estimate': 'bold cyan', 'tip': 'bold yellow',
          'uncertainty': 'magenta', 'ground': 'green', 'title': 'bold', 'axis': 'green',
          'anchor': 'bold blue', 'nlos': 'bold red'}

# A segment's glyph by its direction on screen (degrees, 0 = to the right, 90 = up).
_SLOPES = ((22.5, '-'), (67.5, '/'), (112.5, '|'), (157.5, '\\'), (180.0, '-'))


@dataclass
class Drawing:
    """Rows of characters of equal length and, per cell, a style name or None."""

    rows: list
    styles: list

    @property
    def text(self):
        """Return the drawing as one string, rows separated by newlines."""
        return '\n'.join(self.rows)

    def find(self, glyph):
        """Return the (row, column) cells holding ``glyph``."""
        return [(r, c) for r, row in enumerate(self.rows)
                for c, character in enumerate(row) if character == glyph]


class Canvas:
    """
    A grid of cells over a rectangle of the world: x to the right, y up, in metres.

    The limits are widened (about their centre) so that a metre spans the same length
    across and up, with cells ``aspect`` times as tall as wide.
    """

    def __init__(self, width, height, xlim, ylim, aspect=CELL_ASPECT):
        self.width, self.height = int(width), int(height)
        if self.width < 1 or self.height < 1:
            raise ValueError(f'a canvas needs cells, got {width} x {height}')
        (x0, x1), (y0, y1) = sorted(map(float, xlim)), sorted(map(float, ylim))
        self.dx = max((x1 - x0) / self.width, (y1 - y0) / (aspect * self.height), 1e-9)
        self.dy = aspect * self.dx
        centre_x, centre_y = (x0 + x1) / 2, (y0 + y1) / 2
        self.x0 = centre_x - self.dx * self.width / 2
        self.y1 = centre_y + self.dy * self.height / 2
        self.cells = [[' '] * self.width for _ in range(self.height)]
        self.styles = [[None] * self.width for _ in range(self.height)]

    def cell(self, x, y):
        """Return the (row, column) of the world point, or None when off the canvas."""
        if not (math.isfinite(x) and math.isfinite(y)):
            return None
        column = math.floor((x - self.x0) / self.dx)
        row = math.floor((self.y1 - y) / self.dy)
        if 0 <= row < self.height and 0 <= column < self.width:
            return row, column
        return None

    def centre(self, row, column):
        """Return the world point at the centre of a cell."""
        return self.x0 + (column + 0.5) * self.dx, self.y1 - (row + 0.5) * self.dy

    def restyle(self, x, y, style):
        """Give the cell at the world point ``style``, keeping its glyph."""
        where = self.cell(x, y)
        if where is not None:
            self.styles[where[0]][where[1]] = style

    def put(self, x, y, glyph, style=None):
        """Draw ``glyph`` at the world point, if it is on the canvas."""
        where = self.cell(x, y)
        if where is not None:
            self.cells[where[0]][where[1]] = glyph
            self.styles[where[0]][where[1]] = style

    def line(self, a, b, glyph=None, style=None):
        """Draw the segment a-b; ``glyph`` None: a dash, slash, bar or backslash by its slope."""
        (xa, ya), (xb, yb) = a, b
        if not all(math.isfinite(v) for v in (xa, ya, xb, yb)):
            return
        if glyph is None:
            angle = math.degrees(math.atan2((yb - ya) / self.dy, (xb - xa) / self.dx)) % 180
            glyph = next(g for limit, g in _SLOPES if angle < limit)
        steps = 2 * int(max(abs(xb - xa) / self.dx, abs(yb - ya) / self.dy)) + 2
        for t in np.linspace(0.0, 1.0, steps):
            self.put(xa + t * (xb - xa), ya + t * (yb - ya), glyph, style)

    def disc(self, centre, radius, glyph, style=None):
        """Fill the cells whose centres lie within ``radius`` metres of ``centre``."""
        x, y = centre
        if not (math.isfinite(radius) and radius > 0 and math.isfinite(x)
                and math.isfinite(y)):
            return
        rows = range(max(math.floor((self.y1 - y - radius) / self.dy), 0),
                     min(math.floor((self.y1 - y + radius) / self.dy) + 1, self.height))
        columns = range(max(math.floor((x - radius - self.x0) / self.dx), 0),
                        min(math.floor((x + radius - self.x0) / self.dx) + 1, self.width))
        for row in rows:
            for column in columns:
                cx, cy = self.centre(row, column)
                if (cx - x) ** 2 + (cy - y) ** 2 <= radius ** 2:
                    self.cells[row][column] = glyph
                    self.styles[row][column] = style

    def hline(self, y, glyph, style=None):
        """Fill the row holding height ``y``."""
        where = self.cell(self.x0 + self.dx / 2, y)
        if where is not None:
            self.cells[where[0]] = [glyph] * self.width
            self.styles[where[0]] = [style] * self.width

    def title(self, text, style=STYLES['title']):
        """Write ``text`` at the top left, over whatever is there."""
        for column, character in enumerate(text[:self.width]):
            self.cells[0][column] = character
            self.styles[0][column] = style

    def drawing(self):
        """Return what was drawn as a :class:`Drawing`."""
        return Drawing([''.join(row) for row in self.cells], [list(s) for s in self.styles])


def _points(posture):
    points = np.asarray(posture, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2:
        raise ValueError(f'a posture is the base and joints, shape (p + 1, 3), got '
                         f'{points.shape}')
    return points


def _anchors(anchors):
    stations = np.asarray(anchors, dtype=float)
    if stations.ndim != 2 or stations.shape[1] not in (2, 3):
        raise ValueError(f'anchors are (m, 2) or (m, 3) positions, got {stations.shape}')
    return stations


def _reach(points, axis):
    """Signed reach from the slew axis in the boom's own vertical plane, and heights."""
    horizontal = points[:, :2] - np.asarray(axis, dtype=float)
    distances = np.linalg.norm(horizontal, axis=1)
    farthest = int(np.argmax(distances))
    direction = (horizontal[farthest] / distances[farthest] if distances[farthest] > 1e-9
                 else np.array([1.0, 0.0]))
    return np.column_stack([horizontal @ direction, points[:, 2]])


def _flagged(nlos, estimate, anchors=None):
    """
    Return the (joint, anchor) pairs of ``nlos`` (1-based) that name a drawn joint and anchor.

    ``anchors`` None: only the joint is checked.
    """
    if estimate is None:
        return []
    joints = len(estimate) - 1
    return [(int(k), int(j)) for k, j in nlos if 1 <= k <= joints
            and (anchors is None or 1 <= j <= len(anchors))]


def _draw_boom(canvas, estimate, truth, stds, magnify, nlos=(), under=None):
    """
    Uncertainty under the truth under ``under(canvas)`` under the estimate.

    Each posture is (p + 1, 2) points; the joints of ``nlos`` (joint, anchor) pairs are
    coloured as NLOS.
    """
    if stds is not None and estimate is not None:
        for joint, std in zip(estimate[1:], np.asarray(stds, dtype=float)):
            canvas.disc(joint, SIGMAS * magnify * std, GLYPHS['uncertainty'],
                        STYLES['uncertainty'])
    if truth is not None:
        for a, b in zip(truth[:-1], truth[1:]):
            canvas.line(a, b, GLYPHS['truth_line'], STYLES['truth'])
        for joint in truth[1:]:
            canvas.put(*joint, GLYPHS['truth_joint'], STYLES['truth'])
    if under is not None:
        under(canvas)
    if estimate is not None:
        for a, b in zip(estimate[:-1], estimate[1:]):
            canvas.line(a, b, None, STYLES['estimate'])
        for k, joint in enumerate(estimate[1:-1], start=1):
            canvas.put(*joint, str(k % 10), STYLES['estimate'])
        canvas.put(*estimate[0], GLYPHS['pivot'], STYLES['estimate'])
        canvas.put(*estimate[-1], GLYPHS['tip'], STYLES['tip'])
    for joint, _ in _flagged(nlos, estimate):
        canvas.restyle(*estimate[joint], STYLES['nlos'])


def _span(estimate, truth, axis):
    """Return the farthest any point is from the slew axis, and the highest, metres."""
    points = np.vstack([p for p in (estimate, truth) if p is not None])
    finite = points[np.all(np.isfinite(points), axis=1)]
    if not len(finite):
        return 1.0, 1.0
    reach = np.linalg.norm(finite[:, :2] - np.asarray(axis, dtype=float), axis=1).max()
    return max(float(reach), 1.0), max(float(finite[:, 2].max()), 1.0)


def side_view(estimate, truth=None, stds=None, width=60, height=20, axis=None,
              span=None, top=None, magnify=MAGNIFY, nlos=()):
    """
    Draw the reach from the slew axis against the height, with the ground.

    Parameters
    ----------
    estimate : array_like, shape (p + 1, 3) or None
        The estimated base pivot and joints 1..p, metres (``contract.points_of``).
    truth : array_like, shape (p + 1, 3), optional
        The true posture, drawn under the estimate.
    stds : array_like, shape (p,), optional
        Each joint's predicted standard deviation, metres: a disc of :data:`SIGMAS` of
        them, magnified ``magnify`` times, is drawn around the estimated joint.
    width, height : int
        Canvas size in cells.
    axis : array_like, shape (2,), optional
        The slew axis (x, y), metres; default the estimate's (or truth's) base.
    span, top : float, optional
        The farthest reach and the greatest height to show, metres (default: of the
        postures); fixed values keep the picture still while the boom moves.
    magnify : float
        How much larger than life the uncertainty is drawn.
    nlos : sequence of (int, int), optional
        The tag-anchor links the estimator judged NLOS, (joint, anchor), 1-based (the
        ``NLOS flagged links`` of ``/diagnostics``): their estimated joints are coloured.

    Returns
    -------
    Drawing

    """
    estimate, truth, first, axis = _booms(estimate, truth, axis)
    reach, highest = _span(estimate, truth, axis)
    span, top = span or reach, top or highest
    canvas = Canvas(width, height, (-0.2 * span, 1.05 * span), (-0.08 * top, 1.05 * top))
    canvas.hline(0.0, GLYPHS['ground'], STYLES['ground'])
    base = first[0]
    canvas.line((0.0, 0.0), (0.0, base[2]), GLYPHS['mast'], STYLES['axis'])
    _draw_boom(canvas, None if estimate is None else _reach(estimate, axis),
               None if truth is None else _reach(truth, axis), stds, magnify, nlos)
    canvas.title('side: reach / height')
    return canvas.drawing()


def _booms(estimate, truth, axis):
    """Return the estimate and truth as points (or None), the one drawn first, the axis."""
    estimate = None if estimate is None else _points(estimate)
    truth = None if truth is None else _points(truth)
    first = estimate if estimate is not None else truth
    axis = first[0, :2] if axis is None else np.asarray(axis, dtype=float)
    return estimate, truth, first, axis


def top_view(estimate, truth=None, stds=None, width=40, height=20, axis=None, span=None,
             magnify=MAGNIFY, anchors=None, nlos=()):
    """
    Draw the boom from above (the slew), the slew axis at the centre, and the anchors.

    ``anchors``, array_like of shape (m, 2) or (m, 3), are the anchor positions in metres
    (only x, y are drawn; anchor j of ``nlos`` is row j - 1). Each link of ``nlos`` is
    drawn from its estimated joint to its anchor, under the boom, and its joint and anchor
    are coloured. The other parameters are those of :func:`side_view`; x to the right, y
    up.

    Returns
    -------
    Drawing

    """
    estimate, truth, _, axis = _booms(estimate, truth, axis)
    span = span or _span(estimate, truth, axis)[0]
    canvas = Canvas(width, height, (-1.05 * span, 1.05 * span), (-1.05 * span, 1.05 * span))
    canvas.put(0.0, 0.0, GLYPHS['axis'], STYLES['axis'])

    def plan(points):
        return None if points is None else points[:, :2] - axis
    estimated = plan(estimate)
    stations = None if anchors is None else plan(_anchors(anchors))
    flagged = _flagged(nlos, estimated, stations)

    def links_and_anchors(canvas):
        for joint, anchor in flagged if stations is not None else ():
            canvas.line(estimated[joint], stations[anchor - 1], GLYPHS['nlos'],
                        STYLES['nlos'])
        blocked = {anchor for _, anchor in flagged}
        for j, station in enumerate(() if stations is None else stations, start=1):
            canvas.put(*station, GLYPHS['anchor'],
                       STYLES['nlos'] if j in blocked else STYLES['anchor'])
    _draw_boom(canvas, estimated, plan(truth), stds, magnify, flagged, links_and_anchors)
    canvas.title('top: slew')
    return canvas.drawing()


def draw(estimate, truth=None, stds=None, width=100, height=22, axis=None, span=None,
         top=None, magnify=MAGNIFY, gap=2, anchors=None, nlos=()):
    """
    Draw the side view and, right of it, the top view, on a ``width`` x ``height`` canvas.

    The top view takes a square of the world (as wide as twice its height in cells), at
    most 40 % of the width. Parameters are those of :func:`side_view` and
    :func:`top_view`.

    Returns
    -------
    Drawing

    """
    width, height = int(width), int(height)
    top_width = max(min(int(CELL_ASPECT * height), int(0.4 * width)), 1)
    side_width = max(width - top_width - gap, 1)
    side = side_view(estimate, truth, stds, side_width, height, axis, span, top, magnify,
                     nlos)
    plan = top_view(estimate, truth, stds, top_width, height, axis, span, magnify, anchors,
                    nlos)
    rows = [a + ' ' * gap + b for a, b in zip(side.rows, plan.rows)]
    styles = [a + [None] * gap + b for a, b in zip(side.styles, plan.styles)]
    return Drawing(rows, styles)


def to_rich(drawing):
    """Return the drawing as a ``rich.text.Text``, styles applied by runs of cells."""
    from rich.text import Text
    text = Text(no_wrap=True, overflow='crop')
    for r, (row, styles) in enumerate(zip(drawing.rows, drawing.styles)):
        if r:
            text.append('\n')
        start = 0
        for column in range(1, len(row) + 1):
            if column == len(row) or styles[column] != styles[start]:
                text.append(row[start:column], style=styles[start] or '')
                start = column
    return text
