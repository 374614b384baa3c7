"""The whole camera calibration of a recording: image folders in, calibrated rig and report out.

Layout (docs/formats.md): ``calib/boards.yaml``, ``calib/intrinsics/<cam>/*.png``,
``calib/pairs/<camA>-<camB>/<camA|camB>/<n>.png`` (same ``<n>`` = same instant) and
``calib/world_board/<cam>/*.png``. :func:`calibrate_recording` is what ``gtrig demo`` calls.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from gtrig import geometry as geo
from gtrig.calib.chessboard import Board, BoardsSpec, detect_corners, list_images, read_boards_yaml, read_grey
from gtrig.calib.id_sweep import load_id_intrinsics
from gtrig.calib.intrinsics import IntrinsicsResult, calibrate_intrinsics
from gtrig.calib.network import (
    NetworkProblem,
    NetworkResult,
    PairView,
    SweepView,
    WorldView,
    calibrate_network,
)
from gtrig.errors import InputError
from gtrig.io.atomic import atomic_write_text
from gtrig.io.camfile import CameraIntrinsics, read_cam_yaml
from gtrig.rig.load import load_rig
from gtrig.rig.models import Pose, Rig, pose_cov_rows

log = logging.getLogger(__name__)


def split_pair_name(name: str, cameras: Sequence[str]) -> tuple[str, str]:
    """``"camA-camB"`` into two rig camera names (names may themselves contain ``-``)."""
    for i, ch in enumerate(name):
        if ch == "-" and name[:i] in cameras and name[i + 1 :] in cameras:
            return name[:i], name[i + 1 :]
    raise InputError(
        f"pairs/{name}: the folder name must be <camA>-<camB> with two rig cameras ({', '.join(cameras)})"
    )


def _image_map(folder: Path) -> dict[str, Path]:
    return {p.stem: p for p in list_images(folder)}


def load_pair_views(
    pairs_dir: str | os.PathLike[str],
    board: Board,
    cameras: Sequence[str],
    image_sizes: Mapping[str, tuple[int, int]] | None = None,
) -> list[PairView]:
    """Detect the double board in every pair folder.

    Raises
    ------
    InputError
        A folder not named after two rig cameras; image names of the two cameras that do not match; a
        pair where both boards are never found together.
    """
    root = Path(pairs_dir)
    if not root.is_dir():
        raise InputError(f"{root}: no such folder")
    out: list[PairView] = []
    for d in sorted(p for p in root.iterdir() if p.is_dir()):
        a, b = split_pair_name(d.name, cameras)
        for c in (a, b):
            if not (d / c).is_dir():
                raise InputError(f"{d}: missing sub-folder {c}/ (expected {a}/ and {b}/)")
        ma, mb = _image_map(d / a), _image_map(d / b)
        only_a, only_b = sorted(set(ma) - set(mb)), sorted(set(mb) - set(ma))
        if only_a or only_b:
            cam, other, name = (a, b, ma[only_a[0]].name) if only_a else (b, a, mb[only_b[0]].name)
            more = len(only_a) + len(only_b) - 1
            raise InputError(
                f"{d}: pair names do not match: {cam}/{name} has no partner in {other}/"
                + (f" (and {more} more)" if more else "")
            )
        n_ok = 0
        for stem in sorted(ma):
            ia, ib = read_grey(ma[stem]), read_grey(mb[stem])
            for c, img, p in ((a, ia, ma[stem]), (b, ib, mb[stem])):
                if image_sizes and c in image_sizes and (img.shape[1], img.shape[0]) != tuple(image_sizes[c]):
                    w, h = image_sizes[c]
                    raise InputError(
                        f"{p}: mixed resolutions: {img.shape[1]} x {img.shape[0]}, but camera {c} "
                        f"is {w} x {h}"
                    )
            ca, cb = detect_corners(ia, board), detect_corners(ib, board)
            if ca is None or cb is None:
                log.warning(
                    "%s: board %s not found in %s, instant skipped",
                    d.name,
                    "1" if ca is None else "2",
                    ma[stem].name if ca is None else mb[stem].name,
                )
                continue
            out.append(PairView(a, b, ma[stem].name, ca, cb))
            n_ok += 1
        if n_ok == 0:
            raise InputError(
                f"{d}: board 1 in {a} and board 2 in {b} were found together in none of "
                f"{len(ma)} image pair(s)"
            )
    if not out:
        raise InputError(f"{root}: no pair folders (<camA>-<camB>/<camA>/, <camB>/)")
    return out


def load_world_views(
    world_dir: str | os.PathLike[str], board: Board, cameras: Sequence[str], T_world_board: np.ndarray
) -> list[WorldView]:
    """Detect the world board in ``world_dir/<cam>/*``; images without a board are skipped (warning)."""
    root = Path(world_dir)
    if not root.is_dir():
        raise InputError(f"{root}: no such folder")
    out: list[WorldView] = []
    for d in sorted(p for p in root.iterdir() if p.is_dir()):
        if d.name not in cameras:
            raise InputError(f"{d}: not a rig camera ({', '.join(cameras)})")
        for p in list_images(d):
            c = detect_corners(read_grey(p), board)
            if c is None:
                log.warning("%s: no %dx%d board found, skipped", p, board.cols, board.rows)
                continue
            out.append(WorldView(d.name, p.name, c, T_world_board))
    if not out:
        raise InputError(f"{root}: the world board was found in no image")
    return out


def load_intrinsics(
    source: str | os.PathLike[str], cameras: Sequence[str], board: Board, *, estimate_k3: bool = False
) -> dict[str, CameraIntrinsics | IntrinsicsResult]:
    """Intrinsics per camera from ``source``: ``<cam>.yaml`` files (from ``gtrig calib intrinsics``) or
    ``<cam>/`` image folders (calibrated here). Cameras with neither are left out."""
    root = Path(source)
    if not root.is_dir():
        raise InputError(f"{root}: no such folder")
    out: dict[str, CameraIntrinsics | IntrinsicsResult] = {}
    for c in cameras:
        f = root / f"{c}.yaml"
        if f.is_file():
            out[c] = read_cam_yaml(f)
        elif (root / c).is_dir():
            out[c] = calibrate_intrinsics(root / c, board, estimate_k3=estimate_k3, camera=c)
    if not out:
        raise InputError(f"{root}: no <cam>.yaml and no <cam>/ image folder for any of {', '.join(cameras)}")
    return out


def as_intrinsics(x: CameraIntrinsics | IntrinsicsResult) -> CameraIntrinsics:
    """The lens of a calibration's result, or the lens itself."""
    return x.camera if isinstance(x, IntrinsicsResult) else x


def sweep_views(intrinsics: Mapping[str, CameraIntrinsics | IntrinsicsResult]) -> list[SweepView]:
    """The views used by each single-camera calibration, with their board poses, for the network's
    bundle adjustment to refine the lenses from (cameras calibrated from a ``cam.yaml`` have none)."""
    out: list[SweepView] = []
    for n, x in sorted(intrinsics.items()):
        if isinstance(x, IntrinsicsResult):
            out += [SweepView(n, v.file, v.corners_px, T) for v, T in zip(x.views, x.T_cam_board, strict=True)]
    return out


def calibrated_rig(
    rig: Rig, intrinsics: Mapping[str, CameraIntrinsics | IntrinsicsResult], network: NetworkResult | None
) -> Rig:
    """The rig with each camera's intrinsics and (jointly estimated) ``T_world_cam`` and their joint
    ``pose_cov`` replaced; the lenses refined by the network's bundle adjustment take precedence over the
    single-camera ones."""
    cams = []
    for c in rig.cameras:
        upd: dict[str, Any] = {}
        refined = network.joint[c.name].intrinsics if network is not None and c.name in network.joint else None
        if refined is not None or c.name in intrinsics:
            ci = refined if refined is not None else as_intrinsics(intrinsics[c.name])
            if tuple(ci.image_size) != tuple(c.resolution):
                raise InputError(
                    f"camera {c.name}: its intrinsics (from its calibration images) are for {ci.image_size[0]} x "
                    f"{ci.image_size[1]} images but the rig's cameras.{c.name}.resolution is {c.resolution[0]} x "
                    f"{c.resolution[1]}"
                )
            K = np.asarray(ci.camera_matrix, dtype=float)
            upd["camera_matrix"] = tuple(tuple(float(v) for v in row) for row in K)
            upd["dist_coeffs"] = tuple(float(v) for v in np.asarray(ci.dist_coeffs).ravel())
        if network is not None and c.name in network.joint:
            upd["T_world_cam"] = Pose.from_matrix(network.joint[c.name].T_world_cam)
            # the network's blocks are [w, v, lens]; the rig's pose_cov is [v, w, lens] (centre first)
            cp = network.joint[c.name]
            C = cp.cov_pose_intrinsics if cp.cov_pose_intrinsics is not None else cp.cov
            order = np.r_[3:6, 0:3, 6:C.shape[0]]
            upd["pose_cov"] = pose_cov_rows(C[np.ix_(order, order)])
        cams.append(c.model_copy(update=upd))
    return rig.model_copy(update={"cameras": tuple(cams)})


@dataclass(frozen=True)
class CalibrationReport:
    """Everything measured by :func:`calibrate_recording`.

    Attributes
    ----------
    intrinsics : {camera: IntrinsicsResult or CameraIntrinsics}.
    network : the extrinsic calibration (joint and chain).
    truth : when a true rig is known (simulation): per camera the joint and chain errors and the
        intrinsics errors (mm, deg, px); else empty.
    """

    intrinsics: dict[str, CameraIntrinsics | IntrinsicsResult]
    network: NetworkResult
    truth: dict[str, dict[str, float]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        intr = {}
        for n, x in self.intrinsics.items():
            c = as_intrinsics(x)
            std = c.extra.get("std", {})
            intr[n] = {
                "fx": float(c.camera_matrix[0, 0]),
                "fy": float(c.camera_matrix[1, 1]),
                "cx": float(c.camera_matrix[0, 2]),
                "cy": float(c.camera_matrix[1, 2]),
                "rms_px": float(c.rms_px),
                "std": std,
                "rejected": c.extra.get("rejected", {}),
                "warnings": c.extra.get("warnings", []),
            }
        return {"intrinsics": intr, "network": self.network.to_dict(), "truth": self.truth}

    def to_markdown(self) -> str:
        """A human-readable report: intrinsics, joint vs chain, uncertainties, residuals, truth."""
        L = ["# Camera calibration report"]
        L += self._intrinsics_md() + self._refined_intrinsics_md() + self._poses_md() + self._pairs_md()
        L += self._truth_md() + self._warnings_md()
        return "\n".join(L) + "\n"

    def _intrinsics_md(self) -> list[str]:
        """The intrinsics' table, one row per camera."""
        rows = []
        for n, x in sorted(self.intrinsics.items()):
            c = as_intrinsics(x)
            K, d = c.camera_matrix, c.dist_coeffs
            rows.append(
                f"| {n} | {K[0, 0]:.2f} | {K[1, 1]:.2f} | {K[0, 2]:.2f} | {K[1, 2]:.2f} | {d[0]:.4f} | "
                f"{d[1]:.4f} | {c.rms_px:.3f} | {c.extra.get('views_used', '')} | "
                f"{len(c.extra.get('rejected', {}))} |"
            )
        return _md_table(("camera", "fx", "fy", "cx", "cy", "k1", "k2", "RMS (px)", "views", "rejected"), rows,
                         "Intrinsics")

    def _refined_intrinsics_md(self) -> list[str]:
        """The intrinsics the network bundle adjustment refined, with their sigmas (none: no lines)."""
        net = self.network
        refined = {n: j.intrinsics for n, j in sorted(net.joint.items()) if j.intrinsics is not None}
        if not any(ji.extra.get("refined_in_network") for ji in refined.values()):
            return []
        rows = []
        for n, ji in refined.items():
            K, sd = ji.camera_matrix, ji.extra.get("std", {})
            sigmas = ", ".join(f"{sd.get(k, np.nan):.2f}" for k in ("fx", "fy", "cx", "cy"))
            rows.append(f"| {n} | {K[0, 0]:.2f} | {K[1, 1]:.2f} | {K[0, 2]:.2f} | {K[1, 2]:.2f} | {sigmas} | "
                        f"{net.joint[n].rms_px_sweep:.3f} |")
        return _md_table(("camera", "fx", "fy", "cx", "cy", "sigma fx, fy, cx, cy (px)", "sweep RMS in the BA (px)"),
                         rows, "Intrinsics refined in the network bundle adjustment (sweeps, pairs, world board)")

    def _poses_md(self) -> list[str]:
        """The cameras' poses of the joint adjustment, their sigmas, and how far the chain's are from them."""
        net = self.network
        rows = []
        for n, cp in sorted(net.joint.items()):
            dch, rch = geo.pose_error(net.chain[n], cp.T_world_cam)
            rot = ", ".join(f"{np.degrees(v):.4f}" for v in cp.sigma_rot_rad)
            if cp.sigma_rot_rad_fixed_intrinsics is not None:
                rot += f" ({', '.join(f'{np.degrees(v):.4f}' for v in cp.sigma_rot_rad_fixed_intrinsics)})"
            rows.append(
                f"| {n} | {' > '.join(net.chain_path[n])} | "
                f"{', '.join(f'{v:.4f}' for v in cp.T_world_cam[:3, 3])} | "
                f"{', '.join(f'{v * 1000:.2f}' for v in cp.sigma_pos_m)} | {rot} | {cp.rms_px:.3f} | "
                f"{dch * 1000:.2f} / {np.degrees(rch):.4f} |"
            )
        return _md_table(("camera", "chain path", "x, y, z (m)", "sigma pos (mm)", "sigma rot (deg)", "RMS (px)",
                          "chain - joint (mm / deg)"), rows,
                         "Camera poses: joint bundle adjustment vs chain (the seeds' method)",
                         "Sigmas include the intrinsics' uncertainty; in brackets, the rotation's with the lenses "
                         "held.")

    def _pairs_md(self) -> list[str]:
        """The camera pairs' and world board's residuals, the double board and the overall residual."""
        net = self.network
        rows = [f"| {p} | {e.n} | {net.rms_px_pair[p]:.3f} | {e.trans_rms_m * 1000:.2f} / "
                f"{np.degrees(e.rot_rms_rad):.4f} |" for p, e in sorted(net.edges.items())]
        rows += [f"| world board in {cname} | | {v:.3f} | |" for cname, v in sorted(net.rms_px_world.items())]
        d12 = net.to_dict()["T_board1_board2"]
        return _md_table(("pair", "views", "RMS (px)", "edge spread (mm / deg)"), rows) + [
            "",
            f"Double board: T_board1_board2 = {', '.join(f'{v:.4f}' for v in d12['xyz'])} m "
            f"(sigma {', '.join(f'{v:.2f}' for v in d12['sigma_mm'])} mm). "
            f"Overall RMS {net.rms_px:.3f} px, residual sigma {net.sigma_px:.3f} px per axis.",
        ]

    def _truth_md(self) -> list[str]:
        """The errors against the simulation's truth (none: no lines)."""
        if not self.truth:
            return []
        rows = [f"| {n} | {t['joint_mm']:.2f} / {t['joint_deg']:.4f} | {t['chain_mm']:.2f} / {t['chain_deg']:.4f} | "
                f"{', '.join(f'{t.get(k, np.nan):.2f}' for k in ('dfx_px', 'dfy_px', 'dcx_px', 'dcy_px'))} |"
                for n, t in sorted(self.truth.items())]
        return _md_table(("camera", "joint (mm / deg)", "chain (mm / deg)", "fx, fy, cx, cy error (px)"), rows,
                         "Against truth (simulation)")

    def _warnings_md(self) -> list[str]:
        """The network's and the intrinsics' warnings (none: no lines)."""
        warns = list(self.network.warnings) + [
            w for x in self.intrinsics.values() for w in as_intrinsics(x).extra.get("warnings", [])
        ]
        return ["", "## Warnings", ""] + [f"- {w}" for w in warns] if warns else []

    def texts(self) -> dict[str, str]:
        """{file name: text} of the report's files: ``calibration_report.md`` and ``.yaml``."""
        return {
            "calibration_report.md": self.to_markdown(),
            "calibration_report.yaml": yaml.safe_dump(_plain(self.to_dict()), sort_keys=False, width=120),
        }

    def write(self, folder: str | os.PathLike[str]) -> None:
        """Write ``calibration_report.md`` and ``calibration_report.yaml`` into ``folder`` (atomically)."""
        d = Path(folder)
        for name, text in self.texts().items():
            atomic_write_text(d / name, text)



def _md_table(columns: Sequence[str], rows: Sequence[str], title: str = "", note: str = "") -> list[str]:
    """Lines of a Markdown table of ``columns`` and the formatted ``rows``, after a blank line, the heading
    ``## title`` and the paragraph ``note`` when given."""
    head = [""] + ([f"## {title}", ""] if title else []) + ([note, ""] if note else [])
    return [*head, "| " + " | ".join(columns) + " |", "|---" * len(columns) + "|", *rows]

def _plain(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return _plain(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    return x


def compare_with_truth(
    rig_cal: Rig,
    rig_true: Rig,
    network: NetworkResult,
    intrinsics: Mapping[str, CameraIntrinsics | IntrinsicsResult] | None = None,
) -> dict[str, dict[str, float]]:
    """Per camera: joint and chain pose errors (mm, deg), the calibrated rig's intrinsics errors
    (``dfx_px`` ...) and, given ``intrinsics``, the single-camera calibration's (``sweep_dfx_px`` ...)."""
    out: dict[str, dict[str, float]] = {}
    for c in rig_cal.cameras:
        try:
            t = rig_true.camera(c.name)
        except KeyError:
            continue
        T = t.T_world_cam.matrix()
        dj, rj = geo.pose_error(c.T_world_cam.matrix(), T)
        row = {"joint_mm": dj * 1000, "joint_deg": float(np.degrees(rj))}
        if c.name in network.chain:
            dc, rc = geo.pose_error(network.chain[c.name], T)
            row |= {"chain_mm": dc * 1000, "chain_deg": float(np.degrees(rc))}
        dK = c.K - t.K
        row |= {
            "dfx_px": float(dK[0, 0]),
            "dfy_px": float(dK[1, 1]),
            "dcx_px": float(dK[0, 2]),
            "dcy_px": float(dK[1, 2]),
        }
        if intrinsics is not None and c.name in intrinsics:
            dK0 = as_intrinsics(intrinsics[c.name]).camera_matrix - t.K
            row |= {
                "sweep_dfx_px": float(dK0[0, 0]),
                "sweep_dfy_px": float(dK0[1, 1]),
                "sweep_dcx_px": float(dK0[0, 2]),
                "sweep_dcy_px": float(dK0[1, 2]),
            }
        out[c.name] = row
    return out


def calibrate_recording(
    rec_dir: str | os.PathLike[str], *, estimate_k3: bool = False, write_report: bool = False
) -> tuple[Rig, CalibrationReport]:
    """Calibrate every camera of a recording: intrinsics from ``calib/intrinsics``, then the network.

    Parameters
    ----------
    rec_dir
        The recording folder; reads ``rig.yaml`` (nominal rig) and ``calib/``. When ``truth/rig.yaml``
        exists (simulation), the report also holds the errors against it.
    write_report
        Also write ``REC/calib/calibration_report.{md,yaml}``.

    Returns
    -------
    The calibrated rig (nominal rig with the cameras' intrinsics and ``T_world_cam`` replaced) and the
    report.
    """
    rec = Path(rec_dir)
    rig = load_rig(rec / "rig.yaml")
    spec: BoardsSpec = read_boards_yaml(rec / "calib" / "boards.yaml")
    names = [c.name for c in rig.cameras]
    intr: dict[str, CameraIntrinsics | IntrinsicsResult]
    if spec.sweep_board is None:
        intr = load_intrinsics(rec / "calib" / "intrinsics", names, spec.board, estimate_k3=estimate_k3)
        sweeps = sweep_views(intr)
    else:  # the sweeps show a board with corner IDs
        lenses, sweeps = load_id_intrinsics(rec / "calib" / "intrinsics", names, spec.sweep_board,
                                           estimate_k3=estimate_k3)
        intr = dict(lenses)
    for c in rig.cameras:
        if c.name not in intr:
            log.warning("camera %s: no intrinsic sweep, keeping the rig's intrinsics", c.name)
            intr[c.name] = CameraIntrinsics(c.resolution, c.K, c.dist)
    sizes = {n: as_intrinsics(x).image_size for n, x in intr.items()}
    pairs = load_pair_views(rec / "calib" / "pairs", spec.board, names, sizes)
    if spec.T_world_board is None:
        raise InputError(f"{spec.source}: T_world_board: missing field (the world board's pose)")
    world = load_world_views(rec / "calib" / "world_board", spec.board, names, spec.T_world_board)
    prob = NetworkProblem(
        spec.board,
        spec.T_board1_board2,
        {n: as_intrinsics(x) for n, x in intr.items()},
        {c.name: c.T_world_cam.matrix() for c in rig.cameras},
        pairs,
        world,
        sweeps,
    )
    net = calibrate_network(prob, estimate_k3=estimate_k3)
    rig_cal = calibrated_rig(rig, intr, net)
    truth: dict[str, dict[str, float]] = {}
    if (rec / "truth" / "rig.yaml").is_file():
        truth = compare_with_truth(rig_cal, load_rig(rec / "truth" / "rig.yaml"), net, intr)
    report = CalibrationReport(intr, net, truth)
    if write_report:
        report.write(rec / "calib")
    return rig_cal, report
