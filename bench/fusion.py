"""Fusion bench: one hour of odometry (50 Hz), GTvision (40 Hz) and GTlaser (75 Hz) smoothed with marginal
covariances, and GTSAM (Levenberg-Marquardt, Marginals) on the same factors side by side.

    python bench/fusion.py [--hours 1] [--no-gtsam] [--seeds-root /work/recs]
    python bench/fusion.py --consistency [--seeds 0 1 2] [--minutes 3] [--laps 3]
    python bench/fusion.py --recording REC --results OUT

Part 1 (speed): gtrig.fusion.fuse on the full hour (fixes at their own stamps: EKF + RTS, then the batch MAP
with marginal covariances), wall time and peak memory. Part 2 (peer): the same hour with each fix snapped to
its nearest node and the odometry parameters held at their true values (Pose2 factors GTSAM has: a
BetweenFactorPose2 per increment, a PriorFactorPose2 per fix, the world-frame covariance rotated into the
fix's frame, gtrig's whitening handed over as is); both solvers on those factors, the largest position
difference and the time ratio. Part 2b (``--custom-hours``, 0.01 h by default): GTSAM on exactly gtrig's
factors (``gtsam.CustomFactor`` calling gtrig's compiled residuals), like for like. Part 3
(with --seeds-root): the acceptance rows on simulated recordings (the pipeline's GTvision and GTlaser); with
--sync also every clock offset against the simulator's truth (sources to odometry, injected odometry
offsets, each camera and scanner to GTvision's clock). ``--sync-mc N``: the offset to odometry on N
synthetic runs of the simulator's path and odometry model (bias, scatter, coverage). ``--consistency``: only
NEES/dof with 95 % batch-means intervals per seed and scenario on the synthetic run: fused, the bridged poses
of 3 s gaps, and the run made of laps whose odometry jumps back at every seam (the jumps cut as fusion does,
and fitted through as before). ``--recording REC --results OUT``: a pipeline run's fused track (a lapped
recording's from bench/scale.py too) against the truth: NEES/dof with its 95 % interval, the bridged poses'
over 3 s gaps cut every 20 s, and every camera's and scanner's clock offset against the simulated one.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

import numpy as np

from gtrig.fusion import FusionOptions, fixes_from_track, fuse
from gtrig.fusion.batch import smooth_batch
from gtrig.fusion.chain import PROCESS_ODOMETRY, FactorChain
from gtrig.fusion.process import OdometryNoise, odometry_increments, whitening
from gtrig.io.odometry import OdometryLog
from gtrig.trajectory import PoseTrack


def synthetic_hour(hours: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray, OdometryLog, list[PoseTrack]]:
    """A robot wandering for ``hours``: truth at 50 Hz, odometry with scale errors and slip, two fix streams."""
    rng = np.random.default_rng(seed)
    dt = 0.02
    n = int(hours * 3600 / dt) + 1
    t = 1000.0 + np.arange(n) * dt
    v = 0.4 + 0.2 * np.sin(t / 17.0)
    w = 0.6 * np.sin(t / 5.3) + 0.3 * np.sin(t / 2.1)
    th = np.cumsum(w) * dt
    x = np.cumsum(v * np.cos(th)) * dt
    y = np.cumsum(v * np.sin(th)) * dt
    truth = np.column_stack([x, y, th])
    # odometry: robot-frame increments scaled and slipped, integrated in its own frame
    d = np.diff(truth, axis=0)
    c, s = np.cos(truth[:-1, 2]), np.sin(truth[:-1, 2])
    u = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    _, qcov = odometry_increments(truth, t, OdometryNoise())
    noise = np.einsum("nij,nj->ni", np.linalg.cholesky(qcov), rng.normal(size=u.shape))
    um = (u + noise) * [1.007, 1.007, 0.995]
    o = np.zeros_like(truth)
    for i in range(len(um)):  # dead reckoning; sequential by nature
        ci, si = np.cos(o[i, 2]), np.sin(o[i, 2])
        o[i + 1] = o[i] + [ci * um[i, 0] - si * um[i, 1], si * um[i, 0] + ci * um[i, 1], um[i, 2]]
    odo = OdometryLog(t, o, np.r_[0, um[:, 0] / dt], np.r_[0, um[:, 2] / dt])
    tracks = []
    for name, rate, sig in (("vision", 40.0, (0.002, 0.002, 0.0007)), ("laser", 75.0, (0.0012, 0.0012, 0.0025))):
        st = np.arange(t[0] + 0.003, t[-1] - 0.003, 1 / rate)
        tru = np.column_stack([np.interp(st, t, truth[:, k]) for k in range(3)])
        cov = np.diag(np.square(sig))
        z = tru + rng.multivariate_normal(np.zeros(3), cov, st.size)
        tracks.append(PoseTrack.from_xytheta(st, z, cov=np.tile(cov, (st.size, 1, 1)), source=name))
    return t, truth, odo, tracks


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def part_speed(hours: float) -> tuple[np.ndarray, np.ndarray, OdometryLog, list[PoseTrack]]:
    t, truth, odo, tracks = synthetic_hour(hours)
    n_meas = len(odo) - 1 + sum(len(tr) for tr in tracks)
    fixes = [fixes_from_track(tr) for tr in tracks]
    small = synthetic_hour(0.01)  # compile / load the kernels outside the timing
    fuse([fixes_from_track(tr) for tr in small[3]], small[2])
    rss0 = peak_rss_mb()
    t0, c0 = time.perf_counter(), time.process_time()
    track, rep = fuse(fixes, odo, FusionOptions(correlation_s=0.0))
    secs, cpu = time.perf_counter() - t0, time.process_time() - c0
    e = track.xytheta() - np.column_stack([np.interp(track.stamps_s, t, truth[:, k]) for k in range(3)])
    e[:, 2] = (e[:, 2] + np.pi) % (2 * np.pi) - np.pi
    nees = float(np.mean(np.einsum("ni,nij,nj->n", e, np.linalg.inv(track.cov), e)) / 3)
    print(f"## speed: {hours:g} h, {len(track)} poses, {n_meas} measurements "
          f"({len(odo) - 1} odometry, {len(tracks[0])} vision, {len(tracks[1])} laser)")
    print(f"gtrig fuse (EKF + RTS, batch MAP, marginals): {secs:.2f} s wall, {cpu:.2f} s CPU, "
          f"{n_meas / secs / 1e3:.0f} k measurements/s, "
          f"peak RSS {peak_rss_mb():.0f} MB (+{peak_rss_mb() - rss0:.0f} MB); batch iterations "
          f"{rep.segments[0].iterations}")
    print(f"accuracy vs truth: mean position {np.hypot(e[:, 0], e[:, 1]).mean() * 1e3:.3f} mm, "
          f"NEES/dof {nees:.3f}")
    # the same hour with a run-constant bias considered for both sources (3 right-hand sides each on the
    # marginals' factorisation): what the considered covariance costs (the synthetic fixes carry no bias)
    bias = {tr.source: np.diag([0.001, 0.001, 0.0004]) ** 2 for tr in tracks}
    t0, c0 = time.perf_counter(), time.process_time()
    track_b, _ = fuse(fixes, odo, FusionOptions(correlation_s=0.0, bias_cov=bias))
    secs_b, cpu_b = time.perf_counter() - t0, time.process_time() - c0
    grow = np.sqrt(track_b.cov[:, 0, 0] / track.cov[:, 0, 0])
    print(f"with both sources' bias considered: {secs_b:.2f} s wall, {cpu_b:.2f} s CPU; same poses "
          f"{bool(np.array_equal(track_b.xytheta(), track.xytheta()))}, x sigma x {np.median(grow):.1f} (median)")
    return t, truth, odo, tracks


def snapped_chain(odo: OdometryLog, tracks: list[PoseTrack]) -> tuple[FactorChain, np.ndarray, np.ndarray]:
    """Fixes snapped to their nearest odometry node, parameters held (a tight prior at the true values)."""
    st = odo.stamps_s
    u, qcov = odometry_increments(odo.xytheta, st, OdometryNoise())
    k_true = np.array([1 / 1.007, 1 / 0.995, 0.0])
    node, z, cov = [], [], []
    for tr in tracks:
        k = np.clip(np.round((tr.stamps_s - st[0]) / (st[1] - st[0])).astype(int), 0, st.size - 1)
        node.append(k)
        z.append(tr.xytheta())
        cov.append(tr.cov_xytheta())
    node_a, z_a, cov_a = np.concatenate(node), np.concatenate(z), np.concatenate(cov)
    order = np.argsort(node_a, kind="stable")
    node_a, z_a, cov_a = node_a[order], z_a[order], cov_a[order]
    left = np.minimum(node_a, st.size - 2)
    alpha = (node_a - left).astype(float)
    M = node_a.size
    x0 = z_a[0]
    chain = FactorChain(st, PROCESS_ODOMETRY, u, whitening(qcov), left.astype(np.int64), alpha, np.zeros(M, np.int64),
                        z_a, cov_a, whitening(cov_a), np.zeros((M, 2)), np.zeros(M, np.int64), st[node_a],
                        ("fix",), x0, whitening(np.diag([1e-2, 1e-2, 1e-2])[None])[0], k_true,
                        whitening(np.diag([1e-16, 1e-16, 1e-16])[None])[0])
    # start: dead reckoning with the true parameters from the first fix
    X = np.zeros((st.size, 3))
    X[0] = x0
    for i in range(st.size - 1):
        c, s = np.cos(X[i, 2]), np.sin(X[i, 2])
        a = k_true[0] * u[i]
        X[i + 1] = X[i] + [c * a[0] - s * a[1], s * a[0] + c * a[1], k_true[1] * u[i, 2] + k_true[2] * u[i, 0]]
    return chain, X, k_true


def _difference(result, X: np.ndarray) -> tuple[float, float]:  # noqa: ANN001 (gtsam.Values)
    """Largest position (m) and yaw (rad) difference between GTSAM's Pose2 values and gtrig's states."""
    xy = np.array([[result.atPose2(i).x(), result.atPose2(i).y(), result.atPose2(i).theta()] for i in range(len(X))])
    dpos = float(np.max(np.hypot(*(xy[:, :2] - X[:, :2]).T)))
    return dpos, float(np.max(np.abs((xy[:, 2] - X[:, 2] + np.pi) % (2 * np.pi) - np.pi)))


def part_gtsam(odo: OdometryLog, tracks: list[PoseTrack]) -> None:
    chain, X0, k = snapped_chain(odo, tracks)
    t0 = time.perf_counter()
    res = smooth_batch(chain, X0, k, huber_k=0.0)
    ours_s = time.perf_counter() - t0
    print(f"## peer: the same factors, fixes snapped to nodes ({len(chain)} nodes, {chain.fix_node.size} fixes)")
    print(f"gtrig batch (Gauss-Newton/LM + all marginals): {ours_s:.2f} s, {res.iterations} iterations")
    try:
        import gtsam
    except ImportError:
        print("gtsam: not installed (pip install gtsam); peer skipped")
        return
    graph = gtsam.NonlinearFactorGraph()
    init = gtsam.Values()
    inc = chain.proc_u * [k[0], k[0], 0.0]
    inc[:, 2] = k[1] * chain.proc_u[:, 2] + k[2] * chain.proc_u[:, 0]
    t0 = time.perf_counter()
    for i in range(len(chain) - 1):
        # Pose2's between error is the residual rotated by the increment's own turn: rotate its noise alike
        c, s = np.cos(inc[i, 2]), np.sin(inc[i, 2])
        Rm = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1.0]])
        # gtrig's whitening rotated alike (W R^T): GTSAM's Covariance() would factor the ill-conditioned
        # slip covariance again and lose digits (that alone moved the solution by 2e-6 m)
        graph.add(gtsam.BetweenFactorPose2(i, i + 1, gtsam.Pose2(*inc[i]),
                                           gtsam.noiseModel.Gaussian.SqrtInformation(chain.proc_W[i] @ Rm.T)))
    for j in range(chain.fix_node.size):
        n = int(chain.fix_node[j] + chain.fix_alpha[j])
        z = chain.fix_z[j]
        c, s = np.cos(z[2]), np.sin(z[2])
        J = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1.0]])  # world-frame perturbation -> Pose2's local one
        graph.add(gtsam.PriorFactorPose2(n, gtsam.Pose2(*z),
                                         gtsam.noiseModel.Gaussian.SqrtInformation(chain.fix_W[j] @ J.T)))
    x0p = chain.x0
    graph.add(gtsam.PriorFactorPose2(0, gtsam.Pose2(*x0p), gtsam.noiseModel.Gaussian.Covariance(np.diag([1e-2] * 3))))
    for i in range(len(chain)):
        init.insert(i, gtsam.Pose2(*X0[i]))
    build_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-12)
    result = gtsam.LevenbergMarquardtOptimizer(graph, init, params).optimize()
    solve_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    marg = gtsam.Marginals(graph, result)
    probe = np.linspace(0, len(chain) - 1, 50).astype(int)
    cov_g = [marg.marginalCovariance(int(i)) for i in probe]
    marg_s = time.perf_counter() - t0
    dpos, dyaw = _difference(result, res.X)
    # GTSAM's marginal is in each pose's local frame: rotate ours into it
    rel = []
    for i, cg in zip(probe, cov_g, strict=True):
        c, s = np.cos(res.X[i, 2]), np.sin(res.X[i, 2])
        J = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1.0]])
        co = J @ res.cov_x[i] @ J.T
        rel.append(np.max(np.abs(np.sqrt(np.diag(co)) / np.sqrt(np.diag(cg)) - 1)))
    print(f"gtsam {gtsam.__version__ if hasattr(gtsam, '__version__') else ''} LM: build {build_s:.2f} s, solve "
          f"{solve_s:.2f} s, 50 marginals {marg_s:.2f} s")
    print(f"largest difference: position {dpos:.2e} m, yaw {dyaw:.2e} rad; sigma ratio at 50 nodes within "
          f"{max(rel) * 100:.3f} %")
    print(f"time ratio gtsam solve / gtrig (solve + every marginal): {solve_s / ours_s:.2f}")


def _local_jacobian(theta: float) -> np.ndarray:
    """d (x, y, yaw) / d (Pose2's local tangent) at a pose of heading ``theta``: GTSAM retracts a Pose2 by
    ``pose * Expmap(delta)``, whose first-order effect is the translation rotated into the world."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def gtsam_custom_graph(chain: FactorChain, k: np.ndarray):  # noqa: ANN201
    """GTSAM's graph of exactly gtrig's factors: ``gtsam.CustomFactor`` s whose errors are gtrig's own
    compiled residuals (kernels.odo_residual, kernels.fix_residual, the additive prior) with gtrig's
    noise, the Jacobians mapped into Pose2's tangent space. Only the angle representation differs (Pose2
    wraps yaw; the odometry residual's yaw difference is wrapped alike)."""
    import gtsam

    from gtrig.fusion.kernels import fix_residual, odo_residual, wrap

    graph = gtsam.NonlinearFactorGraph()
    buf = {n: np.empty((3, 3)) for n in ("Ja", "Jb", "Jk", "Jq")}

    def xyt(values: gtsam.Values, key: int) -> np.ndarray:
        p = values.atPose2(key)
        return np.array([p.x(), p.y(), p.theta()])

    def odo_error(i: int):  # noqa: ANN202
        def err(this: gtsam.CustomFactor, values: gtsam.Values, H: list[np.ndarray] | None) -> np.ndarray:
            a, b = xyt(values, i), xyt(values, i + 1)
            r = np.empty(3)
            odo_residual(a, b, k, chain.proc_u[i], r, buf["Ja"], buf["Jb"], buf["Jk"])
            r[2] = wrap(r[2])
            if H is not None:
                H[0] = buf["Ja"] @ _local_jacobian(a[2])
                H[1] = buf["Jb"] @ _local_jacobian(b[2])
            return r
        return err

    def fix_error(j: int, key: int):  # noqa: ANN202
        def err(this: gtsam.CustomFactor, values: gtsam.Values, H: list[np.ndarray] | None) -> np.ndarray:
            q = xyt(values, key)
            r = np.empty(3)
            fix_residual(q, q, 0.0, int(chain.fix_kind[j]), chain.fix_z[j], chain.fix_lever[j], r, buf["Jq"],
                         np.empty(3), np.empty(3))
            if H is not None:
                H[0] = buf["Jq"] @ _local_jacobian(q[2])
            return r
        return err

    def prior_error(this: gtsam.CustomFactor, values: gtsam.Values, H: list[np.ndarray] | None) -> np.ndarray:
        q = xyt(values, 0)
        r = q - chain.x0
        r[2] = wrap(r[2])
        if H is not None:
            H[0] = _local_jacobian(q[2])
        return r

    for i in range(len(chain) - 1):
        # gtrig's own whitening (W^T W = information), not a covariance GTSAM would factor again
        graph.add(gtsam.CustomFactor(gtsam.noiseModel.Gaussian.SqrtInformation(chain.proc_W[i]), [i, i + 1],
                                     odo_error(i)))
    for j in range(chain.fix_node.size):
        key = int(chain.fix_node[j] + chain.fix_alpha[j])  # snapped: alpha is 0 or 1
        graph.add(gtsam.CustomFactor(gtsam.noiseModel.Gaussian.SqrtInformation(chain.fix_W[j]), [key],
                                     fix_error(j, key)))
    graph.add(gtsam.CustomFactor(gtsam.noiseModel.Gaussian.SqrtInformation(chain.W0), [0], prior_error))
    return graph


def part_gtsam_custom(odo: OdometryLog, tracks: list[PoseTrack]) -> None:
    """GTSAM on exactly gtrig's factors (CustomFactor): the like-for-like answer and time ratio."""
    import gtsam

    chain, X0, k = snapped_chain(odo, tracks)
    t0 = time.perf_counter()
    res = smooth_batch(chain, X0, k, huber_k=0.0)
    ours_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    graph = gtsam_custom_graph(chain, k)
    init = gtsam.Values()
    for i in range(len(chain)):
        init.insert(i, gtsam.Pose2(*X0[i]))
    build_s = time.perf_counter() - t0
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(1e-14)
    t0 = time.perf_counter()
    result = gtsam.LevenbergMarquardtOptimizer(graph, init, params).optimize()
    solve_s = time.perf_counter() - t0
    marg = gtsam.Marginals(graph, result)
    probe = np.linspace(0, len(chain) - 1, 50).astype(int)
    dpos, dyaw = _difference(result, res.X)
    rel = []
    for i in probe:  # GTSAM's marginal is over the local tangent: map ours (world-frame) into it
        Jl = np.linalg.inv(_local_jacobian(res.X[i, 2]))
        co = Jl @ res.cov_x[i] @ Jl.T
        rel.append(np.max(np.abs(np.sqrt(np.diag(co)) / np.sqrt(np.diag(marg.marginalCovariance(int(i)))) - 1)))
    print(f"## peer, exactly gtrig's factors (gtsam.CustomFactor calling gtrig's compiled residuals; "
          f"{len(chain)} nodes, {chain.fix_node.size} fixes)")
    print(f"gtrig batch + every marginal {ours_s:.2f} s; gtsam LM with Python factors: build {build_s:.2f} s, "
          f"solve {solve_s:.2f} s")
    print(f"largest difference: position {dpos:.2e} m, yaw {dyaw:.2e} rad; sigma ratio at 50 nodes within "
          f"{max(rel) * 100:.4f} %")
    print(f"time ratio gtsam solve (Python factors) / gtrig (solve + every marginal): {solve_s / ours_s:.2f}")


def part_seeds(root: Path) -> None:
    from gtrig.io.biascov import read_bias_cov
    from gtrig.io.odometry import read_odometry
    from gtrig.io.offsets import read_offsets
    from gtrig.io.posetrack import read_pose_track
    from gtrig.io.tum import read_tum
    from gtrig.pipeline.fusion import BIAS_FILES
    from gtrig.sync.offset import offset_sigmas

    print("## acceptance on simulated recordings (the pipeline's GTvision and GTlaser)")
    print("| seed | source | mean pos (mm) | p95 pos (mm) | max pos (mm) | mean yaw (deg) | NEES/dof | in 95 % (%) |")
    print("|---|---|---|---|---|---|---|---|")
    for rec in sorted(root.glob("s*")):
        res = rec / "results"
        if not (res / "gt_laser.tum").exists() or not (res / "gt_vision_run.tum").exists():
            continue
        vis = read_pose_track(res / "gt_vision_run.tum", res / "gt_vision_run_cov.csv", "vision")
        las = read_pose_track(res / "gt_laser.tum", res / "gt_laser_cov.csv", "laser")
        odo = read_odometry(rec / "recording" / "run" / "odometry.csv")
        truth = read_tum(rec / "recording" / "truth" / "run.tum")
        th = np.unwrap(truth.yaw_rad())

        def errs(tr: PoseTrack, truth=truth, th=th) -> np.ndarray:  # noqa: ANN001
            g = np.column_stack([np.interp(tr.stamps_s, truth.stamps_s, truth.xyz[:, 0]),
                                 np.interp(tr.stamps_s, truth.stamps_s, truth.xyz[:, 1]),
                                 np.interp(tr.stamps_s, truth.stamps_s, th)])
            e = tr.xytheta() - g
            e[:, 2] = (e[:, 2] + np.pi) % (2 * np.pi) - np.pi
            return e

        # each source's run-constant error as its stage wrote it (considered in the covariance only)
        bias = {k: read_bias_cov(res / f) for k, f in BIAS_FILES.items() if (res / f).is_file()}
        for k, b in bias.items():
            sd = np.sqrt(np.diag(b)) * [1e3, 1e3, np.degrees(1e3)]
            print(f"|  | {k}: run-constant error considered, sd x {sd[0]:.3f}, y {sd[1]:.3f} mm, yaw {sd[2]:.1f} mdeg "
                  "| | | | | |")
        fused, rep = fuse([fixes_from_track(vis), fixes_from_track(las)], odo, FusionOptions(bias_cov=bias))
        rows = [("vision", vis.usable()), ("laser", las.usable()), ("fused", fused)]
        if bias:
            rows.append(("fused, no bias term", fuse([fixes_from_track(vis), fixes_from_track(las)], odo)[0]))
        if (res / "sync.yaml").is_file():  # as the pipeline fuses: sync's offsets applied, their sigmas kept
            offs = read_offsets(res / "sync.yaml")
            opts = FusionOptions(offsets_s=offs, offsets_sigma_s=offset_sigmas(res / "sync.yaml"), bias_cov=bias)
            rows.append(("fused, sync's offsets", fuse([fixes_from_track(vis), fixes_from_track(las)], odo, opts)[0]))
        for name, tr in rows:
            e = errs(tr)
            p = np.hypot(e[:, 0], e[:, 1]) * 1e3
            c = tr.cov_xytheta()
            q = np.einsum("ni,nij,nj->n", e, np.linalg.inv(c), e)
            print(f"| {rec.name} | {name} | {p.mean():.3f} | {np.percentile(p, 95):.3f} | {p.max():.3f} | "
                  f"{np.degrees(np.abs(e[:, 2])).mean():.4f} | {q.mean() / 3:.3f} | {100 * np.mean(q <= 7.815):.1f} |")
            # a source's mean world-frame error is what no weighting can average out (GTvision's
            # -1.4, -0.9 mm from the detector's edge band, where the mean pos column looked unchanged)
            print(f"|  | {name}: mean error world x {e[:, 0].mean() * 1e3:+.3f}, y {e[:, 1].mean() * 1e3:+.3f} mm | "
                  "| | | | | |")
            if name.startswith("fused"):
                # where an absolute source is within 0.5 s (accepted fixes of either)
                near = np.zeros(len(tr), bool)
                for src in (vis.usable(), las.usable()):
                    k = np.clip(np.searchsorted(src.stamps_s, tr.stamps_s), 1, len(src) - 1)
                    gap = np.minimum(np.abs(src.stamps_s[k - 1] - tr.stamps_s), np.abs(src.stamps_s[k] - tr.stamps_s))
                    near |= gap <= 0.5
                print(f"|  | {name}: max {p[near].max():.3f} mm where a source is within 0.5 s "
                      f"({int(near.sum())} poses) | | | | | | |")
        print(f"|  | fused: {rep.seconds:.2f} s, {sum(int(v['rejected']) for v in rep.sources.values())} fixes "
              f"rejected, {len(fused)} poses | | | | | | |")
        print(f"|  | odometry noise: {_noise(rep.odometry_noise)} | | | | | | |")
        # a 3 s gap cut out of both sources, mid-run (a quick recording is shorter than a minute): the
        # bridged poses against their ellipses
        g0 = min(float(odo.stamps_s[0]) + 30.0, 0.5 * (float(odo.stamps_s[0]) + float(odo.stamps_s[-1])) - 1.5)
        cut = {n: t.select((t.stamps_s < g0) | (t.stamps_s > g0 + 3.0)) for n, t in (("vision", vis), ("laser", las))}
        bridged, _ = fuse([fixes_from_track(t, n) for n, t in cut.items()], odo, FusionOptions(bias_cov=bias))
        b = bridged.status == 2
        if not b.any():
            print("|  | 3 s gap: no pose bridged (the sources do not both see the robot there) | | | | | | |")
            continue
        e = errs(bridged)[b]
        q = np.einsum("ni,nij,nj->n", e, np.linalg.inv(bridged.cov[b]), e)
        p = np.hypot(e[:, 0], e[:, 1]) * 1e3
        print(f"|  | 3 s gap: {int(b.sum())} bridged poses, max error {p.max():.2f} mm, NEES/dof {q.mean() / 3:.2f}, "
              f"inside 3 sigma {np.mean(q < 14.16) * 100:.1f} % | | | | | | |")


def _noise(n: dict[str, float]) -> str:
    """The fusion report's odometry noise model in a line (slip, floors; the fit's windows and NEES/dof)."""
    if not n:
        return "none"
    out = (f"slip {n['slip_m_per_sqrt_m'] * 1e3:.2f} mm/sqrt(m), floors {n['floor_m_per_sqrt_s'] * 1e3:.2f} mm and "
           f"{n['floor_rad_per_sqrt_s'] * 1e3:.2f} mrad per sqrt(s)")
    if "windows" in n:
        out += (f", fitted on {n['windows']:.0f} windows (their NEES/dof {n['window_nees_given']:.2f} stated, "
                f"{n['window_nees_fitted']:.2f} fitted)")
    return out


def _ms(e) -> str:  # noqa: ANN001
    if e.verdict != "ok":
        return f"{e.verdict} ({e.reason})"
    return f"{e.offset_s * 1e3:+.3f} ms [{e.ci95_s[0] * 1e3:+.2f}, {e.ci95_s[1] * 1e3:+.2f}]"


def _row(name: str, e, truth_s: float) -> str:  # noqa: ANN001
    if e.verdict != "ok":
        return f"| {name} | {truth_s * 1e3:+.3f} | {_ms(e)} | | |"
    err = (e.offset_s - truth_s) * 1e3
    cover = "yes" if e.ci95_s[0] <= truth_s <= e.ci95_s[1] else "**no**"
    return f"| {name} | {truth_s * 1e3:+.3f} | {_ms(e)} | {err:+.3f} | {cover} |"


def _true_xytheta(truth) -> np.ndarray:  # noqa: ANN001 (gtrig Trajectory)
    """(N, 3) the true trajectory's x, y (m) and unwrapped yaw (rad)."""
    return np.column_stack([truth.xyz[:, 0], truth.xyz[:, 1], np.unwrap(truth.yaw_rad())])


def apparent_offset(track: PoseTrack, truth) -> float:  # noqa: ANN001 (gtrig Trajectory)
    """A diagnostic with the truth: the time offset that best explains ``track``'s errors against the true
    trajectory (least squares of ``z(t) - p(t) = -v(t) tau + b``, positions and 0.3 m/rad-weighted yaw), s."""
    T = truth.stamps_s
    X = _true_xytheta(truth)
    V = np.gradient(X, T, axis=0)
    u = track.usable()
    g = np.column_stack([np.interp(u.stamps_s, T, X[:, k]) for k in range(3)])
    v = np.column_stack([np.interp(u.stamps_s, T, V[:, k]) for k in range(3)])
    e = u.xytheta() - g
    e[:, 2] = (e[:, 2] + np.pi) % (2 * np.pi) - np.pi
    w = np.array([1.0, 1.0, 0.3])
    A = np.zeros((u.stamps_s.size, 3, 4))
    A[:, :, 0] = -v * w
    A[:, [0, 1, 2], [1, 2, 3]] = w
    return float(np.linalg.lstsq(A.reshape(-1, 4), (e * w).ravel(), rcond=None)[0][0])


def part_sync(root: Path, lags: tuple[float, ...] = (0.05, 0.3, 2.0)) -> None:
    """Clock offsets on the simulated recordings against their truth (truth/laser_clocks.yaml,
    truth/robot_clock.yaml; cameras are on the GT clock, with per-frame jitter only)."""
    import yaml

    from gtrig.io.odometry import read_odometry
    from gtrig.io.posetrack import read_pose_track
    from gtrig.rig import load_rig
    from gtrig.sync.offset import combine_with_laser_clock, estimate_offset, refine_by_fusion
    from gtrig.sync.returns import recording_returns
    from gtrig.sync.sensors import sensor_offsets_and_laser_clock

    for rec in sorted(root.glob("s*")):
        res, rdir = rec / "results", rec / "recording"
        if not (res / "gt_laser.tum").exists() or not (res / "gt_vision_run.tum").exists():
            continue
        vis = read_pose_track(res / "gt_vision_run.tum", res / "gt_vision_run_cov.csv", "vision")
        las = read_pose_track(res / "gt_laser.tum", res / "gt_laser_cov.csv", "laser")
        odo = read_odometry(rdir / "run" / "odometry.csv")
        rig = load_rig(res / "rig.calibrated.yaml")
        scan_truth = yaml.safe_load((rdir / "truth" / "laser_clocks.yaml").read_text())["run"]["clock_offsets_s"]
        odo_off = float(yaml.safe_load((rdir / "truth" / "robot_clock.yaml").read_text()).get("offset_s", 0.0))
        # GTlaser's clock: its OK frames' share-weighted mean of the scanners' offsets (a scanner's share of a
        # frame is its share of that frame's returns)
        ret = recording_returns(rdir, rig)
        sh = ret.frame_shares()
        k, hit = ret.frame_of(las.usable().stamps_s)
        laser_truth = float(np.mean(sh[k[hit]] @ np.array([scan_truth[n] for n in ret.names])))
        scan = ", ".join(f"{n} {v * 1e3:+.2f}" for n, v in scan_truth.items())
        print(f"## clock offsets, {rec.name} (truth: cameras 0, scanners {scan} ms; GTlaser's share-weighted "
              f"{laser_truth * 1e3:+.3f} ms; odometry {odo_off * 1e3:+.3f} ms)")
        from gtrig.io.tum import read_tum

        true_run = read_tum(rdir / "truth" / "run.tum")
        a_v, a_l = apparent_offset(vis, true_run) * 1e3, apparent_offset(las, true_run) * 1e3
        print(f"(diagnostic with the true trajectory: GTvision's errors look like {a_v:+.3f} ms, GTlaser's like "
              f"{a_l:+.3f} ms)")
        t0 = time.perf_counter()
        ck = res / "gt_vision_run.checkpoint"
        # as the pipeline: the cameras refined jointly with odometry, on GTvision's offset to it
        uv = vis.usable()
        ev = refine_by_fusion(estimate_offset(odo.stamps_s, odo.xytheta[:, 2], uv.stamps_s, uv.yaw_rad(), "vision"),
                              fixes_from_track(vis, "vision"), odo)
        sensors, clock = sensor_offsets_and_laser_clock(
            rdir, rig, vis, las, checkpoint=ck, odometry=odo,
            odometry_offset_s=ev.offset_s if ev.verdict == "ok" else float("nan"))
        secs = time.perf_counter() - t0
        print(f"(GTlaser's clock to GTvision's from the scanners: {clock[0] * 1e3:+.3f} ms, sigma "
              f"{clock[1] * 1e3:.3f}; truth {laser_truth * 1e3:+.3f})")
        print("| offset | truth (ms) | estimate, 95 % interval | error (ms) | covers |")
        print("|---|---|---|---|---|")
        truths = {"vision": 0.0, "laser": laser_truth}
        for lag in (0.0, *lags):
            o = OdometryLog(odo.stamps_s + lag, odo.xytheta, odo.v_mps, odo.omega_radps)
            src = {}
            for name, tr in (("vision", vis), ("laser", las)):
                u = tr.usable()
                e = estimate_offset(o.stamps_s, o.xytheta[:, 2], u.stamps_s, u.yaw_rad(), name)
                src[name] = refine_by_fusion(e, fixes_from_track(tr, name), o)
            comb = dict(zip(("vision", "laser"), combine_with_laser_clock(src["vision"], src["laser"], *clock),
                            strict=True))
            for label, ests in (("alone", src), ("combined", comb)):
                for name, e in ests.items():
                    print(_row(f"{name} to odometry, {label}" + (f" + {lag:g} s injected" if lag else ""), e,
                               truths[name] - odo_off - lag))
        for e in sensors:
            kind, name = e.source.split("/", 1)
            truth = scan_truth[name] if kind == "laser" else 0.0
            print(_row(f"{e.source} to GTvision's clock", e, truth))
        print(f"(per-camera and per-scanner fits: {secs:.1f} s wall, loaded machine)")
        _other_camera_rows(rdir, rig, vis, las, ret, sensors, ck, true_run, scan_truth)
        _truth_to_odometry(true_run, odo, {"vision": vis, "laser": las}, odo_off)


def _truth_to_odometry(tr, odo: OdometryLog, tracks: dict[str, PoseTrack], odo_off: float) -> None:  # noqa: ANN001
    """The true trajectory ``tr`` (truth/run.tum), sampled at each source's stamps with its covariances, timed
    against odometry as the source is: what the odometry alone leaves in the offset (no GT clock error can be
    in it)."""
    from gtrig.sync.offset import estimate_offset, refine_by_fusion

    X = _true_xytheta(tr)
    for name, track in tracks.items():
        u = track.usable()
        xyt = np.column_stack([np.interp(u.stamps_s, tr.stamps_s, X[:, k]) for k in range(3)])
        true_src = PoseTrack.from_xytheta(u.stamps_s, xyt, cov=u.cov_xytheta(), source=name)
        e = estimate_offset(odo.stamps_s, odo.xytheta[:, 2], u.stamps_s, true_src.yaw_rad(), name)
        e = refine_by_fusion(e, fixes_from_track(true_src, name), odo)
        print(_row(f"the true trajectory at {name}'s stamps, to odometry", e, -odo_off))


def _other_camera_rows(rdir: Path, rig, vis: PoseTrack, las: PoseTrack, ret, sensors: list,  # noqa: ANN001
                       ck: Path, tr, clocks: dict[str, float]) -> None:  # noqa: ANN001
    """The cameras by the other method than the default (whole poses / reprojection), on the same
    reference (GTlaser restamped by the scanners' offsets just fitted), and by both methods against the
    true trajectory ``tr`` as reference (the estimators' own limit); ``clocks``: the scanners' true clock
    offsets (truth/laser_clocks.yaml), s."""
    from dataclasses import replace

    from gtrig.sync import sensors as ss

    scanners = [e for e in sensors if e.source.startswith("laser/")]
    cam_stamps = ss.camera_frame_stamps(rdir, rig)
    true_xyt = _true_xytheta(tr)
    truth_ref = ss.Reference(tr.stamps_s, true_xyt, np.gradient(true_xyt, tr.stamps_s, axis=0),
                             np.tile(np.eye(3) * 1e-10, (tr.stamps_s.size, 1, 1)))
    other = ("reprojection", "pose") if ss.CAMERA_METHOD == "pose" else ("pose",)  # pose: GTlaser alone
    true_scanners = [replace(e, offset_s=float(clocks[e.source.split("/", 1)[1]]), verdict="ok") for e in scanners]
    for label, ref in (("GTlaser", ss.camera_reference(las, ret, scanners)),
                       ("GTlaser on the true scanner clocks", ss.camera_reference(las, ret, true_scanners)),
                       ("the true trajectory", truth_ref)):
        methods = other if label == "GTlaser" else ("pose", "reprojection")
        for m in methods:
            t0 = time.process_time()
            ests = (ss.reprojection_offsets(rig, vis, cam_stamps, ref, ck) if m == "reprojection"
                    else ss.camera_offsets(vis, cam_stamps, ref, checkpoint=ck))
            print(f"(cameras by {m}, reference {label}: {time.process_time() - t0:.1f} s CPU)")
            for e in ests:
                print(_row(f"{e.source} to GTvision's clock ({m}, {label})", e, 0.0))


def part_sync_mc(runs: int, duration_s: float = 75.0) -> None:
    """Offsets to odometry on ``runs`` synthetic runs of the simulator's path and odometry model (errors
    drawn per run, slip 2 mm per sqrt(m) and wheel), GTlaser-like white fixes (1.2 mm, 1.2 mrad, 75 Hz)
    on the true clock: the estimator's bias, scatter and coverage against odometry."""
    from gtrig.sim.floor import Floor
    from gtrig.sim.gtroom import continuous_path
    from gtrig.sim.motion import RobotMotion
    from gtrig.sim.odometry import OdometryErrors, simulate_odometry
    from gtrig.sync.offset import estimate_offset, refine_by_fusion

    st, xyth = continuous_path(duration_s=duration_s)
    motion = RobotMotion(st + 100.0, xyth, Floor.flat())
    t0, t1 = motion.stamps_s[0], motion.stamps_s[-1]
    err, cover, half, verdicts = [], [], [], []
    for k in range(runs):
        rng = np.random.default_rng(100 + k)
        odo = simulate_odometry(motion, t0, t1, 50.0, OdometryErrors.draw(rng), rng)
        ts = np.arange(t0 + 0.007, t1 - 0.01, 1 / 75)
        cov = np.diag([0.0012**2, 0.0012**2, 0.0012**2])
        z = motion.planar(ts) + rng.multivariate_normal(np.zeros(3), cov, ts.size)
        las = PoseTrack.from_xytheta(ts, z, cov=np.tile(cov, (ts.size, 1, 1)), source="laser")
        e = estimate_offset(odo.stamps_s, odo.xytheta[:, 2], las.stamps_s, las.yaw_rad(), "laser")
        f = refine_by_fusion(e, fixes_from_track(las), odo)
        verdicts.append(f.verdict)
        if f.verdict == "ok":
            err.append(f.offset_s * 1e3)
            cover.append(f.ci95_s[0] <= 0.0 <= f.ci95_s[1])
            half.append((f.ci95_s[1] - f.ci95_s[0]) / 2 * 1e3)
    e_ms = np.array(err)
    print(f"## offsets to odometry, {runs} synthetic {duration_s:.0f} s runs (truth 0): {verdicts.count('ok')} ok; "
          f"error mean {e_ms.mean():+.3f} ms (its standard error {e_ms.std(ddof=1) / np.sqrt(e_ms.size):.3f}), "
          f"sd {e_ms.std(ddof=1):.3f} ms, max |error| {np.abs(e_ms).max():.3f} ms; mean 95 % half-width "
          f"{np.mean(half):.2f} ms, covering {100 * np.mean(cover):.0f} %")


def lapped(t: np.ndarray, truth: np.ndarray, odo: OdometryLog, tracks: list[PoseTrack], laps: int,
           ) -> tuple[np.ndarray, np.ndarray, OdometryLog, list[PoseTrack]]:
    """The run repeated ``laps`` times, each lap's stamps moved on by the run's length: at every seam the
    robot (truth, fixes) and its odometry jump back to the lap's start, as a recording made of laps does
    (bench/scale.py) and as an odometry reset or a relocalised robot does."""
    period = float(t[-1] - t[0]) + float(t[1] - t[0])

    def rep(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a] * laps)

    st = np.concatenate([t + k * period for k in range(laps)])
    odo2 = OdometryLog(st, rep(odo.xytheta), rep(odo.v_mps), rep(odo.omega_radps))
    trs = [PoseTrack.from_xytheta(np.concatenate([tr.stamps_s + k * period for k in range(laps)]),
                                  rep(tr.xytheta()), cov=rep(tr.cov), source=tr.source) for tr in tracks]
    return st, rep(truth), odo2, trs


