"""Interchange benchmark: bag import throughput, and the same GT from a bag-imported
recording.

1. Throughput. A bag of ``--images`` 1024 x 768 mono8 ``sensor_msgs/Image`` and one of ``--scans``
   181-beam ``sensor_msgs/LaserScan`` (ROS 1 and ROS 2 sqlite3) are written, then imported with
   :func:`gtrig.io.rosbag.record_import.import_bag`. Printed: images/s (PNG level 1 and PGM) and
   scans/s, each beside its peers measured in the same run on the same data: OpenCV's own encoder
   writing the same images with the same threads, and rosbags deserializing the same scans without
   writing anything. The ratios say what the import adds; the machine may be loaded.
2. Round trip. A ``gtrig sim --quick`` recording (``--rec``, or simulated into ``--work``) has its run,
   validation and background sequences exported to a bag (images, fixed and onboard scans,
   odometry), imported into a new recording (the parts no bag holds, survey, calibration images and
   rig, copied), and the whole pipeline (``gtrig run``: GTlaser, GTvision, sync, fusion) run on both.
   Printed: whether every imported file is byte-identical (text) or pixel-identical (images), whether
   the GTlaser, GTvision and fusion pose tracks are byte-identical, and the largest difference of their
   poses and covariances; GTvision (``gtrig.vision.sequence.run_recording``, truth rig) once more on the
   validation sequence imported as one lossless FFV1 video per camera.

    python bench/interchange.py [--images 200] [--scans 20000] [--rec REC] [--work /tmp/gtrig_bench_interchange]
"""

from __future__ import annotations

import argparse
import shutil
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from gtrig.io.rosbag._bag import BagWriter, header
from gtrig.io.rosbag.record_export import export_recording
from gtrig.io.rosbag.record_import import PNG_PARAMS, import_bag
from gtrig.rig.load import dump_rig
from gtrig.sim.gtroom import make_scene


def _rig_for_bench(work: Path) -> Path:
    rig = make_scene(0).rig_true
    sc = rig.laser_scanners[0]
    rig = rig.model_copy(update={"laser_scanners": (sc.model_copy(update={"beams": 181}),) + rig.laser_scanners[1:]})
    p = work / "rig.yaml"
    dump_rig(rig, p)
    return p


def _image_bag(path: Path, ver: int, n: int, rng: np.random.Generator) -> list[np.ndarray]:
    base = cv2.GaussianBlur(rng.integers(0, 255, (768, 1024), dtype=np.uint8), (0, 0), 3)
    imgs = [np.roll(base, 7 * i, axis=1) for i in range(n)]
    with BagWriter(path, ver) as w:
        T = w.ts.types
        for i, img in enumerate(imgs):
            t = 1.7e9 + 0.1 * i
            w.write("/cam0/image_raw", t, T["sensor_msgs/msg/Image"](
                header=header(w.ts, ver, t, "cam0", i), height=768, width=1024, encoding="mono8", is_bigendian=0,
                step=1024, data=img.reshape(-1)))
    return imgs


def _scan_bag(path: Path, ver: int, n: int, sc: object, rng: np.random.Generator) -> None:
    with BagWriter(path, ver) as w:
        T = w.ts.types
        for i in range(n):
            t = 1.7e9 + i / 75.0
            r = rng.uniform(0.5, 29.0, 181).astype(np.float32)
            w.write("/laser0/scan", t, T["sensor_msgs/msg/LaserScan"](
                header=header(w.ts, ver, t, "laser0", i), angle_min=sc.angle_min_rad,  # type: ignore[attr-defined]
                angle_max=sc.angle_min_rad + 180 * sc.angle_increment_rad,  # type: ignore[attr-defined]
                angle_increment=sc.angle_increment_rad, time_increment=0.0,  # type: ignore[attr-defined]
                scan_time=1 / 75, range_min=0.0, range_max=30.0, ranges=r, intensities=np.zeros(0, np.float32)))


