"""A forest on real depth frames: does it find the people, and leave the rest alone?

Real frames carry no part labels; what they can be scored on is the person/background
decision. A frame is either a frame *with people*, which has a person mask (an 8-bit
PNG of the frame's size, 0 = not a person, any other value = a person), a frame *with
nobody*, or a frame of *people only*, whose background the source removed (Skeltrack's
test frames): its mask is ``depth > 0``. Only pixels with a measurement count. A pixel
is called a person when the forest gives it any body part (label > 0), after the
optional segmentation stage (:mod:`vhgen.forest.segment`).

- ``person_iou``: over the frames with people, person pixels called a person / (person
  pixels or pixels called a person), pooled over the frames (``person_iou_mean``: the
  mean of the per-frame IoUs);
- ``person_recall`` = called and person / person; ``person_precision`` = called and
  person / called;
- ``background_called``: the share of background pixels (every valid pixel of a frame
  with nobody, the valid pixels outside the mask of a frame with people) called a body
  part, pooled; also for the two kinds of frames apart;
- ``people_only``: over the frames of people only, ``person_recall`` (pooled) and
  ``person_recall_mean`` (per frame); they have no background, so no precision or IoU,
  and they are kept out of the scores above.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vhgen.depthfile import DepthFrame, depth_files, read_depth
from vhgen.errors import DepthFileError, ForestError

log = logging.getLogger(__name__)

MASK_SUFFIX = ".mask.png"  # a mask beside its frame: capture.pcd -> capture.mask.png


KINDS = ("people", "nobody", "people_only")


@dataclass(frozen=True, eq=False)
class RealFrame:
    """A real frame to score: its depth, and its person mask (None: nobody in it);
    ``people_only``: the mask is every measured pixel (the source removed the rest)."""

    frame: DepthFrame
    mask: np.ndarray | None
    people_only: bool = False

    @property
    def name(self) -> str:
        return Path(self.frame.path).name

    @property
    def kind(self) -> str:
        """``people``, ``nobody`` or ``people_only``."""
        return "people_only" if self.people_only else (
            "nobody" if self.mask is None else "people")


def find_mask(frame_path: Path, masks: Path | None) -> Path | None:
    """The mask file of a frame: ``MASKS/<stem>.png``, else ``<stem>.mask.png`` beside it."""
    stem = frame_path.name[: -len(frame_path.suffix)] if frame_path.suffix else frame_path.name
    for cand in ([masks / f"{stem}.png"] if masks is not None else []) + [
            frame_path.with_name(stem + MASK_SUFFIX)]:
        if cand.is_file():
            return cand
    return None


def read_mask(path: Path, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool person mask from an 8-bit (or 1-bit) single-channel PNG; DepthFileError
    naming the file when it is not one or not of the frame's size."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            if im.mode not in ("L", "1", "P"):
                raise DepthFileError(path, f"a person mask must be a single-channel 8-bit "
                                           f"PNG (0 = not a person), got mode {im.mode}")
            arr = np.asarray(im)
    except (OSError, UnidentifiedImageError) as e:
        raise DepthFileError(path, f"cannot read the person mask: {e}") from None
    if arr.shape != shape:
        raise DepthFileError(path, f"mask is {arr.shape[1]}x{arr.shape[0]}, its frame "
                                   f"{shape[1]}x{shape[0]}")
    return arr > 0


def load_real_frames(people: Iterable[str | Path], nobody: Iterable[str | Path],
                     masks: str | Path | None = None,
                     warn: Callable[[str], None] = log.warning,
                     people_only: Iterable[str | Path] = ()) -> list[RealFrame]:
    """Real frames with people (each with its mask: see :func:`find_mask`), frames with
    nobody and frames of people only (mask ``depth > 0``). A frame that cannot be read, a
    frame with people without a readable mask, or a frame of people only without a
    measured pixel is one warning line and is left out; the rest go on. ForestError when
    none is left."""
    mdir = Path(masks) if masks is not None else None
    if mdir is not None and not mdir.is_dir():
        raise ForestError(f"--masks {mdir}: no such folder")
    out: list[RealFrame] = []
    for paths, kind in ((people, "people"), (nobody, "nobody"), (people_only, "people_only")):
        for f in depth_files(paths):
            if f.name.endswith(MASK_SUFFIX):
                continue  # a mask beside its frame, not a frame
            try:
                frame = read_depth(f)
                mask = None
                if kind == "people_only":
                    mask = np.asarray(frame.depth_mm) > 0
                    if not mask.any():
                        raise DepthFileError(f, "a frame of people only (--people-only) "
                                                "without a measured pixel")
                elif kind == "people":
                    m = find_mask(f, mdir)
                    if m is None:
                        raise DepthFileError(f, "a frame with people needs a person mask "
                                                f"(--masks DIR/<name>.png or <name>{MASK_SUFFIX})")
                    mask = read_mask(m, frame.depth_mm.shape)
            except DepthFileError as e:
                warn(f"skipped {e}")
                continue
            out.append(RealFrame(frame, mask, kind == "people_only"))
    if not out:
        raise ForestError("no readable real frame given (--real / --nobody / --people-only)")
    return out


def person_counts(pred: np.ndarray, depth_mm: np.ndarray, mask: np.ndarray | None
                  ) -> dict[str, int]:
    """Pixel counts of one frame: ``tp`` (person, called), ``fp`` (not a person, called),
    ``fn`` (person, not called), ``background`` (valid, not a person) over valid pixels."""
    valid = np.asarray(depth_mm) > 0
    called = (np.asarray(pred) > 0) & valid
    person = (mask & valid) if mask is not None else np.zeros_like(valid)
    return {"tp": int((called & person).sum()), "fp": int((called & ~person).sum()),
            "fn": int((person & ~called).sum()), "background": int((valid & ~person).sum())}


def person_scores(per_frame: list[dict]) -> dict:
    """The pooled scores of :func:`person_counts` rows (``kind``: one of :data:`KINDS`)."""
    def total(rows: list[dict], k: str) -> int:
        return sum(r[k] for r in rows)

    withp = [r for r in per_frame if r["kind"] == "people"]
    nob = [r for r in per_frame if r["kind"] == "nobody"]
    only = [r for r in per_frame if r["kind"] == "people_only"]
    recalls = [r["tp"] / (r["tp"] + r["fn"]) for r in only if r["tp"] + r["fn"]]
    tp, fp, fn = total(withp, "tp"), total(withp, "fp"), total(withp, "fn")

    def ratio(a: int, b: int) -> float | None:
        return a / b if b else None

    ious = [r["tp"] / (r["tp"] + r["fp"] + r["fn"]) for r in withp
            if r["tp"] + r["fp"] + r["fn"]]
    return {
        "frames_with_people": len(withp), "frames_with_nobody": len(nob),
        "person_iou": ratio(tp, tp + fp + fn),
        "person_iou_mean": float(np.mean(ious)) if ious else None,
        "person_recall": ratio(tp, tp + fn), "person_precision": ratio(tp, tp + fp),
        "background_called": ratio(total(withp + nob, "fp"),
                                   total(withp + nob, "background")),
        "background_called_nobody": ratio(total(nob, "fp"), total(nob, "background")),
        "background_called_people": ratio(fp, total(withp, "background")),
        "people_only": {"frames": len(only),
                        "person_recall": ratio(total(only, "tp"),
                                               total(only, "tp") + total(only, "fn")),
                        "person_recall_mean": float(np.mean(recalls)) if recalls else None},
    }


def evaluate_real(predict: Callable[[DepthFrame], np.ndarray], frames: list[RealFrame], *,
                  out_dir: str | Path | None = None, colors: list | None = None,
                  num_classes: int = 0) -> dict:
    """Score ``predict`` (a frame -> (H, W) uint8 labels) on real frames; ``out_dir``
    gets ``real_sheet.png`` (depth | predicted parts, the mask's outline drawn on both).
    Returns the scores of :func:`person_scores` and the per-frame rows."""
    rows, shown = [], []
    for rf in frames:
        pred = predict(rf.frame)
        c = person_counts(pred, rf.frame.depth_mm, rf.mask)
        n = c["tp"] + c["fp"] + c["fn"]
        rows.append({"frame": rf.frame.path, "kind": rf.kind, "people": rf.mask is not None,
                     **c, "iou": c["tp"] / n if rf.kind == "people" and n else None,
                     "recall": c["tp"] / (c["tp"] + c["fn"]) if c["tp"] + c["fn"] else None,
                     "background_called": c["fp"] / c["background"] if c["background"]
                     else None})
        shown.append((rf, pred))
    res = {**person_scores(rows), "per_frame": rows}
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        real_sheet(shown, colors, num_classes, out / "real_sheet.png")
    return res


def real_sheet(shown: list[tuple[RealFrame, np.ndarray]], colors: list | None,
               num_classes: int, path: Path, scale: float = 0.5) -> Path:
    """Rows of real depth | predicted parts, with the person mask's outline (red)."""
    from PIL import Image, ImageDraw
    from scipy import ndimage

    from vhgen.forest.evaluate import palette_for
    from vhgen.preview import colorize_depth

    pal = palette_for(colors, max(num_classes, int(max((p.max() for _, p in shown),
                                                         default=0)) + 1))
    h, w = shown[0][1].shape if shown else (10, 10)
    th, tw = int(h * scale), int(w * scale)
    sheet = Image.new("RGB", (2 * tw, max(1, len(shown)) * (th + 14)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for r, (rf, pred) in enumerate(shown):
        y = r * (th + 14)
        edge = None
        if rf.mask is not None:
            edge = rf.mask & ~ndimage.binary_erosion(rf.mask, iterations=2)
        for c, (tile, title) in enumerate([(colorize_depth(rf.frame.depth_mm), "depth"),
                                           (pal[pred], "predicted parts")]):
            tile = np.array(tile)
            if edge is not None:
                tile[edge] = (255, 0, 0)
            draw.text((c * tw + 4, y + 1), f"{rf.name}: {title}", fill=(0, 0, 0))
            sheet.paste(Image.fromarray(tile).resize((tw, th), Image.Resampling.NEAREST),
                        (c * tw, y + 13))
    sheet.save(path)
    return path


def table(res: dict) -> str:
    """The real-frame scores as text."""
    def f(v: float | None) -> str:
        return "-" if v is None else f"{v:.3f}"

    shown = {"people": "yes", "nobody": "no", "people_only": "only"}
    lines = [f"{'real frame':<28} {'people':>6} {'IoU':>6} {'recall':>6} {'bg called':>9}"]
    for r in res["per_frame"]:
        lines.append(f"{Path(r['frame']).name:<28} {shown[r['kind']]:>6} "
                     f"{f(r['iou']):>6} {f(r['recall']):>6} {f(r['background_called']):>9}")
    only = res["people_only"]
    if only["frames"]:
        lines.append(f"people only (mask = depth > 0): person recall "
                     f"{f(only['person_recall'])} (mean per frame "
                     f"{f(only['person_recall_mean'])}) over {only['frames']} frames")
    if res["frames_with_people"] or res["frames_with_nobody"]:
        lines.append(f"person IoU {f(res['person_iou'])} (recall {f(res['person_recall'])}, "
                     f"precision {f(res['person_precision'])}) over "
                     f"{res['frames_with_people']} frames with people; background called a "
                     f"body part {f(res['background_called'])} (frames with nobody "
                     f"{f(res['background_called_nobody'])}, around people "
                     f"{f(res['background_called_people'])})")
    return "\n".join(lines)