def slipped(odo: OdometryLog, starts_s: np.ndarray, duration_s: float, factor: float) -> OdometryLog:
    """The odometry with its travel over ``duration_s`` from each of ``starts_s`` multiplied by ``factor``
    (the wheels spinning), dead-reckoned on from there."""
    xyt = odo.xytheta
    d = np.diff(xyt, axis=0)
    c, s = np.cos(xyt[:-1, 2]), np.sin(xyt[:-1, 2])
    u = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    st = odo.stamps_s[1:]
    for t0 in np.atleast_1d(starts_s):
        u[(st >= t0) & (st < t0 + duration_s), :2] *= factor
    out = np.zeros_like(xyt)
    out[0] = xyt[0]
    for i in range(len(u)):  # dead reckoning; sequential by nature
        ci, si = np.cos(out[i, 2]), np.sin(out[i, 2])
        out[i + 1] = out[i] + [ci * u[i, 0] - si * u[i, 1], si * u[i, 0] + ci * u[i, 1], u[i, 2]]
    return OdometryLog(odo.stamps_s, out, odo.v_mps, odo.omega_radps)


def _nees_dof(track: PoseTrack, t: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None):  # noqa: ANN202
    """NEES/dof of ``track`` against the truth (piecewise: a lap's seam is not interpolated across) and
    its 95 % batch-means interval (gtrig.evaluate.gt_aware.batch_interval)."""
    from gtrig.evaluate.gt_aware import batch_interval

    k = np.clip(np.searchsorted(t, track.stamps_s), 1, len(t) - 1)
    a = (track.stamps_s - t[k - 1]) / (t[k] - t[k - 1])
    g = truth[k - 1] + a[:, None] * (truth[k] - truth[k - 1])
    e = track.xytheta() - g
    e[:, 2] = (e[:, 2] + np.pi) % (2 * np.pi) - np.pi
    q = np.einsum("ni,nij,nj->n", e, np.linalg.inv(track.cov), e) / 3
    m = np.ones(len(q), bool) if mask is None else mask
    return batch_interval(q[m]), float(np.hypot(e[m, 0], e[m, 1]).max())


