"""Step 3: relative poses of the marker pairs seen together, flips resolved by consistency.

In an image showing markers ``a`` and ``b``, each has two IPPE solutions, so the image offers four
candidate relative poses ``T_a_b = inv(T_cam_a) T_cam_b``. The true one is the same in every image;
a wrong one (one marker flipped) moves with the viewpoint, because the flip mirrors the plane about the
line of sight. So the candidate that most other images agree with (within ``tol_m``, ``tol_rad``) is
taken, each image contributes its candidate nearest to it, and those are averaged on SE(3)
(:func:`gtrig.geometry.se3avg.mean_pose`). Images whose candidate stays far from the mean are outliers of
the pair (a misdetection, a bent marker in one view) and are named in the report.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from gtrig import geometry as geo
from gtrig.geometry.se3avg import mean_pose
from gtrig.markers.robotcal.observe import Array
from gtrig.markers.robotcal.pnp import ViewPoses


@dataclass(frozen=True)
class PairEdge:
    """The averaged relative pose of one co-visible pair.

    Attributes
    ----------
    a, b : marker IDs (``a < b``).
    T_a_b : (4, 4) pose of marker ``b`` in marker ``a``'s frame (metres).
    images : the images that agree (inliers).
    outliers : the images of the pair that disagree.
    rot_rms_rad, trans_rms_m : spread of the inliers about the mean.
    """

    a: int
    b: int
    T_a_b: Array
    images: tuple[str, ...]
    outliers: tuple[str, ...]
    rot_rms_rad: float
    trans_rms_m: float

    @property
    def n(self) -> int:
        return len(self.images)


def _dist(Ta: Array, Tb: Array) -> tuple[float, float]:
    return geo.pose_error(Ta, Tb)


def close_matrix(A: Array, B: Array, tol_m: float, tol_rad: float) -> np.ndarray:
    """(N, M) whether poses ``A[i]`` and ``B[j]`` (stacks of 4 x 4) are within ``tol_m`` and ``tol_rad``.

    The angle test compares traces (``cos angle = (tr(Ra^T Rb) - 1) / 2``): exact enough at degree-level
    tolerances and vectorised (this is the inner loop of the flip vote)."""
    dt = np.linalg.norm(A[:, None, :3, 3] - B[None, :, :3, 3], axis=2)
    tr = np.einsum("aij,bij->ab", A[:, :3, :3], B[:, :3, :3])
    return (dt < tol_m) & ((tr - 1.0) / 2.0 > np.cos(tol_rad))


def pair_edge(a: int, b: int, per_image: Sequence[tuple[str, ViewPoses, ViewPoses]],
              tol_m: float = 0.02, tol_rad: float = math.radians(2.0)) -> PairEdge | None:
    """Average the relative pose of markers ``a`` and ``b`` over the images that show both.

    Parameters
    ----------
    per_image : (image, solutions of a, solutions of b) for each image showing both.
    tol_m, tol_rad : two candidates agree when closer than this.

    Returns None when several images show the pair but no candidate is supported by two of them. A pair
    seen in one image only keeps that image's lowest-error combination (weak: the bundle adjustment and
    the graph's other edges decide).
    """
    cands: list[tuple[int, Array, float]] = []  # (image index, T_a_b, summed rms)
    for k, (_, pa, pb) in enumerate(per_image):
        for i in range(2):
            for j in range(2):
                T = geo.inv_T(pa.T_cam_marker[i]) @ pb.T_cam_marker[j]
                cands.append((k, T, float(pa.rms[i] + pb.rms[j])))
    n_img = len(per_image)
    Ts = np.stack([T for _, T, _ in cands])
    img = np.array([k for k, _, _ in cands])
    close = close_matrix(Ts, Ts, tol_m, tol_rad)  # (C, C)
    hits = np.zeros((len(cands), n_img), bool)
    for k in range(n_img):
        hits[:, k] = close[:, img == k].any(axis=1)
    scored = [(int(hits[i].sum()), -rms, i) for i, (_, _, rms) in enumerate(cands)]
    best_support, _, best = max(scored)
    if best_support < 2 and n_img >= 2:
        return None
    ref = cands[best][1]
    for _ in range(3):  # nearest candidate per image, average, repeat around the new mean
        chosen: dict[int, Array] = {}
        for k, T, _ in cands:
            dt, dr = _dist(ref, T)
            if dt < tol_m and dr < tol_rad:
                prev = chosen.get(k)
                if prev is None or sum(_ratio(ref, T, tol_m, tol_rad)) < sum(_ratio(ref, prev, tol_m, tol_rad)):
                    chosen[k] = T
        if not chosen:
            return None
        m = mean_pose(np.stack(list(chosen.values())))
        ref = m.T
    # tighten: drop inliers far from the mean relative to the pair's own spread
    keys = sorted(chosen)
    errs = np.array([_ratio(ref, chosen[k], max(m.trans_rms_m, 1e-4), max(m.rot_rms_rad, 1e-5))
                     for k in keys])
    worst = np.max(errs, axis=1)
    keep = [k for k, e in zip(keys, worst, strict=True) if e < 4.0] if len(keys) >= 4 else keys
    if len(keep) != len(keys):
        m = mean_pose(np.stack([chosen[k] for k in keep]))
    names = [per_image[k][0] for k in keep]
    out = [per_image[k][0] for k in range(n_img) if k not in keep]
    return PairEdge(a, b, m.T, tuple(names), tuple(out), m.rot_rms_rad, m.trans_rms_m)


def _ratio(Ta: Array, Tb: Array, s_m: float, s_rad: float) -> tuple[float, float]:
    dt, dr = _dist(Ta, Tb)
    return dt / s_m, dr / s_rad


def pair_edges(solutions: Mapping[str, Mapping[int, ViewPoses]], tol_m: float = 0.02,
               tol_rad: float = math.radians(2.0)) -> list[PairEdge]:
    """Every co-visible pair's :class:`PairEdge`; ``solutions`` is {image: {marker ID: solutions}}."""
    pairs: dict[tuple[int, int], list[tuple[str, ViewPoses, ViewPoses]]] = {}
    for image, sols in solutions.items():
        ids = sorted(sols)
        for i, a in enumerate(ids):
            for b in ids[i + 1:]:
                pairs.setdefault((a, b), []).append((image, sols[a], sols[b]))
    edges = []
    for (a, b), per_image in sorted(pairs.items()):
        e = pair_edge(a, b, per_image, tol_m, tol_rad)
        if e is not None:
            edges.append(e)
    return edges
