"""A* on a lazily built visibility graph of inflated geofences (2D, local metres).

Obstacles are the clearance-inflated, merged geofence polygons of
:func:`gcs_utm.core.deconfliction.geometry.merged_obstacles`. Graph nodes are the *convex*
vertices of those polygons pushed ``NODE_EPS_M`` outward (a shortest path among polygons only
bends at convex vertices), plus start and goal. An edge exists when the straight segment
crosses no obstacle border; since both ends lie outside every obstacle, such a segment is
entirely outside, hence at least the clearance away from every geofence. The visibility of a
node is computed only when A* expands it, vectorised over all candidate nodes and all
obstacle edges at once (orientation tests), which keeps 20 geofences at a few milliseconds.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import shapely
from shapely.geometry import Point, Polygon

from gcs_utm.core.deconfliction.geometry import NODE_EPS_M
from gcs_utm.model import FloatArray

BoolArray = npt.NDArray[np.bool_]


class VisibilityPlanner:
    """Shortest obstacle-free 2D paths among fixed polygons."""

    def __init__(self, obstacles: Sequence[Polygon]) -> None:
        self.obstacles = [shapely.orient_polygons(p) for p in obstacles]
        a_list: list[FloatArray] = []
        b_list: list[FloatArray] = []
        nodes: list[FloatArray] = []
        for poly in self.obstacles:
            ring = np.asarray(poly.exterior.coords, dtype=np.float64)[:-1]
            a_list.append(ring)
            b_list.append(np.roll(ring, -1, axis=0))
            grown = poly.buffer(NODE_EPS_M, join_style="mitre", mitre_limit=2.0)
            if not isinstance(grown, Polygon):
                continue
            g = np.asarray(shapely.orient_polygons(grown).exterior.coords, dtype=np.float64)[:-1]
            prev = np.roll(g, 1, axis=0)
            nxt = np.roll(g, -1, axis=0)
            turn = (g[:, 0] - prev[:, 0]) * (nxt[:, 1] - g[:, 1]) - (g[:, 1] - prev[:, 1]) * (
                nxt[:, 0] - g[:, 0]
            )
            nodes.append(g[turn > 0.0])  # counter-clockwise ring: left turns are convex
        self._a = np.concatenate(a_list) if a_list else np.zeros((0, 2))
        self._b = np.concatenate(b_list) if b_list else np.zeros((0, 2))
        all_nodes = np.concatenate(nodes) if nodes else np.zeros((0, 2))
        if all_nodes.shape[0] and self.obstacles:
            inside = np.zeros(all_nodes.shape[0], dtype=bool)
            for poly in self.obstacles:
                inside |= shapely.contains_xy(poly, all_nodes[:, 0], all_nodes[:, 1])
            all_nodes = all_nodes[~inside]
        self._nodes = all_nodes
        self._union = shapely.union_all(self.obstacles) if self.obstacles else None
        self._rows: dict[int, BoolArray] = {}
        self._paths: dict[tuple[float, float, float, float], list[FloatArray] | None] = {}

    # ---- predicates --------------------------------------------------------------------------
    def blocked(self, p: FloatArray, qs: FloatArray) -> BoolArray:
        """For each row q of ``qs``: does the segment p->q cross an obstacle border?"""
        if self._a.shape[0] == 0:
            return np.zeros(qs.shape[0], dtype=bool)
        d = qs - p  # (K, 2)
        ap = self._a - p  # (M, 2)
        bp = self._b - p
        o1 = d[:, 0, None] * ap[None, :, 1] - d[:, 1, None] * ap[None, :, 0]
        o2 = d[:, 0, None] * bp[None, :, 1] - d[:, 1, None] * bp[None, :, 0]
        e = self._b - self._a  # (M, 2)
        o3 = e[:, 0] * (p[1] - self._a[:, 1]) - e[:, 1] * (p[0] - self._a[:, 0])  # (M,)
        qa_e = qs[:, 0, None] - self._a[None, :, 0]
        qa_n = qs[:, 1, None] - self._a[None, :, 1]
        o4 = e[None, :, 0] * qa_n - e[None, :, 1] * qa_e
        hit = (o1 * o2 <= 0.0) & (o3[None, :] * o4 <= 0.0)
        return np.asarray(hit.any(axis=1), dtype=bool)

    def free(self, p: FloatArray) -> bool:
        return self._union is None or not shapely.contains_xy(self._union, p[0], p[1])

    def segment_free(self, p: FloatArray, q: FloatArray) -> bool:
        return self.free(p) and self.free(q) and not bool(self.blocked(p, q[None, :])[0])

    def exit_point(self, p: FloatArray, extra_m: float = 0.0) -> FloatArray:
        """The closest point outside every obstacle (by ``NODE_EPS_M + extra_m``), or ``p``."""
        if self.free(p):
            return p
        assert self._union is not None
        grown = self._union.buffer(NODE_EPS_M + extra_m, join_style="mitre", mitre_limit=2.0)
        boundary = grown.boundary
        q = boundary.interpolate(boundary.project(Point(p[0], p[1])))
        out = np.array([q.x, q.y], dtype=np.float64)
        # The nearest boundary point of a union may be a hole's border; step out once more.
        if not self.free(out):
            hull = self._union.convex_hull.buffer(NODE_EPS_M + extra_m)
            hb = hull.boundary
            q = hb.interpolate(hb.project(Point(p[0], p[1])))
            out = np.array([q.x, q.y], dtype=np.float64)
        return out

    # ---- search -----------------------------------------------------------------------------
    def _node_row(self, i: int) -> BoolArray:
        """Visibility of graph node ``i`` to every graph node (cached: the obstacle graph is
        the same for every query of this planner)."""
        row = self._rows.get(i)
        if row is None:
            row = ~self.blocked(self._nodes[i], self._nodes)
            row[i] = False
            self._rows[i] = row
        return row

    def path(self, start: FloatArray, goal: FloatArray) -> list[FloatArray] | None:
        """Shortest path start..goal (both included) or None when there is none or an end is
        inside an obstacle."""
        start = np.asarray(start, dtype=np.float64)
        goal = np.asarray(goal, dtype=np.float64)
        key = (
            round(float(start[0]), 3),
            round(float(start[1]), 3),
            round(float(goal[0]), 3),
            round(float(goal[1]), 3),
        )
        if key in self._paths:
            return self._paths[key]
        result = self._search(start, goal)
        self._paths[key] = result
        return result

    def _search(self, start: FloatArray, goal: FloatArray) -> list[FloatArray] | None:
        if not (self.free(start) and self.free(goal)):
            return None
        if not bool(self.blocked(start, goal[None, :])[0]):
            return [start, goal]
        nodes = self._nodes
        m = nodes.shape[0]
        pts = np.concatenate([start[None, :], goal[None, :], nodes])
        n = pts.shape[0]
        # Rows for the two query points, computed once; node-node rows come from the cache.
        from_start = np.concatenate([[False, False], ~self.blocked(start, nodes)])
        to_goal = ~self.blocked(goal, nodes)
        g_cost = np.full(n, math.inf)
        parent = np.full(n, -1, dtype=np.int64)
        closed = np.zeros(n, dtype=bool)
        h = np.hypot(pts[:, 0] - goal[0], pts[:, 1] - goal[1])
        g_cost[0] = 0.0
        heap: list[tuple[float, int]] = [(float(h[0]), 0)]
        while heap:
            _, u = heapq.heappop(heap)
            if closed[u]:
                continue
            if u == 1:
                return _walk(parent, pts)
            closed[u] = True
            if u == 0:
                visible = from_start
            else:
                visible = np.concatenate([[False, bool(to_goal[u - 2])], self._node_row(u - 2)])
            vis = np.flatnonzero(visible & ~closed)
            if m == 0 and u == 0:
                vis = np.array([], dtype=np.int64)
            step = np.hypot(pts[vis, 0] - pts[u, 0], pts[vis, 1] - pts[u, 1])
            new_g = g_cost[u] + step
            better = new_g < g_cost[vis] - 1e-9
            for v, gv in zip(vis[better], new_g[better], strict=True):
                g_cost[v] = gv
                parent[v] = u
                heapq.heappush(heap, (float(gv + h[v]), int(v)))
        return None


def _walk(parent: npt.NDArray[np.int64], pts: FloatArray) -> list[FloatArray]:
    idx = [1]
    while parent[idx[-1]] >= 0:
        idx.append(int(parent[idx[-1]]))
    return [pts[i] for i in reversed(idx)]
