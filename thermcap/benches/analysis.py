"""``thermcap bench analysis``: the detector scored against the simulator's ground truth.

Scenes with known targets at contrasts from 2 to 30 K and sizes from 3x3 to 40x40 px (moving,
sky and ground), target-free scenes, and a dawn crossover; detections match truth at IoU >= 0.5.
Reports precision, recall and F1 per contrast band, centroid error, false detections per 100
target-free frames, and the detector's frames per second on one core.
"""

from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np

from thermcap.recorder.analysis.detector import HotSpotDetector, iou
from thermcap.recorder.capture.sources.sim import SimSource, SimTarget

__all__ = ["bench_analysis", "print_table", "score"]

DELTAS = (2.0, 3.0, 5.0, 7.5, 10.0, 15.0, 20.0, 30.0)
SIZES = (3, 5, 10, 20, 40)


def _band(delta: float) -> str:
    return "< 5 K" if delta < 5 else ("5-10 K" if delta < 10 else ">= 10 K")


SPEED_ROUNDS = 5


def score(truth: list[list[int]], dets: list[list[int]]) -> tuple[int, int, int, list[int]]:
    """(tp, fp, fn, matched truth indexes) with greedy IoU >= 0.5 matching."""
    pairs = sorted(((iou(t, d), ti, di) for ti, t in enumerate(truth) for di, d in enumerate(dets)), reverse=True)
    used_t, used_d = set(), set()
    for v, ti, di in pairs:
        if v < 0.5:
            break
        if ti in used_t or di in used_d:
            continue
        used_t.add(ti)
        used_d.add(di)
    return len(used_t), len(dets) - len(used_d), len(truth) - len(used_t), sorted(used_t)


def _scene(delta: float, size: int, seed: int, frames: int) -> SimSource:
    rng = np.random.default_rng(seed)
    targets = []
    for k in range(4):
        region = "sky" if k % 2 == 0 else "ground"
        y = rng.uniform(0.05, 0.3) if region == "sky" else rng.uniform(0.55, 0.85)
        # Spread across the frame and slow enough never to touch within a scene: the score is
        # about detection, not about separating merged blobs.
        x = 0.06 + 0.22 * k + rng.uniform(0, 0.05)
        targets.append(SimTarget(f"T{k}", "test", 0.0, (size, size), (x, y),
                                 (rng.uniform(-20, 20), rng.uniform(-3, 3)), region, delta_k=delta, scale_size=False))
    return SimSource(frames=frames, paced=False, seed=seed, targets=tuple(targets), cue_period_s=0, start_time_ns=0)


