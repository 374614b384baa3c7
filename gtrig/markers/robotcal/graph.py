"""Step 4: the pose graph over markers: spanning-tree start, bridges, robust SE(3) averaging.

Nodes are markers, edges the averaged relative poses of co-visible pairs (:mod:`.pairs`), weighted by
their number of agreeing images. The start is the maximum-weight spanning tree grown from the anchor
(Prim): each marker is reached through its best-observed chain, so a marker never seen with the anchor
(or with some other marker) is *bridged* through the markers it was seen with, as the seeds did by hand
("we selected the chains with the highest number of views"). Then every edge is used: rotations by
iterated robust averaging of the neighbours' predictions (each marker's rotation is the weighted Karcher
mean of ``R_a R_a_b`` over its edges, Huber-weighted by the disagreement; Govindu, "Lie-algebraic
averaging", CVPR 2004; Hartley et al., IJCV 2013), translations by a weighted linear least-squares
over all edges given the rotations, reweighted likewise. Edges that still disagree with the averaged
graph by more than ``reject`` times the median are rejected and named.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gtrig import geometry as geo
from gtrig.geometry.se3avg import mean_rotation
from gtrig.markers.robotcal.observe import Array
from gtrig.markers.robotcal.pairs import PairEdge


@dataclass(frozen=True)
class GraphResult:
    """Marker poses relative to the anchor from the pose graph.

    Attributes
    ----------
    T_anchor_marker : {ID: (4, 4)} pose of each reached marker in the anchor marker's frame (metres).
    paths : {ID: chain of IDs from the anchor} in the spanning tree (length 2 = seen with the anchor;
        longer = bridged through other markers).
    unreached : markers in no edge connected to the anchor.
    rejected_edges : (a, b) pairs rejected as inconsistent with the rest of the graph.
    """

    T_anchor_marker: dict[int, Array]
    paths: dict[int, tuple[int, ...]]
    unreached: tuple[int, ...]
    rejected_edges: tuple[tuple[int, int], ...]


def _oriented(e: PairEdge, frm: int) -> tuple[int, Array]:
    """(other end, T_from_other) of edge ``e`` seen from marker ``frm``."""
    return (e.b, e.T_a_b) if frm == e.a else (e.a, geo.inv_T(e.T_a_b))


def spanning_tree(ids: Sequence[int], edges: Sequence[PairEdge], anchor: int
                  ) -> tuple[dict[int, Array], dict[int, tuple[int, ...]]]:
    """Poses ``T_anchor_marker`` by composing the maximum-weight spanning tree from ``anchor`` (Prim)."""
    T = {anchor: np.eye(4)}
    paths: dict[int, tuple[int, ...]] = {anchor: (anchor,)}
    while True:
        best: tuple[int, int, PairEdge] | None = None
        for e in edges:
            for frm, to in ((e.a, e.b), (e.b, e.a)):
                if frm in T and to not in T and to in ids and (best is None or e.n > best[2].n):
                    best = (frm, to, e)
        if best is None:
            return T, paths
        frm, to, e = best
        _, T_ft = _oriented(e, frm)
        T[to] = T[frm] @ T_ft
        paths[to] = paths[frm] + (to,)


def _huber_w(r: Array, k: float) -> Array:
    return np.where(r <= k, 1.0, k / np.maximum(r, 1e-300))


def average_graph(T0: dict[int, Array], edges: Sequence[PairEdge], anchor: int, iters: int = 10
                  ) -> dict[int, Array]:
    """Robust rotation then translation averaging over every edge between markers of ``T0``; the anchor
    stays at identity. Returns the averaged ``T_anchor_marker``."""
    ids = [i for i in T0 if i != anchor]
    use = [e for e in edges if e.a in T0 and e.b in T0]
    R = {i: T0[i][:3, :3].copy() for i in T0}
    for _ in range(iters):
        res = []
        for e in use:
            res.append(geo.rotation_angle(R[e.a].T @ R[e.b] @ e.T_a_b[:3, :3].T))
        k = max(3.0 * 1.4826 * float(np.median(res)) if res else 0.0, math.radians(0.05))
        w_edge = {(e.a, e.b): e.n * float(_huber_w(np.array([r]), k)[0]) for e, r in zip(use, res, strict=True)}
        for i in ids:
            preds, ws = [], []
            for e in use:
                if i not in (e.a, e.b):
                    continue
                other, T_io = _oriented(e, i)
                # R_i = R_other R_other_i = R_other inv(R_i_other)
                preds.append(R[other] @ T_io[:3, :3].T)
                ws.append(w_edge[(e.a, e.b)])
            if preds:
                R[i] = mean_rotation(np.stack(preds), np.asarray(ws))
    # translations: t_b - t_a = R_a t_ab for every edge, anchor fixed at 0
    col = {i: n for n, i in enumerate(ids)}
    t = {i: T0[i][:3, 3].copy() for i in T0}
    t[anchor] = np.zeros(3)
    if ids:
        w = np.array([float(e.n) for e in use])
        for _ in range(iters):
            A = np.zeros((3 * len(use), 3 * len(ids)))
            b = np.zeros(3 * len(use))
            for r, e in enumerate(use):
                rhs = R[e.a] @ e.T_a_b[:3, 3]
                for node, sign in ((e.b, 1.0), (e.a, -1.0)):
                    if node == anchor:
                        continue
                    A[3 * r:3 * r + 3, 3 * col[node]:3 * col[node] + 3] = sign * np.eye(3)
                b[3 * r:3 * r + 3] = rhs
            sw = np.repeat(np.sqrt(w), 3)
            x = np.linalg.lstsq(A * sw[:, None], b * sw, rcond=None)[0]
            for i in ids:
                t[i] = x[3 * col[i]:3 * col[i] + 3]
            res_t = np.linalg.norm((A @ x - b).reshape(-1, 3), axis=1)
            k = max(3.0 * 1.4826 * float(np.median(res_t)), 2e-4)
            w = np.array([float(e.n) for e in use]) * _huber_w(res_t, k)
    return {i: geo.make_T(R[i], t[i]) for i in T0}


def edge_residuals(T: dict[int, Array], e: PairEdge) -> tuple[float, float]:
    """(metres, radians) disagreement of edge ``e`` with the graph poses ``T``."""
    return geo.pose_error(geo.inv_T(T[e.a]) @ T[e.b], e.T_a_b)


def solve_graph(ids: Sequence[int], edges: Sequence[PairEdge], anchor: int, reject: float = 6.0
                ) -> GraphResult:
    """The pose graph of markers ``ids`` from ``edges``, anchored on ``anchor``; see the module doc.

    ``reject``: an edge is dropped when its residual exceeds ``reject`` times the median residual (with
    floors of 2 mm and 0.2 deg, below which pairs are consistent to the accuracy of one image).
    """
    live = list(edges)
    rejected: list[tuple[int, int]] = []
    while True:
        T0, paths = spanning_tree(ids, live, anchor)
        T = average_graph(T0, live, anchor)
        used = [e for e in live if e.a in T and e.b in T]
        if len(used) <= len(T) - 1:  # a tree: nothing to cross-check
            break
        res = np.array([edge_residuals(T, e) for e in used])
        lim_m = max(reject * float(np.median(res[:, 0])), 0.002)
        lim_r = max(reject * float(np.median(res[:, 1])), math.radians(0.2))
        bad = np.maximum(res[:, 0] / lim_m, res[:, 1] / lim_r)
        worst = int(np.argmax(bad))
        if bad[worst] <= 1.0:
            break
        e = used[worst]
        # never cut the last link of a marker: a wrong bridge is reported by the bundle adjustment
        rest = [x for x in live if x is not e]
        T_rest, _ = spanning_tree(ids, rest, anchor)
        if len(T_rest) < len(T):
            break
        rejected.append((e.a, e.b))
        live = rest
    unreached = tuple(sorted(set(ids) - set(T)))
    return GraphResult(T, {i: p for i, p in paths.items() if i != anchor}, unreached, tuple(rejected))