def throughput(work: Path, n_images: int, n_scans: int) -> None:
    from rosbags.highlevel import AnyReader

    rng = np.random.default_rng(0)
    rig_path = _rig_for_bench(work)
    from gtrig.rig import load_rig

    sc = load_rig(rig_path).laser_scanners[0]
    print(f"throughput ({n_images} images 1024x768 mono8, {n_scans} scans of 181 beams; machine loaded: ratios "
          "against peers measured now)")
    for ver, suffix in ((1, ".bag"), (2, "")):
        tag = f"ROS {ver}"
        ib, sb = work / f"images{ver}{suffix}", work / f"scans{ver}{suffix}"
        imgs = _image_bag(ib, ver, n_images, rng)
        _scan_bag(sb, ver, n_scans, sc, rng)
        for fmt in ("png", "pgm"):
            out = work / f"imp_img{ver}_{fmt}"
            shutil.rmtree(out, ignore_errors=True)
            t0, c0 = time.perf_counter(), time.process_time()
            import_bag(ib, {"cameras": {"cam0": "/cam0/image_raw"}}, out, rig_path=rig_path, image_format=fmt)
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            peer_dir = work / f"peer_{fmt}"
            shutil.rmtree(peer_dir, ignore_errors=True)
            peer_dir.mkdir()
            params = PNG_PARAMS if fmt == "png" else []
            t0, c0 = time.perf_counter(), time.process_time()
            with ThreadPoolExecutor(2) as pool:
                list(pool.map(lambda a, d=peer_dir, f=fmt, p=params: cv2.imwrite(str(d / f"{a[0]:06d}.{f}"), a[1], p),
                              enumerate(imgs)))
            dp, dpc = time.perf_counter() - t0, time.process_time() - c0
            print(f"  {tag} images -> {fmt}: {n_images / dt:8.1f} images/s wall, {n_images / dc:8.1f} per CPU-second "
                  f"(OpenCV writing the same {fmt}s, 2 threads: {n_images / dp:8.1f}/s wall, {n_images / dpc:8.1f} per "
                  f"CPU-s; import / peer time {dt / dp:.2f})")
        out = work / f"imp_scan{ver}"
        shutil.rmtree(out, ignore_errors=True)
        t0, c0 = time.perf_counter(), time.process_time()
        import_bag(sb, {"lasers": {"laser0": "/laser0/scan"}}, out, rig_path=rig_path)
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        t0, c0 = time.perf_counter(), time.process_time()
        with AnyReader([sb]) as r:
            for c, _, raw in r.messages(r.connections):
                r.deserialize(raw, c.msgtype)
        dp, dpc = time.perf_counter() - t0, time.process_time() - c0
        print(f"  {tag} scans: {n_scans / dt:8.0f} scans/s wall, {n_scans / dc:8.0f} per CPU-second (rosbags "
              f"reading and deserializing alone: {n_scans / dp:8.0f}/s wall, {n_scans / dpc:8.0f} per CPU-s; "
              f"import / peer time {dt / dp:.2f})")