def part_consistency(seeds: list[int], minutes: float, laps: int) -> None:
    """NEES/dof with its 95 % interval per seed and scenario on the synthetic run: the plain run, the
    bridged poses of 3 s gaps cut every 20 s from both sources, and the run made of ``laps`` laps (the
    odometry jumping back at each seam) with and without the jumps cut (FusionOptions.jumps), and the run
    whose wheels slip (30 % too much travel for 0.5 s) once a minute, with and without the slips widened
    (FusionOptions.slip_ratio)."""
    from dataclasses import replace as _replace

    from gtrig.fusion.process import OdometryJumps

    opts = FusionOptions(correlation_s=0.0)  # the synthetic fixes' errors are independent
    never = _replace(opts, jumps=OdometryJumps(max_speed_mps=1e9, max_yaw_rate_radps=1e9))

    def fmt(iv) -> str:  # noqa: ANN001
        return f"{iv.value:.2f} [{iv.low:.2f}, {iv.high:.2f}]"

    print(f"## consistency: synthetic run of {minutes:g} min (odometry 50 Hz, vision 40 Hz, laser 75 Hz)")
    print("| seed | scenario | poses | NEES/dof [95 %] | max pos error (mm) |")
    print("|---|---|---|---|---|")
    for seed in seeds:
        t, truth, odo, tracks = synthetic_hour(minutes / 60.0, seed)
        fx = [fixes_from_track(tr) for tr in tracks]
        fused, _ = fuse(fx, odo, opts)
        iv, mx = _nees_dof(fused, t, truth)
        print(f"| {seed} | fused | {len(fused)} | {fmt(iv)} | {1e3 * mx:.2f} |", flush=True)
        t0 = float(t[0])
        cut = [tr.select(((tr.stamps_s - t0) % 20.0 < 10.0) | ((tr.stamps_s - t0) % 20.0 > 13.0)) for tr in tracks]
        gap, _ = fuse([fixes_from_track(tr) for tr in cut], odo, opts)
        b = gap.status == 2
        iv, mx = _nees_dof(gap, t, truth, b)
        print(f"| {seed} | bridged poses, 3 s gaps every 20 s | {int(b.sum())} | {fmt(iv)} | {1e3 * mx:.2f} |",
              flush=True)
        lt, ltruth, lodo, ltracks = lapped(t, truth, odo, tracks, laps)
        lfx = [fixes_from_track(tr) for tr in ltracks]
        for name, o in (("jumps cut", opts), ("jumps fitted through", never)):
            lf, rep = fuse(lfx, lodo, o)
            iv, mx = _nees_dof(lf, lt, ltruth)
            print(f"| {seed} | {laps} laps, {name} ({len(rep.odometry_jumps_s)} jumps found) "
                  f"| {len(lf)} | {fmt(iv)} | {1e3 * mx:.2f} |", flush=True)
        sodo = slipped(odo, t0 + 30.0 + 60.0 * np.arange(int(minutes)), 0.5, 1.3)
        for name, o in (("slips widened", opts), ("slips fitted through", _replace(opts, slip_ratio=0.0))):
            sf, _ = fuse(fx, sodo, o)
            iv, mx = _nees_dof(sf, t, truth)
            print(f"| {seed} | 30 % slip for 0.5 s every minute, {name} | {len(sf)} | {fmt(iv)} | {1e3 * mx:.2f} |",
                  flush=True)


