"""Accuracy of a forest on labelled frames: confusion matrix, per-part table, pictures.

Evaluated pixels are body pixels with a measurement (label > 0 and depth > 0), as in
Shotton et al.; the forest may answer background (0) there, which counts as an error.
``pixel_accuracy`` = correct / evaluated; ``mean_per_class`` = mean over the parts that occur
of (correct pixels of the part / its pixels).

The same pass scores the person/background decision per person instance, distance and
group size (:mod:`vhgen.forest.persons`), on the forest's labels > 0 or on the person mask
of a later stage (``person_mask``).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from vhgen.forest.data import (
    StoreInfo,
    cut_out_view,
    read_classes,
    read_frames,
    read_instances,
    select_frames,
)
from vhgen.forest.persons import PeopleScore, frame_people
from vhgen.forest.trees import Forest, Predictor

# (depth (H, W) uint16 mm, the forest's labels (H, W) uint8, the frame's store) ->
# (H, W) bool: the pixels called a person, or integer person instance ids (0 = none),
# with which the person scores also count false people (vhgen.forest.persons)
PersonMask = Callable[[np.ndarray, np.ndarray, StoreInfo], np.ndarray]

log = logging.getLogger(__name__)


def confusion(pred: np.ndarray, true: np.ndarray, depth: np.ndarray, num_classes: int
              ) -> np.ndarray:
    """(C, C) int64 counts [true, predicted] over body pixels with a measurement."""
    m = (true > 0) & (depth > 0)
    idx = true[m].astype(np.int64) * num_classes + pred[m].astype(np.int64)
    return np.bincount(idx, minlength=num_classes * num_classes).reshape(num_classes,
                                                                           num_classes)


def scores(conf: np.ndarray, names: list[str]) -> dict:
    """pixel_accuracy, mean_per_class and a per-part list from a confusion matrix."""
    total = conf[1:].sum()
    rows = conf.sum(axis=1)
    per = []
    for k in range(1, conf.shape[0]):
        if rows[k] == 0:
            continue
        per.append({"label": k, "name": names[k - 1], "pixels": int(rows[k]),
                    "accuracy": float(conf[k, k] / rows[k]),
                    "precision": float(conf[k, k] / max(conf[:, k].sum(), 1))})
    return {"pixel_accuracy": float(np.trace(conf[1:, 1:]) / max(total, 1)),
            "mean_per_class": float(np.mean([p["accuracy"] for p in per])) if per else 0.0,
            "pixels": int(total), "per_part": per}


def evaluate(forest: Forest, infos: list[StoreInfo], *, max_frames: int | None = None,
             seed: int = 0, batch: int = 32, out_dir: str | Path | None = None,
             sheet_frames: int = 4, person_mask: PersonMask | None = None,
             called_by: str = "forest labels > 0", parts: Forest | None = None,
             cut_out: bool = False) -> dict:
    """Label every selected frame and score it; ``out_dir`` gets confusion.png and
    contact_sheet.png. Returns the scores plus frames, seconds, fps and the matrix, and
    under ``people`` the person scores of :mod:`vhgen.forest.persons` on ``person_mask``
    (default: the forest's labels > 0; ``called_by`` names it in the output). The part
    scores are the forest's own labels, or those of ``parts``; a forest trained
    ``--segmented`` (or with a ``--segmented-share``) labels the true people alone (the
    depth of every other pixel removed: Shotton et al.'s test of the parts of segmented
    people). ``cut_out``: every frame is scored as a pipeline that removed its background
    feeds it, its people alone measured (:func:`vhgen.forest.data.cut_out_view`)."""
    names = list(forest.meta["label_names"])
    by_path = {i.path: i for i in infos}
    people = PeopleScore(called_by=called_by)
    c = forest.num_classes
    frames = select_frames(infos, max_frames, seed)
    pred_fn = Predictor(forest)
    part_forest = parts if parts is not None else forest
    on_people = part_forest.labels_people
    part_fn = pred_fn
    if on_people:  # the parts of people: no background
        part_fn = Predictor(part_forest, parts_only=True)
    elif parts is not None:
        part_fn = Predictor(parts)
    conf = np.zeros((c, c), np.int64)
    shown: list[tuple[np.ndarray, np.ndarray, np.ndarray, int]] = []
    show_ids = set(np.linspace(0, len(frames) - 1, min(sheet_frames, len(frames)))
                   .round().astype(int).tolist()) if frames else set()
    seconds = 0.0
    for s in range(0, len(frames), batch):
        part = frames[s:s + batch]
        depth, labels = read_frames(part)
        if cut_out:
            depth = cut_out_view(depth, labels, read_classes(part, depth.shape))
        if labels.max(initial=0) >= c:
            from vhgen.errors import ForestError

            raise ForestError(f"{part[0][0]}: label {int(labels.max())} outside the forest's "
                              f"{c - 1} parts (label scheme mismatch)")
        t0 = time.perf_counter()
        pred = pred_fn.predict(depth)
        seconds += time.perf_counter() - t0
        if on_people:  # the true people alone
            part_pred = part_fn.predict(np.where(labels > 0, depth, 0))
        elif parts is not None:
            part_pred = part_fn.predict(depth)
        else:
            part_pred = pred
        conf += confusion(part_pred, labels, depth, c)
        inst, has = read_instances(part, labels)
        for i, (path, f, _) in enumerate(part):
            called = (pred[i] > 0 if person_mask is None
                      else person_mask(depth[i], pred[i], by_path[path]))
            people.add(frame_people(called, depth[i], inst[i], has_instances=bool(has[i])),
                       (path, f), bool(has[i]))
        for i in range(len(part)):
            if s + i in show_ids:
                shown.append((depth[i], labels[i], part_pred[i], part[i][2]))
        log.info("evaluated %d/%d frames", min(s + batch, len(frames)), len(frames))
    res = scores(conf, names)
    res.update({"frames": len(frames), "predict_seconds": round(seconds, 3),
                "frames_per_second": round(len(frames) / seconds, 2) if seconds else None,
                "confusion": conf.tolist(), "label_names": names,
                "parts_on": "the true people alone" if on_people else "whole frames",
                "cut_out": cut_out,
                "people": people.result()})
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        plot_confusion(conf, names, out / "confusion.png")
        contact_sheet(shown, forest.meta.get("label_colors"), c, out / "contact_sheet.png")
    return res


def table(res: dict) -> str:
    """The per-part table and the two headline numbers as text."""
    lines = [f"{'part':<12} {'pixels':>10} {'accuracy':>9} {'precision':>9}"]
    for p in res["per_part"]:
        lines.append(f"{p['name']:<12} {p['pixels']:>10d} {p['accuracy']:>9.3f} "
                     f"{p['precision']:>9.3f}")
    lines.append(f"pixel_accuracy {res['pixel_accuracy']:.4f}  mean_per_class "
                 f"{res['mean_per_class']:.4f}  ({res['pixels']} body pixels, "
                 f"{res['frames']} frames)")
    return "\n".join(lines)


def plot_confusion(conf: np.ndarray, names: list[str], path: Path) -> Path:
    """Row-normalised confusion matrix (true rows, predicted columns) as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = conf.sum(axis=1, keepdims=True)
    norm = conf / np.maximum(rows, 1)
    labels = ["bg", *names]
    fig, ax = plt.subplots(figsize=(9, 8))
    im = ax.imshow(norm, cmap="viridis", vmin=0, vmax=1)
    ax.set_xticks(range(len(labels)), labels, rotation=90, fontsize=7)
    ax.set_yticks(range(len(labels)), labels, fontsize=7)
    ax.set_xlabel("predicted")
    ax.set_ylabel("true")
    fig.colorbar(im, ax=ax, fraction=0.046)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def palette_for(colors: list | None, num_classes: int) -> np.ndarray:
    """(C, 3) uint8: the store's label colours, else a fixed spread of hues."""
    if colors is not None and len(colors) >= num_classes:
        return np.asarray(colors, np.uint8)[:num_classes]
    from vhgen.preview import turbo

    pal = turbo(np.linspace(0, 1, num_classes))
    pal[0] = 0
    return pal


def contact_sheet(shown: list[tuple[np.ndarray, np.ndarray, np.ndarray, int]],
                  colors: list | None, num_classes: int, path: Path,
                  scale: float = 0.5) -> Path:
    """Rows of depth | true labels | predicted labels."""
    from PIL import Image, ImageDraw

    from vhgen.preview import colorize_depth

    pal = palette_for(colors, num_classes)
    if not shown:
        Image.new("RGB", (10, 10), (255, 255, 255)).save(path)
        return path
    h, w = shown[0][0].shape
    th, tw = int(h * scale), int(w * scale)
    sheet = Image.new("RGB", (3 * tw, len(shown) * (th + 14)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for r, (d, t, p, gid) in enumerate(shown):
        y = r * (th + 14)
        for c, (tile, title) in enumerate([(colorize_depth(d), "depth"),
                                           (pal[np.minimum(t, num_classes - 1)], "true"),
                                           (pal[p], "predicted")]):
            draw.text((c * tw + 4, y + 1), f"frame {gid}: {title}", fill=(0, 0, 0))
            tile_img = Image.fromarray(tile).resize((tw, th), Image.Resampling.NEAREST)
            sheet.paste(tile_img, (c * tw, y + 13))
    sheet.save(path)
    return path
