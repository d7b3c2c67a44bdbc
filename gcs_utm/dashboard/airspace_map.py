"""The airspace map as a grid of styled characters: a pure function of a
:class:`~gcs_utm.dashboard.airspace_scene.MapScene` and a size, so it is tested without a
terminal; :mod:`gcs_utm.dashboard.widgets` shows it in the dashboard.

What it draws, north up:

- the scene fitted into the grid with a margin: the bounding box of vehicles, plans, geofences
  and separation rings, at equal metres per cell horizontally and vertically. A terminal cell
  is about twice as tall as wide (``cell_aspect``), so a row spans ``cell_aspect`` times the
  metres of a column;
- each UAS as an arrow pointing along its course over ground (``●`` when hovering) followed by
  its label; intruders (ADS-B, Remote ID) as double arrows (``◆`` hovering), in red; the
  glyphs of the two vehicles of an active separation threat white on red;
- each operation's current plan as a faint dotted line (``·``), separation rings (``∘``)
  around the two vehicles of a threat, geofence outlines (``#``, polygons and circles) over
  them;
- on the bottom row a scale bar of a round number of metres (``├───┤ 100 m``: the distance
  between the two ticks' cells) and the north mark ``↑N``.

Positions are rounded to the nearest cell, so a position and the scale bar are good to half a
cell (``MapGrid.m_per_col`` metres across, twice that up).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

from rich.text import Text

from gcs_utm.dashboard.airspace_scene import MapScene, MapVehicle, Point

CELL_ASPECT = 2.0
"""Height of a terminal cell over its width (about 2 in common terminal fonts)."""

MIN_SPAN_M = 100.0
"""Smallest extent the map shows (a lone hovering UAS still gets a readable scale)."""

MARGIN_FRACTION = 0.08
"""Margin around the scene's bounding box, as a fraction of its larger extent."""

COURSE_ARROWS = "↑↗→↘↓↙←↖"
INTRUDER_ARROWS = "⇑⇗⇒⇘⇓⇙⇐⇖"
HOVER_GLYPH = "●"
INTRUDER_HOVER_GLYPH = "◆"
PLAN_GLYPH = "·"
FENCE_GLYPH = "#"
RING_GLYPH = "∘"
NORTH_MARK = "↑N"

STYLE_UAS = "bold cyan"
STYLE_STALE = "dim cyan"
STYLE_INTRUDER = "bold red"
STYLE_PLAN = "dim"
STYLE_FENCE = "yellow"
STYLE_RING = "red"
STYLE_THREAT = "bold white on red"
STYLE_SCALE = "bold"


@dataclass(frozen=True, slots=True)
class Cell:
    char: str = " "
    style: str = ""


@dataclass(slots=True)
class MapGrid:
    """``height`` rows of ``width`` cells; row 0 is the top (north)."""

    width: int
    height: int
    m_per_col: float
    """Metres east-west per column; a row spans ``m_per_col * cell_aspect`` metres."""
    m_per_row: float
    scale_m: float
    """Length of the scale bar in metres (0: no bar)."""
    rows: list[list[Cell]] = field(default_factory=list)

    def line(self, row: int) -> str:
        return "".join(c.char for c in self.rows[row])

    def plain(self) -> str:
        return "\n".join(self.line(r) for r in range(self.height))

    def find(self, text: str) -> tuple[int, int] | None:
        """(row, column) of the first occurrence of ``text``, None if it is not drawn."""
        for r in range(self.height):
            col = self.line(r).find(text)
            if col >= 0:
                return r, col
        return None

    def to_text(self) -> Text:
        """The grid as rich text, consecutive cells of one style in one span."""
        out = Text(no_wrap=True, overflow="crop")
        for r, row in enumerate(self.rows):
            run, style = "", row[0].style if row else ""
            for cell in row:
                if cell.style != style:
                    out.append(run, style=style or None)
                    run, style = "", cell.style
                run += cell.char
            out.append(run, style=style or None)
            if r < self.height - 1:
                out.append("\n")
        return out


