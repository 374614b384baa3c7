"""The outdoor scenario: a robot on a campus with an RTK-GPS receiver and wheel odometry, with truth.

``gtrig sim --scenario outdoor`` writes::

    gps/gps.log          RAWSEEDS layout "log_clock, $GPGGA..." + $GPGST + $GPRMC at 5 Hz (full checksums)
    odometry/odometry.csv  wheel odometry at 20 Hz (docs/formats.md), on the UTC clock
    truth/robot.tum      the robot frame in the local ENU (origin in truth/outdoor.json), UTC stamps
    truth/antenna.tum    the antenna (robot frame + lever arm), same stamps
    truth/gps_truth.csv  per GPS epoch: utc, visible satellites, fix quality, outlier flag, true error (E, N, U)
    truth/outdoor.json   origin (lat, lon, h), lever arm, buildings, the odometry's true errors

Physics (docs/gps.md, "Simulator"):

- the campus: blocks of buildings (footprint rectangles with heights 10-30 m, 12 m streets) along streets, and an open
  lawn; the path runs along the streets at walking speed with rounded corners;
- the sky mask: a constellation of satellites (azimuth, elevation, drifting slowly); one is seen when
  the ray from the antenna to it clears every building (2-D slab entry distance times tan(elevation)
  above the roof height);
- the fix: 6 or more satellites seen for ``t_fix_s`` since the last drop: RTK fixed; 4 or 5 (or not
  yet re-fixed): RTK float; fewer: no fix (GGA quality 0 without a position, no GST);
- errors drawn from the covariance the GST reports (a Gauss-Markov process of time constant
  ``tau_s``, so consecutive fixes share their error as real ones do), sigmas growing as the satellite
  count falls; in float, multipath outliers (a 1.5-5 m reflected-path offset over a few epochs)
  that the receiver's sigmas do not show;
- the ground: roll and pitch wander (Gauss-Markov, 2 deg, 3 s), so the antenna on its 0.6 m mast
  moves about 2 cm about the point above the robot frame;
- odometry: distance scale, turn scale and a curvature bias (a wheel radius difference), plus slip.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gtrig.io.atomic import atomic_write_text
from gtrig.io.odometry import OdometryLog, write_odometry_csv
from gtrig.trajectory import PoseTrack

ORIGIN = (45.5062, 9.1662, 160.0)  # a campus in Milan (lat, lon deg; ellipsoidal height m)
T0_UNIX_S = 1223134000.0  # 2008-10-04 15:26:40 UTC
LEVER_ARM_M = (-0.20, 0.05, 0.60)  # the antenna in the robot frame (x forward, y left, z up)


@dataclass(frozen=True)
class OutdoorParams:
    """The outdoor scenario's settings."""

    duration_s: float = 420.0
    speed_mps: float = 1.0
    gps_rate_hz: float = 5.0
    odo_rate_hz: float = 20.0
    n_sats: int = 9
    min_fixed: int = 6
    min_float: int = 4
    t_fix_s: float = 6.0
    tau_s: float = 8.0
    sigma_fixed_m: float = 0.012
    sigma_float_m: float = 0.25
    outlier_rate_hz: float = 0.1
    log_latency_s: float = 0.020
    tilt_sigma_deg: float = 2.0
    tilt_tau_s: float = 3.0


def _buildings(rng: np.random.Generator) -> np.ndarray:
    """(B, 5) rows ``xmin, ymin, xmax, ymax, height``: a 4 x 3 grid of blocks, one left open (the lawn)."""
    out = []
    for i in range(4):
        for j in range(3):
            if (i, j) == (1, 1):
                continue
            x0, y0 = -60 + i * 50 + 6, -40 + j * 45 + 6
            out.append([x0, y0, x0 + 38, y0 + 33, rng.uniform(10, 30)])
    return np.array(out)