def png_settings(n: int = 20) -> None:
    """OpenCV's PNG encoder settings on the bench's frames, one thread: frames per CPU-second and size."""
    rng = np.random.default_rng(0)
    base = cv2.GaussianBlur(rng.integers(0, 255, (768, 1024), dtype=np.uint8), (0, 0), 3)
    imgs = [np.roll(base, 7 * i, axis=1) for i in range(n)]
    C, S = cv2.IMWRITE_PNG_COMPRESSION, cv2.IMWRITE_PNG_STRATEGY
    settings = {"OpenCV's default (no options)": [], "level 1": [C, 1],
                "level 1, Huffman only": [C, 1, S, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY],
                "level 1, Huffman only, SUB filter (gtrig's)": PNG_PARAMS,
                "level 0 (stored)": [C, 0]}
    if hasattr(cv2, "IMWRITE_PNG_FILTER"):
        settings["level 0 (stored), no filter"] = [C, 0, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    print(f"PNG encoder settings, {n} frames 1024 x 768 mono8, OpenCV {cv2.__version__}, one thread:")
    for name, params in settings.items():
        c0 = time.process_time()
        size = [len(cv2.imencode(".png", im, params)[1]) for im in imgs]
        dc = time.process_time() - c0
        print(f"  {name}: {n / dc:7.1f} frames per CPU-second, {np.mean(size) / 1e3:.0f} kB")
    cv2.setNumThreads(threads)


def _same_files(a: Path, b: Path) -> tuple[int, list[str]]:
    n, diff = 0, []
    for f in sorted(a.rglob("*")):
        if not f.is_file():
            continue
        g = b / f.relative_to(a)
        n += 1
        if not g.is_file():
            diff.append(f"{f.relative_to(a)} missing")
        elif f.suffix == ".png":
            x, y = cv2.imread(str(f), cv2.IMREAD_UNCHANGED), cv2.imread(str(g), cv2.IMREAD_UNCHANGED)
            if x.shape != y.shape or np.any(x != y):
                diff.append(f"{f.relative_to(a)} pixels differ")
        elif f.read_bytes() != g.read_bytes():
            diff.append(f"{f.relative_to(a)} bytes differ")
    return n, diff


def round_trip(rec: Path, work: Path) -> None:
    from gtrig.io.posetrack import read_pose_track
    from gtrig.pipeline import run as run_pipeline
    from gtrig.rig import load_rig
    from gtrig.vision.sequence import run_recording

    back = work / "imported"
    shutil.rmtree(back, ignore_errors=True)
    back.mkdir(parents=True)
    t0 = time.perf_counter()
    for seq in ("run", "validation", "background"):
        if not (rec / seq).is_dir():
            continue
        bag = work / f"{seq}.bag"
        if bag.exists():
            bag.unlink()
        topics = export_recording(rec, bag, 1, sequence=seq)
        import_bag(bag, topics, back, rig_path=rec / "rig.yaml", image_format="png")  # the original's files
        shutil.rmtree(back / seq / "stamps")  # gtrig's sidecar, not in the original layout
        if (rec / seq / "poses.csv").is_file():  # the validation stops are no sensor: not in a bag
            shutil.copyfile(rec / seq / "poses.csv", back / seq / "poses.csv")
    for sub in ("calib", "handheld", "survey", "truth"):
        if (rec / sub).is_dir():
            shutil.copytree(rec / sub, back / sub)
    if (rec / "sim_config.yaml").is_file():  # the simulated room's calibration object is found through it
        shutil.copyfile(rec / "sim_config.yaml", back / "sim_config.yaml")
    print(f"round trip: {rec} -> ROS 1 bags -> {back} in {time.perf_counter() - t0:.1f} s")
    for seq in ("run", "validation", "background"):
        if (rec / seq).is_dir():
            n, diff = _same_files(rec / seq, back / seq)
            print(f"  {seq}: {n} files, {'all identical' if not diff else str(len(diff)) + ' differ: ' + diff[0]}")
    # the whole pipeline (survey ... GTlaser, GTvision, sync, fusion) on both recordings: the same outputs
    outs = {}
    for name, r in (("original", rec), ("imported", back)):
        outs[name] = work / f"pipeline_{name}"
        shutil.rmtree(outs[name], ignore_errors=True)
        t1 = time.perf_counter()
        run_pipeline(r, outs[name], reuse=False)
        print(f"  gtrig run on the {name} recording: {time.perf_counter() - t1:.0f} s")
    for stem, what in (("gt_laser", "GTlaser run"), ("gt_vision_validation", "GTvision validation"),
                       ("gt_vision_run", "GTvision run"), ("gt_fused", "fusion run")):
        files = [f"{stem}.tum", f"{stem}_cov.csv"]
        if not all((outs["original"] / f).is_file() for f in files):
            print(f"  {what}: not produced")
            continue
        same = all((outs["original"] / f).read_bytes() == (outs["imported"] / f).read_bytes() for f in files)
        a = read_pose_track(outs["original"] / files[0], outs["original"] / files[1])
        b = read_pose_track(outs["imported"] / files[0], outs["imported"] / files[1])
        _compare(f"{what} ({'TUM and covariance files byte-identical' if same else 'files differ'})", a.stamps_s,
                 b.stamps_s, a.xyz, b.xyz, a.quat_xyzw, b.quat_xyzw, a.cov, b.cov)
    rig = load_rig(rec / "truth" / "rig.yaml")
    va = run_recording(rec, rig, "validation", workers=1)
    ta = va.trajectory()
    # the same bag imported with one lossless video per camera, decoded by GTvision's workers
    vid = work / "imported_video"
    shutil.rmtree(vid, ignore_errors=True)
    vid.mkdir(parents=True)
    topics = export_recording(rec, work / "validation.bag", 1, sequence="validation", force=True)
    import_bag(work / "validation.bag", topics, vid, rig_path=rec / "rig.yaml", video=True)
    shutil.copyfile(rec / "validation" / "poses.csv", vid / "validation" / "poses.csv")
    vv = run_recording(vid, rig, "validation", workers=1)
    tv = vv.trajectory()
    _compare("GTvision validation from video.mkv", ta.stamps_s, tv.stamps_s, ta.xyz, tv.xyz, ta.quat_xyzw,
             tv.quat_xyzw, va.covariances(), vv.covariances())


def _compare(what: str, sa: np.ndarray, sb: np.ndarray, xa: np.ndarray, xb: np.ndarray, qa: np.ndarray,
             qb: np.ndarray, ca: np.ndarray | None, cb: np.ndarray | None) -> None:
    if sa.shape != sb.shape:
        print(f"  {what}: {sa.size} vs {sb.size} poses")
        return
    dc = float(np.nanmax(np.abs(ca - cb))) if ca is not None and cb is not None and ca.size else float("nan")
    print(f"  {what}: {sa.size} poses; max |d stamp| {np.abs(sa - sb).max():.3g} s, max |d xyz| "
          f"{np.abs(xa - xb).max():.3g} m, max |d quat| {np.abs(qa - qb).max():.3g}, max |d cov| {dc:.3g}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--images", type=int, default=200)
    ap.add_argument("--scans", type=int, default=20000)
    ap.add_argument("--rec", type=Path, default=None, help="a recording (default: gtrig sim --quick into --work)")
    ap.add_argument("--work", type=Path, default=Path("/tmp/gtrig_bench_interchange"))
    ap.add_argument("--skip-throughput", action="store_true")
    ap.add_argument("--skip-round-trip", action="store_true")
    a = ap.parse_args()
    a.work.mkdir(parents=True, exist_ok=True)
    if not a.skip_throughput:
        tp = a.work / "throughput"
        shutil.rmtree(tp, ignore_errors=True)
        tp.mkdir()
        png_settings()
        throughput(tp, a.images, a.scans)
    if not a.skip_round_trip:
        rec = a.rec
        if rec is None:
            from gtrig.sim.config import SimConfig
            from gtrig.sim.recording import simulate

            rec = a.work / "sim_quick"
            if not (rec / "rig.yaml").is_file():
                simulate(SimConfig.quick_defaults(seed=0), rec)
        round_trip(rec, a.work / "round_trip")


if __name__ == "__main__":
    main()
