"""Contact sheets: depth colour-mapped beside labels in the scheme's palette, with a legend."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vhgen.store.zarr_store import open_store

# Turbo colour map (Mikhailov 2019), polynomial approximation by the author, public domain
_TURBO_R = (0.13572138, 4.61539260, -42.66032258, 132.13108234, -152.94239396, 59.28637943)
_TURBO_G = (0.09140261, 2.19418839, 4.84296658, -14.18503333, 4.27729857, 2.82956604)
_TURBO_B = (0.10667330, 12.64194608, -60.58204836, 110.36276771, -89.90310912, 27.34824973)


def turbo(x: np.ndarray) -> np.ndarray:
    """Values in [0, 1] -> (..., 3) uint8 RGB."""
    x = np.clip(np.asarray(x, np.float64), 0.0, 1.0)
    out = []
    for c in (_TURBO_R, _TURBO_G, _TURBO_B):
        out.append(sum(k * x ** i for i, k in enumerate(c)))
    return (np.clip(np.stack(out, -1), 0, 1) * 255 + 0.5).astype(np.uint8)


def colorize_depth(depth_mm: np.ndarray) -> np.ndarray:
    """uint16 mm -> RGB; near = red, far = blue, no measurement = black."""
    valid = depth_mm > 0
    rgb = np.zeros(depth_mm.shape + (3,), np.uint8)
    if valid.any():
        lo, hi = np.percentile(depth_mm[valid], [1, 99])
        x = (depth_mm.astype(np.float64) - lo) / max(hi - lo, 1.0)
        rgb[valid] = turbo(1.0 - x[valid])
    return rgb


# scene classes (background, floor, wall, prop, person, then user classes) and instances
CLASS_COLORS = np.array([[0, 0, 0], [196, 170, 120], [120, 140, 170], [150, 90, 40],
                         [240, 90, 160], [90, 200, 90], [220, 220, 60], [60, 200, 220]],
                        np.uint8)
INSTANCE_COLORS = np.array([[0, 0, 0], [230, 25, 75], [60, 180, 75], [0, 130, 200],
                            [245, 130, 48], [145, 30, 180], [70, 240, 240], [240, 50, 230]],
                           np.uint8)


def instance_colors(instances: np.ndarray | int) -> np.ndarray:
    """(..., 3) uint8 colour of person instances (0 = no person: black; 1, 2, ... cycle
    through the seven INSTANCE_COLORS after it)."""
    k = np.asarray(instances, np.int64)
    return INSTANCE_COLORS[np.where(k == 0, 0, (k - 1) % (len(INSTANCE_COLORS) - 1) + 1)]


def class_palette(num_classes: int) -> np.ndarray:
    """(max(num_classes, 8), 3) uint8 colours of scene classes: the shipped classes keep
    CLASS_COLORS; user classes beyond take turbo colours at golden-ratio steps (distinct,
    deterministic, neighbouring ids far apart), so each declared class has its own."""
    extra = np.arange(len(CLASS_COLORS), max(int(num_classes), len(CLASS_COLORS)))
    return np.vstack([CLASS_COLORS, turbo((extra * 0.6180339887498949) % 1.0)])


def _scene_tiles(root, frames: list[int]) -> bool:
    """Whether to show the instance and class images: the store has them and the frames
    shown have more than one person or anything besides people."""
    if "instances" not in root or "classes" not in root:
        return False
    names = list(root.attrs.get("class_names", []))
    person = names.index("person") if "person" in names else -1
    for f in frames:
        if (np.asarray(root["instances"][f]) > 1).any():
            return True
        c = np.asarray(root["classes"][f])
        if ((c != 0) & (c != person)).any():
            return True
    return False


def _people_joints(store: Path, frames: list[int]) -> dict[int, list[tuple]]:
    """frame -> [(instance, (J, 2) float pixels, (J,) bool visible)] from the manifest."""
    import pyarrow as pa
    import pyarrow.compute as pc

    from vhgen.errors import StoreError
    from vhgen.store.manifest import read_manifest_table
    from vhgen.store.zarr_store import MANIFEST_FILE

    path = store / MANIFEST_FILE
    if not path.is_file():
        raise StoreError(f"{path}: no manifest (an unfinished job? run it again with "
                         f"--resume)")
    table = read_manifest_table(path, ["frame", "people"])
    wanted = pa.array([int(f) for f in frames], table.schema.field("frame").type)
    table = table.filter(pc.is_in(table.column("frame"), value_set=wanted))
    out: dict[int, list[tuple]] = {}
    for f, people in zip(table.column("frame").to_pylist(), table.column("people").to_pylist(),
                         strict=True):
        out[f] = [(p["instance"], np.asarray(p["joints_px"], np.float64).reshape(-1, 2),
                   np.asarray(p["joints_visible"], bool)) for p in people or []]
    return out


def _draw_joints(draw, people: list[tuple], x0: int, y0: int, scale: float,
                 size: tuple[int, int]) -> None:
    """Each person's 2D joints on the tile at (x0, y0): a filled dot where the joint is
    visible, a ring where it is not (occluded or outside), in the person's instance
    colour."""
    w, h = size
    for instance, px, visible in people:
        color = tuple(int(c) for c in instance_colors(instance))
        for (u, v), vis in zip(px, visible, strict=True):
            if not (0 <= u < w and 0 <= v < h):
                continue
            x, y = x0 + (u + 0.5) * scale, y0 + (v + 0.5) * scale
            box = [x - 2.5, y - 2.5, x + 2.5, y + 2.5]
            if vis:
                draw.ellipse(box, fill=color, outline=(255, 255, 255))
            else:
                draw.ellipse(box, outline=color)


def contact_sheet(store: str | Path, out: str | Path, *, num_frames: int = 6,
                  frames: list[int] | None = None, scale: float = 0.5,
                  joints: bool = False) -> Path:
    """Write a PNG with up to ``num_frames`` evenly spaced frames (depth | labels, and
    instances | classes for scenes) + legend. ``joints``: every person's 2D joints from
    the manifest drawn on the labels tile (filled: visible, ring: occluded or outside)."""
    from PIL import Image, ImageDraw, ImageFont

    root = open_store(store)
    depth, labels = root["depth"], root["labels"]
    names = list(root.attrs["label_names"])
    palette = np.asarray(root.attrs["label_colors"], dtype=np.uint8)
    n = depth.shape[0]
    if frames is None:
        frames = sorted(set(np.linspace(0, n - 1, min(num_frames, n)).round().astype(int)))
    h, w = depth.shape[1:]
    th, tw = int(h * scale), int(w * scale)
    scene = _scene_tiles(root, frames)
    people = _people_joints(Path(store), frames) if joints else {}
    class_names = list(root.attrs.get("class_names", []))
    class_colors = class_palette(len(class_names))
    cols = 4 if scene else 2
    rows = len(frames)
    legend_w = 190
    legend_h = (14 * len(names) + 40 + (14 * len(class_names) + 30 if scene else 0)
                + (40 if joints else 0))
    sheet = Image.new("RGB", (cols * tw + legend_w, max(rows * (th + 16), legend_h)),
                      (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    font = ImageFont.load_default()
    for r, f in enumerate(frames):
        d = np.asarray(depth[f])
        lab = np.asarray(labels[f])
        tiles = [colorize_depth(d), palette[np.minimum(lab, len(palette) - 1)]]
        titles = ["depth (mm)", "labels"]
        if scene:
            inst = np.asarray(root["instances"][f])
            cls = np.asarray(root["classes"][f])
            tiles += [instance_colors(inst),
                      class_colors[np.minimum(cls, len(class_colors) - 1)]]
            titles += ["instances", "classes"]
        y = r * (th + 16)
        for c, title in enumerate(titles):
            draw.text((c * tw + 4, y + 2), f"frame {f}: {title}", fill=(0, 0, 0), font=font)
        for c, tile in enumerate(tiles):
            img = Image.fromarray(tile).resize((tw, th), Image.Resampling.NEAREST)
            sheet.paste(img, (c * tw, y + 14))
        if joints:
            _draw_joints(draw, people.get(f, []), tw, y + 14, tw / w, (w, h))
    x0 = cols * tw + 8
    draw.text((x0, 4), "labels (subject's L/R)", fill=(0, 0, 0), font=font)
    for k, name in enumerate(names, start=1):
        y = 20 + (k - 1) * 14
        draw.rectangle([x0, y, x0 + 12, y + 10], fill=tuple(int(c) for c in palette[k]))
        draw.text((x0 + 18, y - 1), f"{k:2d} {name}", fill=(0, 0, 0), font=font)
    if joints:
        y = 20 + len(names) * 14 + (14 * len(class_names) + 30 if scene else 0) + 10
        draw.ellipse([x0 + 3, y + 2, x0 + 9, y + 8], fill=(80, 80, 80))
        draw.text((x0 + 18, y - 1), "joint visible", fill=(0, 0, 0), font=font)
        draw.ellipse([x0 + 3, y + 16, x0 + 9, y + 22], outline=(80, 80, 80))
        draw.text((x0 + 18, y + 13), "joint hidden", fill=(0, 0, 0), font=font)
    if scene:
        y = 20 + len(names) * 14 + 10
        draw.text((x0, y), "classes", fill=(0, 0, 0), font=font)
        for k, name in enumerate(class_names[1:], 1):
            yy = y + 16 + (k - 1) * 14
            draw.rectangle([x0, yy, x0 + 12, yy + 10], fill=tuple(int(c) for c in
                                                                 class_colors[k]))
            draw.text((x0 + 18, yy - 1), name, fill=(0, 0, 0), font=font)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(out)
    return out