def _path(duration_s: float, speed: float, rng: np.random.Generator, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(stamps (N,), x y yaw (N, 3)) along the street centres (x = -60 + 50 i, y = -40 + 45 j), corners rounded."""
    ways = np.array([[-60, -40], [90, -40], [90, 50], [40, 50], [40, 5], [-10, 5], [-10, 50], [-60, 50], [-60, -40],
                     [40, -40], [40, 50], [-60, 50]], float)
    k = int(rng.integers(0, 4))
    ways = np.concatenate([ways[k:], ways[1:k + 1]]) if k else ways
    seg = np.linalg.norm(np.diff(ways, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    fine = np.arange(0, s[-1], 0.05)
    xy = np.column_stack([np.interp(fine, s, ways[:, 0]), np.interp(fine, s, ways[:, 1])])
    # round the corners: a moving average over 6 m
    w = 120
    pad = np.concatenate([np.repeat(xy[:1], w, 0), xy, np.repeat(xy[-1:], w, 0)])
    ker = np.ones(2 * w + 1) / (2 * w + 1)
    xy = np.column_stack([np.convolve(pad[:, 0], ker, "valid"), np.convolve(pad[:, 1], ker, "valid")])
    arc = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    t = np.arange(0, duration_s, dt)
    # a gently varying speed, with a 10 s stop a third of the way
    v = speed * (1 + 0.2 * np.sin(2 * np.pi * t / 37.0))
    v[(t > duration_s / 3) & (t < duration_s / 3 + 10)] = 0.0
    dist = np.minimum(np.concatenate([[0], np.cumsum(v[:-1] * dt)]), arc[-1] - 0.01)
    x, y = np.interp(dist, arc, xy[:, 0]), np.interp(dist, arc, xy[:, 1])
    yaw = np.unwrap(np.arctan2(np.interp(dist + 0.3, arc, xy[:, 1]) - y, np.interp(dist + 0.3, arc, xy[:, 0]) - x))
    return t, np.column_stack([x, y, yaw])


def visible(xy: np.ndarray, az: np.ndarray, el: np.ndarray, buildings: np.ndarray) -> np.ndarray:
    """(N, S) bool: satellite s seen from antenna position xy[n] (height ``LEVER_ARM_M[2]``) past the buildings.

    The ray's horizontal direction (sin az, cos az) enters a footprint at distance ``t_in`` (slab
    method); the building blocks it when ``t_in tan(el) + antenna height < roof height``.
    """
    d = np.stack([np.sin(az), np.cos(az)], -1)  # (N, S, 2) east, north
    p = xy[:, None, :]
    seen = np.ones(az.shape, bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        for bx0, by0, bx1, by1, h in buildings:
            tx1, tx2 = (bx0 - p[..., 0]) * inv[..., 0], (bx1 - p[..., 0]) * inv[..., 0]
            ty1, ty2 = (by0 - p[..., 1]) * inv[..., 1], (by1 - p[..., 1]) * inv[..., 1]
            t_in = np.maximum(np.minimum(tx1, tx2), np.minimum(ty1, ty2))
            t_out = np.minimum(np.maximum(tx1, tx2), np.maximum(ty1, ty2))
            hit = (t_out >= np.maximum(t_in, 0)) & (np.maximum(t_in, 0) * np.tan(el) + LEVER_ARM_M[2] < h)
            seen &= ~hit
    return seen


def _gauss_markov(rng: np.random.Generator, n: int, dt: float, tau: float) -> np.ndarray:
    """(n, 3) unit-variance first-order Gauss-Markov samples."""
    a = np.exp(-dt / tau)
    w = rng.standard_normal((n, 3)) * np.sqrt(1 - a * a)
    x = np.empty((n, 3))
    x[0] = rng.standard_normal(3)
    for i in range(1, n):
        x[i] = a * x[i - 1] + w[i]
    return x


def _antenna(pose: np.ndarray, tilt: np.ndarray) -> np.ndarray:
    """(N, 3) the antenna in ENU: robot pose ``x, y, yaw`` (N, 3) with roll, pitch (N, 2) applied to the lever arm."""
    from scipy.spatial.transform import Rotation

    R = Rotation.from_euler("ZYX", np.column_stack([pose[:, 2], tilt[:, 1], tilt[:, 0]]))
    return np.column_stack([pose[:, :2], np.zeros(len(pose))]) + R.apply(np.asarray(LEVER_ARM_M))


def _checksum(body: str) -> str:
    x = 0
    for ch in body.encode():
        x ^= ch
    return f"{x:02X}"


def _ddmm(v: float, pos: str, neg: str, width: int) -> tuple[str, str]:
    h = pos if v >= 0 else neg
    v = abs(v)
    d = int(v)
    m = (v - d) * 60.0
    return f"{d:0{width}d}{m:011.8f}", h


def _hms(utc: float) -> str:
    s = utc % 86400.0
    hh, mm = int(s // 3600), int(s % 3600 // 60)
    return f"{hh:02d}{mm:02d}{s - hh * 3600 - mm * 60:05.2f}"


def simulate_outdoor(out_dir: str | Path, seed: int = 0, quick: bool = False, params: OutdoorParams | None = None,
                     ) -> dict[str, float]:
    """Write the outdoor recording (module docstring) into ``out_dir``; returns summary figures."""
    prm = params or OutdoorParams(duration_s=120.0 if quick else 420.0)
    rng = np.random.default_rng(seed)
    out = Path(out_dir)
    bld = _buildings(rng)
    dt_o = 1.0 / prm.odo_rate_hz
    t_o, pose = _path(prm.duration_s, prm.speed_mps, rng, dt_o)
    # GPS epochs on the UTC grid
    t_g = np.arange(0.0, t_o[-1], 1.0 / prm.gps_rate_hz)
    # the ground is not flat: roll and pitch wander (kerbs, camber, braking), tilting the antenna mast
    tilt = _gauss_markov(rng, t_o.size, dt_o, prm.tilt_tau_s)[:, :2] * np.radians(prm.tilt_sigma_deg)
    antenna_o = _antenna(pose, tilt)
    ant = np.column_stack([np.interp(t_g, t_o, antenna_o[:, k]) for k in range(3)])
    n_vis = _visible_satellites(rng, prm, t_g, ant, bld)
    quality = _fix_quality(t_g, n_vis, prm)
    fix = _fix_errors(rng, prm, t_g, n_vis, quality)
    utc = T0_UNIX_S + t_g
    log_t = utc + prm.log_latency_s + rng.uniform(-0.004, 0.004, t_g.size)
    lines = _nmea_lines(utc, log_t, ant + fix.err_enu, ant, t_g, n_vis, quality, fix)
    (out / "gps").mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "gps" / "gps.log", "\n".join(lines) + "\n")
    odo, odo_errors = _odometry(rng, t_o, pose, dt_o)
    (out / "odometry").mkdir(parents=True, exist_ok=True)
    write_odometry_csv(out / "odometry" / "odometry.csv", odo)
    _write_truth(out, t_o, pose, antenna_o, utc, n_vis, quality, fix)
    meta = {"origin": {"lat_deg": ORIGIN[0], "lon_deg": ORIGIN[1], "h_m": ORIGIN[2]}, "lever_arm_m": LEVER_ARM_M,
            "t0_unix_s": T0_UNIX_S, "seed": seed, "buildings": bld.tolist(),
            "odometry_errors": odo_errors,
            "log_latency_s": prm.log_latency_s,
            "tilt_sigma_deg": prm.tilt_sigma_deg}
    atomic_write_text(out / "truth" / "outdoor.json", json.dumps(meta, indent=1) + "\n")
    share = {f"q{q}": float(np.mean(quality == q)) for q in (0, 4, 5)}
    return {"epochs": float(t_g.size), **share, "outliers": float(fix.outlier.sum())}


def _visible_satellites(rng: np.random.Generator, prm: OutdoorParams, t_g: np.ndarray, ant: np.ndarray,
                        bld: np.ndarray) -> np.ndarray:
    """Satellites (G,) in view of the antenna at each epoch: azimuths uniform, elevations uniform over the
    sky's solid angle above 10 deg, drifting; the buildings block the rest."""
    az0 = rng.uniform(0, 2 * np.pi, prm.n_sats)
    el0 = np.arcsin(rng.uniform(np.sin(np.radians(10)), np.sin(np.radians(85)), prm.n_sats))
    drift = np.radians(0.25 / 60.0) * rng.choice([-1, 1], prm.n_sats)
    az = az0[None] + drift[None] * t_g[:, None]
    el = np.clip(el0[None] + 0.3 * drift[None] * t_g[:, None], np.radians(5), np.radians(85))
    return visible(ant[:, :2], az, el, bld).sum(axis=1)