class _Canvas:
    """Cells with a fit from metres to (row, column); ``solid`` cells (vehicles and labels)
    are never overwritten."""

    def __init__(self, width: int, height: int, fit: _Fit) -> None:
        self.width, self.height, self.fit = width, height, fit
        blank = Cell()  # cells are immutable: one blank shared by all
        self.cells = [[blank] * width for _ in range(height)]
        self.solid: set[tuple[int, int]] = set()

    def inside(self, r: int, c: int) -> bool:
        return 0 <= r < self.fit.rows and 0 <= c < self.width

    def put(self, r: int, c: int, char: str, style: str, *, solid: bool = False) -> None:
        if self.inside(r, c) and (r, c) not in self.solid:
            self.cells[r][c] = Cell(char, style)
            if solid:
                self.solid.add((r, c))

    def stroke(self, cells: Iterable[tuple[int, int]], char: str, style: str) -> None:
        """``char`` in every cell of ``cells`` on the map that is not solid (one Cell shared:
        a plan across the map is hundreds of cells, drawn at every refresh)."""
        mark, rows, width, grid, solid = (
            Cell(char, style),
            self.fit.rows,
            self.width,
            self.cells,
            self.solid,
        )
        for r, c in cells:
            if 0 <= r < rows and 0 <= c < width and (r, c) not in solid:
                grid[r][c] = mark


def _round(x: float) -> int:
    """Nearest integer, halves up (round() goes to even: 2.5 -> 2 but 3.5 -> 4, uneven steps)."""
    return math.floor(x + 0.5)


@dataclass(frozen=True, slots=True)
class _Fit:
    """Metres -> cells: the scene's centre at the middle of the ``rows`` x ``width`` map area."""

    width: int
    rows: int
    east_c_m: float
    north_c_m: float
    m_per_col: float
    m_per_row: float

    def cell(self, p: Point) -> tuple[int, int]:
        col = _round((self.width - 1) / 2.0 + (p[0] - self.east_c_m) / self.m_per_col)
        row = _round((self.rows - 1) / 2.0 - (p[1] - self.north_c_m) / self.m_per_row)
        return row, col

    def segment(self, a: Point, b: Point) -> list[tuple[int, int]]:
        """The cells of the straight line from ``a`` to ``b`` (every cell it crosses)."""
        (r0, c0), (r1, c1) = self.cell(a), self.cell(b)
        n = max(abs(r1 - r0), abs(c1 - c0), 1)
        dr, dc = (r1 - r0) / n, (c1 - c0) / n
        floor = math.floor
        return [(floor(r0 + dr * i + 0.5), floor(c0 + dc * i + 0.5)) for i in range(n + 1)]

    def circle(self, center: Point, radius_m: float) -> list[tuple[int, int]]:
        """The cells of a circle, sampled every half column of arc or finer (no gaps), the
        four extreme points (north, east, south, west) among the samples."""
        n = 4 * max(4, math.ceil(2.0 * math.pi * radius_m / (self.m_per_col * 0.5) / 4))
        pts = [
            (
                center[0] + radius_m * math.cos(2 * math.pi * i / n),
                center[1] + radius_m * math.sin(2 * math.pi * i / n),
            )
            for i in range(n)
        ]
        return list(dict.fromkeys(self.cell(p) for p in pts))


@dataclass(frozen=True, slots=True)
class _Extent:
    """The scene's bounding box centre and its extent with the margin, in metres."""

    east_c_m: float
    north_c_m: float
    span_e_m: float
    span_n_m: float


def _extent(scene: MapScene, cell_aspect: float) -> _Extent:
    pts = scene.points() or [(0.0, 0.0)]
    e_lo, e_hi = min(p[0] for p in pts), max(p[0] for p in pts)
    n_lo, n_hi = min(p[1] for p in pts), max(p[1] for p in pts)
    pad_m = MARGIN_FRACTION * max(e_hi - e_lo, n_hi - n_lo)
    return _Extent(
        east_c_m=(e_lo + e_hi) / 2.0,
        north_c_m=(n_lo + n_hi) / 2.0,
        span_e_m=max(e_hi - e_lo + 2 * pad_m, MIN_SPAN_M),
        span_n_m=max(n_hi - n_lo + 2 * pad_m, MIN_SPAN_M / cell_aspect),
    )