def _truth_at(truth, stamps_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001 (Trajectory)
    """The true x, y, yaw (n, 3) at ``stamps_s`` and a mask (n,) of the stamps the truth brackets by two
    consecutive samples at its own rate: a recording made of laps jumps back at each seam, where an
    interpolation across the jump would be a pose the robot never had."""
    T = truth.stamps_s
    X = _true_xytheta(truth)
    k = np.clip(np.searchsorted(T, stamps_s), 1, len(T) - 1)
    step = float(np.median(np.diff(T)))
    ok = (stamps_s >= T[0]) & (stamps_s <= T[-1]) & (T[k] - T[k - 1] <= 1.5 * step)
    a = ((stamps_s - T[k - 1]) / (T[k] - T[k - 1]))[:, None]
    return X[k - 1] + a * (X[k] - X[k - 1]), ok


def _track_nees(track: PoseTrack, truth, mask: np.ndarray | None = None):  # noqa: ANN001, ANN202
    """Per-pose NEES/dof (x, y, yaw) of ``track`` where the truth is defined (and ``mask``), and the
    largest position error (m)."""
    g, ok = _truth_at(truth, track.stamps_s)
    ok &= np.ones(len(track), bool) if mask is None else mask
    e = track.xytheta()[ok] - g[ok]
    e[:, 2] = (e[:, 2] + np.pi) % (2 * np.pi) - np.pi
    q = np.einsum("ni,nij,nj->n", e, np.linalg.inv(track.cov_xytheta()[ok]), e) / 3
    return q, float(np.hypot(e[:, 0], e[:, 1]).max()) if len(e) else float("nan")


def part_recording(rec: Path, res: Path, gap_every_s: float = 20.0, gap_s: float = 3.0) -> None:
    """A recording's pipeline results (``gtrig run``; a lapped one from bench/scale.py too) against its
    truth: the fused track's NEES/dof with its 95 % batch-means interval, the bridged poses' over
    ``gap_s`` gaps cut every ``gap_every_s`` from both sources (fused again as the pipeline fuses: sync's
    offsets with their sigmas, each source's run-constant error), the odometry jumps fusion found, and
    every camera's and scanner's clock offset to GTvision's (sync.yaml) against the simulated one."""
    from gtrig.evaluate.gt_aware import batch_interval
    from gtrig.fusion import fuse_tracks
    from gtrig.io.biascov import read_bias_cov
    from gtrig.io.odometry import read_odometry
    from gtrig.io.offsets import read_offsets
    from gtrig.io.posetrack import read_pose_track
    from gtrig.io.tum import read_tum
    from gtrig.io.yamlfile import load_yaml
    from gtrig.pipeline.fusion import BIAS_FILES
    from gtrig.sync.offset import offset_sigmas

    def fmt(q: np.ndarray) -> str:
        iv = batch_interval(q)
        return f"{iv.value:.2f} [{iv.low:.2f}, {iv.high:.2f}]"

    truth = read_tum(rec / "truth" / "run.tum")
    fused = read_pose_track(res / "gt_fused.tum", res / "gt_fused_cov.csv", "fusion")
    report = json.loads((res / "fusion_report.json").read_text(encoding="utf-8"))
    print(f"## {rec} (results {res}): {truth.stamps_s[-1] - truth.stamps_s[0]:.0f} s, "
          f"{len(report.get('odometry_jumps_s', []))} odometry jumps found by fusion")
    print(f"odometry noise: {_noise(report.get('odometry_noise', {}))}")
    print("| track | poses | NEES/dof [95 %] | max pos error (mm) |")
    print("|---|---|---|---|")
    # every pose the track gives as ground truth: measured and bridged alike (a score of the OK poses
    # alone would hide a stretch the fusion lost and bridged)
    q, mx = _track_nees(fused, truth, fused.status != 3)
    print(f"| fused (the pipeline's gt_fused), every pose | {len(q)} | {fmt(q)} | {1e3 * mx:.2f} |", flush=True)
    print(f"| of which bridged (fusion's own gaps) | {int(np.sum(fused.status == 2))} | | |", flush=True)
    tracks = {"vision": read_pose_track(res / "gt_vision_run.tum", res / "gt_vision_run_cov.csv", "vision"),
              "laser": read_pose_track(res / "gt_laser.tum", res / "gt_laser_cov.csv", "laser")}
    sync = res / "sync.yaml"
    offs = {k: v for k, v in read_offsets(sync).items() if k in tracks}
    sig = {k: v for k, v in offset_sigmas(sync).items() if k in offs}
    bias = {k: read_bias_cov(res / f) for k, f in BIAS_FILES.items() if (res / f).is_file()}
    opts = FusionOptions(offsets_s=offs, offsets_sigma_s=sig, bias_cov=bias)
    t0 = float(truth.stamps_s[0])
    phase = {n: (tr.stamps_s - t0) % gap_every_s for n, tr in tracks.items()}
    cut = {n: tr.select((phase[n] < 10.0) | (phase[n] > 10.0 + gap_s)) for n, tr in tracks.items()}
    odo = read_odometry(rec / "run" / "odometry.csv")
    gap, _ = fuse_tracks(cut, odo, opts)
    b = gap.status == 2
    q, mx = _track_nees(gap, truth, b)
    print(f"| bridged poses alone, {gap_s:g} s gaps every {gap_every_s:g} s | {len(q)} | {fmt(q)} | {1e3 * mx:.2f} |",
          flush=True)
    doc = load_yaml(sync) or {}
    lc = rec / "truth" / "laser_clocks.yaml"
    scan = (((load_yaml(lc) or {}).get("run") or {}).get("clock_offsets_s") or {}) if lc.is_file() else {}
    # a lapped recording repeats one lap's sensor data (the same noise draws) lap after lap: its blocks of
    # time are copies, so the jackknife's interval is narrower than one lap's by sqrt(laps), the error not
    laps = len(report.get("odometry_jumps_s", [])) + 1
    print(f"\n| sensor | offset to GTvision's (ms) | 95 % interval | truth (ms) | error (ms) | "
          f"error / half-interval x sqrt(laps {laps}) |")
    print("|---|---|---|---|---|---|")
    for name, v in (doc.get("sources") or {}).items():
        if "offset_to_vision_s" not in v:
            continue
        kind, sensor = name.split("/", 1)
        true = float(scan.get(sensor, float("nan"))) if kind == "laser" else 0.0  # cameras: the GT clock
        if v.get("verdict") != "ok":
            print(f"| {name} | {v.get('verdict')} ({v.get('reason')}) | | {1e3 * true:+.3f} | | |")
            continue
        o, ci = float(v["offset_to_vision_s"]), v.get("ci95_to_vision_s") or [float("nan")] * 2
        half = 0.5 * (float(ci[1]) - float(ci[0])) * np.sqrt(laps)
        print(f"| {name} | {1e3 * o:+.3f} | [{1e3 * ci[0]:+.2f}, {1e3 * ci[1]:+.2f}] | {1e3 * true:+.3f} | "
              f"{1e3 * (o - true):+.3f} | {(o - true) / half:+.2f} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--no-gtsam", action="store_true")
    ap.add_argument("--gtsam-hours", type=float, default=None,
                    help="the peer on a shorter synthetic run (GTSAM's Python graph of 6e5 factors needs > 4 GB)")
    ap.add_argument("--custom-hours", type=float, default=0.01,
                    help="GTSAM on exactly gtrig's factors (Python CustomFactor: slow) on a run this long")
    ap.add_argument("--seeds-root", type=Path, default=None)
    ap.add_argument("--sync", action="store_true", help="with --seeds-root: the clock offsets against the truth")
    ap.add_argument("--sync-mc", type=int, default=0, help="offsets to odometry on this many synthetic runs")
    ap.add_argument("--consistency", action="store_true",
                    help="only the NEES/dof with 95 %% intervals per seed and scenario (plain, bridged, lapped)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--minutes", type=float, default=3.0, help="--consistency: the synthetic run's length")
    ap.add_argument("--laps", type=int, default=3, help="--consistency: laps of the lapped run")
    ap.add_argument("--recording", type=Path, default=None,
                    help="with --results: a recording's pipeline results against its truth (fused, bridged, offsets)")
    ap.add_argument("--results", type=Path, default=None, help="the results folder of --recording (gtrig run)")
    a = ap.parse_args(argv)
    if a.consistency:
        part_consistency(a.seeds, a.minutes, a.laps)
        return 0
    if a.recording is not None:
        if a.results is None:
            ap.error("--recording needs --results")
        part_recording(a.recording, a.results)
        return 0
    if a.seeds_root is not None:
        part_seeds(a.seeds_root)
        if a.sync:
            part_sync(a.seeds_root)
    if a.sync_mc:
        part_sync_mc(a.sync_mc)
    _, _, odo, tracks = part_speed(a.hours)
    if not a.no_gtsam:
        if a.gtsam_hours is not None:
            _, _, odo, tracks = synthetic_hour(a.gtsam_hours)
            small = synthetic_hour(0.005)  # compile the kernels for the snapped chain outside the timing
            sc, sx, sk = snapped_chain(small[2], small[3])
            smooth_batch(sc, sx, sk, huber_k=0.0)
        part_gtsam(odo, tracks)
        if a.custom_hours > 0:
            _, _, odo, tracks = synthetic_hour(a.custom_hours)
            part_gtsam_custom(odo, tracks)
    return 0


if __name__ == "__main__":
    sys.exit(main())