def _fix_quality(t_g: np.ndarray, n_vis: np.ndarray, prm: OutdoorParams) -> np.ndarray:
    """GGA quality (G,) int8: RTK fixed (4) once ``min_fixed`` satellites have been seen for ``t_fix_s``,
    float (5) with ``min_float`` or more, none (0) below."""
    quality = np.zeros(t_g.size, np.int8)
    since = -1e9
    for i in range(t_g.size):
        if n_vis[i] >= prm.min_fixed:
            if since < -1e8:
                since = t_g[i]
            quality[i] = 4 if t_g[i] - since >= prm.t_fix_s else 5
        elif n_vis[i] >= prm.min_float:
            since = -1e9
            quality[i] = 5
        else:
            since = -1e9
            quality[i] = 0
    return quality


@dataclass(frozen=True)
class _FixErrors:
    """The receiver's stated error model per epoch and the error drawn from it (ENU, metres).

    ``geom`` (G,) the geometry factor; ``base`` (G,) the stated sigma; ``a_m``, ``b_m`` (G,) the error
    ellipse's semi-axes; ``orient_rad`` (G,) its orientation from north; ``sig_alt`` (G,); ``cov_enu``
    (G, 3, 3); ``err_enu`` (G, 3); ``outlier`` (G,) epochs offset by a multipath reflection.
    """

    geom: np.ndarray
    base: np.ndarray
    a_m: np.ndarray
    b_m: np.ndarray
    orient_rad: np.ndarray
    sig_alt: np.ndarray
    cov_enu: np.ndarray
    err_enu: np.ndarray
    outlier: np.ndarray