def fit_scene(scene: MapScene, width: int, rows: int, cell_aspect: float = CELL_ASPECT) -> _Fit:
    """The largest scale at which the scene's bounding box, with its margin, fits ``rows`` x
    ``width`` cells (one empty column each side for labels at the edge)."""
    ext = _extent(scene, cell_aspect)
    cols_between = max(1, width - 3)  # one margin column each side
    rows_between = max(1, rows - 1)
    m_per_col = max(ext.span_e_m / cols_between, ext.span_n_m / (rows_between * cell_aspect))
    return _Fit(
        width=width,
        rows=rows,
        east_c_m=ext.east_c_m,
        north_c_m=ext.north_c_m,
        m_per_col=m_per_col,
        m_per_row=m_per_col * cell_aspect,
    )


def rows_to_fit(scene: MapScene, width: int, cell_aspect: float = CELL_ASPECT) -> int:
    """The rows (bottom row included) a map ``width`` cells wide needs to show ``scene`` at
    the scale its east-west extent sets: a flat scene needs few rows, a tall one many (the
    widget caps them; the map then fits the rows it gets)."""
    ext = _extent(scene, cell_aspect)
    m_per_col = ext.span_e_m / max(1, width - 3)
    return math.ceil(ext.span_n_m / (m_per_col * cell_aspect) - 1e-9) + 2


def scale_bar_m(m_per_col: float, max_cols: int) -> float:
    """The longest round length (1, 2 or 5 x 10^k m) whose bar spans at most ``max_cols``
    columns (and at least one)."""
    best = 0.0
    k = math.floor(math.log10(max(m_per_col, 1e-9)))
    for exp in range(k - 1, k + 8):
        for mant in (1.0, 2.0, 5.0):
            length_m = mant * 10.0**exp
            cols = _round(length_m / m_per_col)
            if 1 <= cols <= max_cols:
                best = max(best, length_m)
    return best


def _metres(length_m: float) -> str:
    if length_m >= 1000.0:
        return f"{length_m / 1000.0:g} km"
    return f"{length_m:g} m"