def bench_analysis(frames_per_scene: int = 12) -> dict[str, Any]:
    bands: dict[str, dict[str, Any]] = {}
    cells = []
    cerr: list[float] = []
    for delta in DELTAS:
        for size in SIZES:
            src = _scene(delta, size, seed=int(delta * 10) + size, frames=frames_per_scene)
            det = HotSpotDetector(src.model, bad_pixel_map=src.bad_pixel_map)
            tp = fp = fn = 0
            for f in src.frames():
                truth = [t for _, m in f.messages if _ == "/sim/ground_truth" for t in m["targets"]]
                dets, _ = det.detect(f.pixels)
                a, b, c, matched = score([t["bbox"] for t in truth], [d.bbox for d in dets])
                tp, fp, fn = tp + a, fp + b, fn + c
                for ti in matched:
                    t = truth[ti]
                    d = max(dets, key=lambda d: iou(d.bbox, t["bbox"]))
                    cerr.append(float(np.hypot(d.centroid[0] - t["centroid"][0], d.centroid[1] - t["centroid"][1])))
            band = bands.setdefault(_band(delta), {"tp": 0, "fp": 0, "fn": 0})
            band["tp"] += tp
            band["fp"] += fp
            band["fn"] += fn
            cells.append({"delta_k": delta, "size": size, "recall": round(tp / max(1, tp + fn), 3),
                          "precision": round(tp / max(1, tp + fp), 3) if tp + fp else None})
    for stats in bands.values():
        p = stats["tp"] / (stats["tp"] + stats["fp"]) if stats["tp"] + stats["fp"] else 0.0
        r = stats["tp"] / (stats["tp"] + stats["fn"]) if stats["tp"] + stats["fn"] else 0.0
        stats.update(precision=round(p, 4), recall=round(r, 4), f1=round(2 * p * r / (p + r), 4) if p + r else 0.0)
    # Target-free scenes: every detection is false.
    empty = SimSource(frames=100, paced=False, seed=99, targets=(), cue_period_s=0, start_time_ns=0)
    det = HotSpotDetector(empty.model, bad_pixel_map=empty.bad_pixel_map)
    false = sum(len(det.detect(f.pixels)[0]) for f in empty.frames())
    # A dawn crossover: the grade follows the truth's fade.
    xo = SimSource(frames=240, paced=False, seed=7, crossover=True, cue_period_s=0, start_time_ns=0)
    det = HotSpotDetector(xo.model, bad_pixel_map=xo.bad_pixel_map)
    grades = [(det.detect(f.pixels)[1]["thermal_contrast_grade"],
               f.sidecar["thermal_analysis"]["thermal_contrast_grade"])
              for f in xo.frames()]
    agree = sum((a < 0.3) == (b < 0.3) for a, b in grades) / len(grades)
    # Speed on one core, 640x512, in CPU time (the host is shared: wall time says more of the
    # neighbours than of the detector); the goal is <= 0.15 cores for a camera at 60 fps. CPU
    # time moves with the neighbours too (caches, the sibling hyperthread), so it is the best
    # of five rounds, as timeit reports, with the median beside it.
    pre = [f.pixels for f in SimSource(frames=120, paced=False, seed=3, start_time_ns=0).frames()]
    det = HotSpotDetector(SimSource(frames=1).model)
    for px in pre[:10]:
        det.detect(px)
    rounds = []
    for _ in range(SPEED_ROUNDS):
        t = time.thread_time()
        for px in pre:
            det.detect(px)
        rounds.append(len(pre) / (time.thread_time() - t))
    fps, fps_median = max(rounds), statistics.median(rounds)
    return {"bands": bands, "cells": cells,
            "centroid_error_px": {"mean": round(float(np.mean(cerr)), 3) if cerr else None,
                                  "p95": round(float(np.percentile(cerr, 95)), 3) if cerr else None},
            "false_per_100_empty_frames": round(false, 2),
            "crossover_agreement_with_truth": round(agree, 4),
            "fps_640x512_one_core": round(fps, 1), "cores_per_camera_640x512_at_60fps": round(60 / fps, 3),
            "cores_per_camera_median_of_rounds": round(60 / fps_median, 3), "speed_rounds": SPEED_ROUNDS,
            "worst_case": worst_case(fps)}


def _scene_fps(det: HotSpotDetector, frames: list[np.ndarray]) -> tuple[float, dict[str, Any] | None]:
    capped = None
    best = 0.0
    for _ in range(3):
        t = time.thread_time()
        for px in frames:
            capped = det.detect(px)[1].get("detection_capped") or capped
        best = max(best, len(frames) / max(time.thread_time() - t, 1e-9))
    return best, capped


def worst_case(typical_fps: float) -> dict[str, Any]:
    """The scenes that cost a detector most: every pixel a candidate (uniform noise), and noise
    just below the bound where whole frames are set aside (most cells candidates, joined into
    wide regions). Each against the typical scene's speed in the same run."""
    rng = np.random.default_rng(5)
    model = SimSource(frames=1).model
    scenes = {"uniform_noise": lambda: rng.integers(0, 16383, (512, 640), dtype=np.uint16),
              "gaussian_noise_45_counts": lambda: (2000 + rng.normal(0, 45, (512, 640))).astype(np.uint16)}
    out: dict[str, Any] = {}
    for name, make in scenes.items():
        fps, capped = _scene_fps(HotSpotDetector(model), [make() for _ in range(30)])
        out[name] = {"fps_640x512_one_core": round(fps, 1), "vs_typical_scene": round(fps / typical_fps, 3),
                     "cap": capped["rule"] if capped else None}
    return out