def _fix_errors(rng: np.random.Generator, prm: OutdoorParams, t_g: np.ndarray, n_vis: np.ndarray,
                quality: np.ndarray) -> _FixErrors:
    """The stated covariance per epoch (GST), a Gauss-Markov error drawn from it, and multipath outliers."""
    geom = np.sqrt(6.0 / np.maximum(n_vis, 4))
    base = np.where(quality == 4, prm.sigma_fixed_m, prm.sigma_float_m) * geom
    aniso = 1.4  # semi-axes 1.4 and 1/1.4 of the base sigma; N-S worse than E-W (the northern sky hole)
    orient = np.radians(np.interp(t_g, [0, t_g[-1] + 1], rng.uniform(-30, 30, 2)))  # major axis near north
    # the covariance the error is drawn from is the one the GST sentence states, to its printed digits
    # (mm, 0.1 deg): with the unrounded one a 7.4 mm semi-minor axis printed as 7 mm under-reports
    # by 6 %, a bias of the simulated receiver, not of its physics
    a_m, b_m = np.round(base * aniso, 3), np.round(base / aniso, 3)
    orient = np.radians(np.round(np.degrees(orient) % 180.0, 1))
    sig_alt = np.round(1.8 * base, 3)
    uE, uN = np.sin(orient), np.cos(orient)
    cov = np.zeros((t_g.size, 3, 3))
    cov[:, 0, 0] = a_m**2 * uE**2 + b_m**2 * uN**2
    cov[:, 1, 1] = a_m**2 * uN**2 + b_m**2 * uE**2
    cov[:, 0, 1] = cov[:, 1, 0] = (a_m**2 - b_m**2) * uE * uN
    cov[:, 2, 2] = sig_alt**2
    L = np.linalg.cholesky(cov + 1e-12 * np.eye(3))
    z = _gauss_markov(rng, t_g.size, 1.0 / prm.gps_rate_hz, prm.tau_s)
    err = np.einsum("nij,nj->ni", L, z)
    # multipath outliers in float: a reflected path offsets the fix by 1.5-5 m for 1-4 epochs
    outlier = np.zeros(t_g.size, bool)
    starts = np.flatnonzero((quality == 5) & (rng.uniform(size=t_g.size) < prm.outlier_rate_hz / prm.gps_rate_hz))
    for i in starts.tolist():
        k = int(rng.integers(1, 5))
        ang = rng.uniform(0, 2 * np.pi)
        mag = rng.uniform(1.5, 5.0)
        sl = slice(i, min(i + k, t_g.size))
        m = quality[sl] == 5
        err[sl][m] += mag * np.array([np.cos(ang), np.sin(ang), 0.3])
        outlier[sl] |= m
    return _FixErrors(geom, base, a_m, b_m, orient, sig_alt, cov, err, outlier)