def glyph(v: MapVehicle) -> str:
    """A vehicle's glyph: the arrow of its course in 45-degree sectors, or the hover mark."""
    if v.course_deg is None:
        return INTRUDER_HOVER_GLYPH if v.intruder else HOVER_GLYPH
    arrows = INTRUDER_ARROWS if v.intruder else COURSE_ARROWS
    return arrows[int(((v.course_deg % 360.0) + 22.5) // 45.0) % 8]


def _vehicle_style(v: MapVehicle) -> str:
    if v.intruder:
        return STYLE_INTRUDER
    return STYLE_STALE if v.stale else STYLE_UAS


def _place_label(canvas: _Canvas, r: int, c: int, label: str, style: str) -> None:
    """The label next to its glyph at (r, c): right of it, else left, else on the row above
    or below, wherever it fits whole without covering another vehicle or label."""
    n = len(label)
    for r0, c0 in ((r, c + 1), (r, c - n), (r - 1, c - n // 2), (r + 1, c - n // 2)):
        spots = [(r0, c0 + i) for i in range(n)]
        if all(canvas.inside(*s) and s not in canvas.solid for s in spots):
            for i, ch in enumerate(label):
                canvas.put(r0, c0 + i, ch, style, solid=True)
            return
    for i, ch in enumerate(label):  # crowded: right of the glyph, cropped at the edge
        canvas.put(r, c + 1 + i, ch, style, solid=True)


def _bottom_row(canvas: _Canvas, fit: _Fit) -> float:
    """Scale bar at the left of the bottom row, north mark at its right; the bar's metres."""
    row = canvas.height - 1
    north_at = canvas.width - len(NORTH_MARK)
    bar_m = scale_bar_m(fit.m_per_col, max(1, min(canvas.width // 3, north_at - 8)))
    text = ""
    if bar_m > 0:
        cols = _round(bar_m / fit.m_per_col)
        text = "├" + "─" * (cols - 1) + "┤ " + _metres(bar_m)
    for i, ch in enumerate(text[: max(0, north_at - 1)]):
        canvas.cells[row][i] = Cell(ch, STYLE_SCALE)
    for i, ch in enumerate(NORTH_MARK):
        if north_at + i >= 0:
            canvas.cells[row][north_at + i] = Cell(ch, STYLE_SCALE)
    return bar_m


def render_map(
    scene: MapScene, width: int, height: int, *, cell_aspect: float = CELL_ASPECT
) -> MapGrid:
    """The map of ``scene`` in ``height`` rows of ``width`` cells (module docstring); the
    bottom row holds the scale bar and the north mark."""
    width, height = max(1, width), max(2, height)
    fit = fit_scene(scene, width, height - 1, cell_aspect)
    canvas = _Canvas(width, height, fit)
    for plan in scene.plans:
        for a, b in zip(plan.points, plan.points[1:], strict=False):
            canvas.stroke(fit.segment(a, b), PLAN_GLYPH, STYLE_PLAN)
        canvas.stroke((fit.cell(p) for p in plan.points[:1]), PLAN_GLYPH, STYLE_PLAN)
    for sep in scene.rings:
        canvas.stroke(fit.circle(sep.center, sep.radius_m), RING_GLYPH, STYLE_RING)
    for fence in scene.fences:  # over the rings: a jamming geofence is often centred on a UAS
        if fence.center is not None:
            canvas.stroke(fit.circle(fence.center, fence.radius_m), FENCE_GLYPH, STYLE_FENCE)
        ring = list(fence.vertices)
        for a, b in zip(ring, ring[1:] + ring[:1], strict=False):
            canvas.stroke(fit.segment(a, b), FENCE_GLYPH, STYLE_FENCE)
    at = [fit.cell((v.east_m, v.north_m)) for v in scene.vehicles]
    for v, (r, c) in zip(scene.vehicles, at, strict=True):
        canvas.put(r, c, glyph(v), STYLE_THREAT if v.in_threat else _vehicle_style(v), solid=True)
    for v, (r, c) in zip(scene.vehicles, at, strict=True):
        if canvas.inside(r, c):
            _place_label(canvas, r, c, v.label, _vehicle_style(v).replace("bold ", ""))
    if not scene.points():
        msg = "(empty airspace)"[:width]
        for i, ch in enumerate(msg):
            canvas.cells[(height - 1) // 2][(width - len(msg)) // 2 + i] = Cell(ch, "dim")
    bar_m = _bottom_row(canvas, fit)
    return MapGrid(
        width=width,
        height=height,
        m_per_col=fit.m_per_col,
        m_per_row=fit.m_per_row,
        scale_m=bar_m,
        rows=canvas.cells,
    )


def map_legend(scene: MapScene, width: int | None = None) -> Text:
    """What the marks on the map mean (only those drawn; the rings with their radius), as
    ``mark=meaning`` entries broken into lines of ``width`` cells between entries only."""
    marks = [(COURSE_ARROWS[0], STYLE_UAS, "UAS")]
    if any(v.intruder for v in scene.vehicles):
        marks.append((INTRUDER_ARROWS[0], STYLE_INTRUDER, "intruder"))
    if scene.plans:
        marks.append((PLAN_GLYPH, STYLE_PLAN, "plan"))
    if scene.fences:
        marks.append((FENCE_GLYPH, STYLE_FENCE, "geofence"))
    radii = sorted({r.radius_m for r in scene.rings})
    if radii:
        marks.append(
            (RING_GLYPH, STYLE_RING, "separation " + "/".join(f"{r:.0f}" for r in radii) + " m")
        )
    out = Text(no_wrap=True, overflow="ellipsis")
    used = 0
    for mark, style, meaning in marks:
        n = len(mark) + 1 + len(meaning)
        if used and width is not None and used + 1 + n > width:
            out.append("\n")
            used = 0
        elif used:
            out.append(" ")
            used += 1
        out.append(mark, style=style)
        out.append("=" + meaning)
        used += n
    return out