def print_table(res: dict[str, Any]) -> str:
    lines = [f"{'band':>8} {'precision':>10} {'recall':>8} {'F1':>7} {'tp':>6} {'fp':>5} {'fn':>5}"]
    for name in ("< 5 K", "5-10 K", ">= 10 K"):
        b = res["bands"].get(name)
        if b:
            lines.append(f"{name:>8} {b['precision']:>10} {b['recall']:>8} {b['f1']:>7} {b['tp']:>6} "
                         f"{b['fp']:>5} {b['fn']:>5}")
    lines.append("recall by delta T (rows) and target size in px (columns):")
    lines.append("        " + "".join(f"{s:>7}" for s in SIZES))
    for d in DELTAS:
        row = [c for c in res["cells"] if c["delta_k"] == d]
        lines.append(f"{d:>6} K" + "".join(f"{c['recall']:>7}" for c in row))
    err = res["centroid_error_px"]
    lines.append(f"centroid error: mean {err['mean']} px, p95 {err['p95']} px")
    lines.append(f"false detections per 100 target-free frames: {res['false_per_100_empty_frames']}")
    lines.append(f"crossover (grade < 0.3) agreement with ground truth: {res['crossover_agreement_with_truth']}")
    lines.append(f"detector speed, 640x512, one core: {res['fps_640x512_one_core']} fps (CPU time, best of "
                 f"{res['speed_rounds']} rounds), {res['cores_per_camera_640x512_at_60fps']} cores for a camera at "
                 f"60 fps (median round {res['cores_per_camera_median_of_rounds']}; goal 0.15)")
    for name, w in res.get("worst_case", {}).items():
        lines.append(f"worst case {name}: {w['fps_640x512_one_core']} fps, {w['vs_typical_scene']}x the typical "
                     f"scene (cap: {w['cap'] or 'none'})")
    return "\n".join(lines)


def overlay_png(temps: np.ndarray, boxes: list[list[int]], palette_name: str = "ironbow") -> bytes:
    """A heatmap of ``temps`` with each detection's box drawn in white, and its °C scale."""
    from thermcap.recorder.exports.render import colour_png, frame_range

    return colour_png(temps, frame_range(temps), palette_name, boxes=boxes, level=6)


def sample_report(samples_dir: str, out_dir: str | None = None) -> list[dict[str, Any]]:
    """The detector on real files: hot spots per image, with an overlay PNG of each."""
    import os

    from thermcap.recorder.importers import ImportFileError, read_file
    from thermcap.recorder.radiometry import TemperatureUnavailable

    rows = []
    for dirpath, _d, names in sorted(os.walk(samples_dir)):
        for name in sorted(names):
            if name.endswith((".json", ".txt")):
                continue
            path = os.path.join(dirpath, name)
            try:
                (f,) = read_file(path)[:1]
            except ImportFileError:
                continue
            try:
                temps = np.asarray(f.model.to_celsius(f.pixels), dtype=np.float32)
            except TemperatureUnavailable:
                rows.append({"file": name, "format": f.format, "layout": f.layout, "hot_spots": None,
                             "note": "no temperatures without DJI's SDK"})
                continue
            dets, analysis = HotSpotDetector(f.model).detect(f.pixels)
            row = {"file": name, "format": f.format, "layout": f.layout, "hot_spots": len(dets),
                   "grade": analysis["thermal_contrast_grade"], "delta_t": analysis["delta_t_deg_c"],
                   "scene_c": [round(float(temps.min()), 1), round(float(temps.max()), 1)],
                   "largest_px": max(((d.bbox[2] - d.bbox[0] + 1) * (d.bbox[3] - d.bbox[1] + 1) for d in dets),
                                     default=0)}
            if out_dir:
                os.makedirs(out_dir, exist_ok=True)
                out = os.path.join(out_dir, os.path.splitext(name)[0] + ".overlay.png")
                with open(out, "wb") as fh:
                    fh.write(overlay_png(temps, [d.bbox for d in dets]))
                row["overlay"] = out
            rows.append(row)
    return rows