def _nmea_lines(utc: np.ndarray, log_t: np.ndarray, meas_enu: np.ndarray, ant: np.ndarray, t_g: np.ndarray,
                n_vis: np.ndarray, quality: np.ndarray, fix: _FixErrors) -> list[str]:
    """The receiver's log: GGA, GST (when fixed or float) and RMC per epoch, each stamped on the logger's
    clock (``log_t``), positions ``meas_enu`` (G, 3) in the local ENU frame at :data:`ORIGIN`."""
    from pyproj import Transformer

    tr = Transformer.from_pipeline(
        f"+proj=pipeline +step +proj=cart +ellps=WGS84 +step +proj=topocentric +ellps=WGS84 +lat_0={ORIGIN[0]} "
        f"+lon_0={ORIGIN[1]} +h_0={ORIGIN[2]}")
    lon, lat, h = tr.transform(meas_enu[:, 0], meas_enu[:, 1], meas_enu[:, 2], direction="INVERSE")
    geoid_sep = 48.022
    speed = np.hypot(np.gradient(ant[:, 0], t_g), np.gradient(ant[:, 1], t_g))
    course = np.degrees(np.arctan2(np.gradient(ant[:, 0], t_g), np.gradient(ant[:, 1], t_g))) % 360
    cov, geom = fix.cov_enu, fix.geom
    lines = []
    for i in range(t_g.size):
        hms = _hms(utc[i])
        la, ns = _ddmm(lat[i], "N", "S", 2)
        lo, ew = _ddmm(lon[i], "E", "W", 3)
        q = int(quality[i])
        if q:
            gga = (f"GPGGA,{hms},{la},{ns},{lo},{ew},{q},{int(n_vis[i]):02d},{0.9 * geom[i]:.1f},"
                   f"{h[i] - geoid_sep:.3f},M,{geoid_sep:.3f},M,1.0,0000")
        else:
            gga = f"GPGGA,{hms},,,,,0,{int(n_vis[i]):02d},,,M,,M,,"
        lines.append(f"{log_t[i]:.6f}, ${gga}*{_checksum(gga)}")
        if q:
            gst = (f"GPGST,{hms},{fix.base[i]:.3f},{fix.a_m[i]:.3f},{fix.b_m[i]:.3f},"
                   f"{np.degrees(fix.orient_rad[i]) % 180:.1f},"
                   f"{np.sqrt(cov[i, 1, 1]):.3f},{np.sqrt(cov[i, 0, 0]):.3f},{fix.sig_alt[i]:.3f}")
            lines.append(f"{log_t[i] + 0.010:.6f}, ${gst}*{_checksum(gst)}")
        day = np.datetime64(int(utc[i]), "s").astype(object)
        rmc = (f"GPRMC,{hms},{'A' if q else 'V'},{la},{ns},{lo},{ew},{speed[i] / 0.514444:.2f},{course[i]:.1f},"
               f"{day.strftime('%d%m%y')},,,{'R' if q in (4, 5) else 'N'}")
        lines.append(f"{log_t[i] + 0.015:.6f}, ${rmc}*{_checksum(rmc)}")
    return lines


def _odometry(rng: np.random.Generator, t_o: np.ndarray, pose: np.ndarray, dt_o: float,
              ) -> tuple[OdometryLog, dict[str, float]]:
    """Wheel odometry integrated at its rate from the true path ``pose`` (N, 3: x, y m, theta rad) with a
    scale, turn-scale and curvature error plus slip noise; returns the log and the drawn errors."""
    ds = np.hypot(np.diff(pose[:, 0]), np.diff(pose[:, 1]))
    dth = np.diff(pose[:, 2])
    e_scale, e_turn, e_curv = rng.normal(0, 0.01), rng.normal(0, 0.02), rng.normal(0, 0.004)
    ds_m = ds * (1 + e_scale) + rng.normal(0, 0.002, ds.size) * np.sqrt(ds)
    dth_m = dth * (1 + e_turn) + e_curv * ds + rng.normal(0, 0.002, ds.size) * np.sqrt(ds) / 0.5
    th = np.concatenate([[0.0], np.cumsum(dth_m)])
    mid = th[:-1] + 0.5 * dth_m
    xo = np.concatenate([[0.0], np.cumsum(ds_m * np.cos(mid))])
    yo = np.concatenate([[0.0], np.cumsum(ds_m * np.sin(mid))])
    odo = OdometryLog(T0_UNIX_S + t_o, np.column_stack([xo, yo, th]), np.concatenate([ds_m / dt_o, [0.0]]),
                      np.concatenate([dth_m / dt_o, [0.0]]))
    return odo, {"scale": e_scale, "turn_scale": e_turn, "curvature_rad_per_m": e_curv}


def _write_truth(out: Path, t_o: np.ndarray, pose: np.ndarray, antenna_o: np.ndarray, utc: np.ndarray,
                 n_vis: np.ndarray, quality: np.ndarray, fix: _FixErrors) -> None:
    """``truth/robot.tum``, ``truth/antenna.tum`` and ``truth/gps_truth.csv`` (each epoch's drawn error)."""
    from gtrig.io.tum import write_tum

    (out / "truth").mkdir(parents=True, exist_ok=True)
    write_tum(out / "truth" / "robot.tum", PoseTrack.from_xytheta(T0_UNIX_S + t_o, pose))
    level = np.tile([0, 0, 0, 1.0], (t_o.size, 1))
    write_tum(out / "truth" / "antenna.tum", PoseTrack(T0_UNIX_S + t_o, antenna_o, level))
    err, outlier = fix.err_enu, fix.outlier
    rows = ["utc_s,n_visible,quality,outlier,err_e,err_n,err_u"] + [
        f"{utc[i]:.3f},{int(n_vis[i])},{int(quality[i])},{int(outlier[i])},"
        f"{err[i, 0]:.5f},{err[i, 1]:.5f},{err[i, 2]:.5f}"
        for i in range(utc.size)]
    atomic_write_text(out / "truth" / "gps_truth.csv", "\n".join(rows) + "\n")
