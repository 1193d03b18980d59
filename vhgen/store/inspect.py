"""Verifying a finished store: ``vhgen inspect STORE``.

Checks, shard by shard (one shard of every array in memory at a time):

* the group and its arrays follow the contract (names, dtypes, (N, H, W) shapes that
  agree with each other, with the ``num_frames`` attribute and with the manifest's
  ``width``/``height``);
* the manifest holds every frame ``0..N-1`` exactly once, each in its own shard;
* every shard file exists (a missing shard reads back silently as fill values in
  Zarr, so absence is checked on disk) and decodes (codec and checksum errors are caught
  per shard and reported with the shard's frame range);
* each frame's ``body_pixels`` (labels > 0) and ``valid_pixels`` (depth > 0), recomputed
  from the arrays, equal the manifest's; labels stay within ``0..K``;
* ``instances`` and ``classes`` (scene stores) agree with ``labels``: a pixel is a body
  part exactly when it belongs to a person instance and has the person class; instance
  ids stay within the frame's ``num_people`` and classes within ``class_names``;
* every shard has its completion record (``manifest/part-<shard>.parquet``) while the
  manifest is not merged (the merge removes the parts).

Each defect is one line saying where. The report also carries the per-part pixel
histogram and valid-pixel statistics of the readable frames.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.scene.geometry import PERSON, SCENE_CLASSES
from vhgen.store.manifest import manifest_form, read_manifest_table
from vhgen.store.zarr_store import (
    ARRAYS,
    MANIFEST_FILE,
    MANIFEST_PARTS,
    REQUIRED_ARRAYS,
    open_store,
)

# array name -> dtype the contract requires; REQUIRED_ARRAYS are mandatory
CONTRACT_ARRAYS = {name: dtype for name, (dtype, _, _) in ARRAYS.items()}


@dataclass
class InspectReport:
    """Outcome of :func:`inspect_store`.

    defects : one human-readable line per defect, each naming the array/shard/frame/column.
    num_frames : N of the arrays (0 if unknown).
    label_names : the K part names (label k is ``label_names[k-1]``).
    histogram : (K+1,) int64 pixel count per label over all readable frames (0 = background).
    valid : per-frame valid-pixel statistics (min / mean / max fraction of the image, and the
        fraction of body pixels that carry a depth), plus the depth range of valid pixels in mm.
    """

    store: str
    defects: list[str] = field(default_factory=list)
    num_frames: int = 0
    frames_per_shard: int = 0
    arrays: dict[str, list[int]] = field(default_factory=dict)
    label_names: list[str] = field(default_factory=list)
    histogram: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    valid: dict[str, float] = field(default_factory=dict)
    frames_checked: int = 0
    manifest_form: int = 0  # 1 or 2 (see vhgen.store.manifest), 0 if there is no manifest
    codecs: dict[str, str] = field(default_factory=dict)  # array -> its frames' codecs

    @property
    def ok(self) -> bool:
        return not self.defects

    def to_dict(self) -> dict[str, Any]:
        total = int(self.histogram.sum())
        parts = ["background", *self.label_names]
        return {
            "store": self.store, "ok": self.ok, "defects": list(self.defects),
            "num_frames": self.num_frames, "frames_per_shard": self.frames_per_shard,
            "frames_checked": self.frames_checked, "arrays": self.arrays,
            "histogram": [{"label": k, "name": parts[k] if k < len(parts) else f"?{k}",
                           "pixels": int(c), "fraction": c / total if total else 0.0}
                          for k, c in enumerate(self.histogram.tolist())],
            "valid": self.valid, "manifest_form": self.manifest_form,
            "codecs": self.codecs,
        }

    def _codec_lines(self) -> list[str]:
        if not self.codecs:
            return []
        groups: dict[str, list[str]] = {}
        for name, codecs in self.codecs.items():
            groups.setdefault(codecs, []).append(name)
        line = "codecs: " + "; ".join(f"{', '.join(n)}: {c}" for c, n in groups.items())
        from vhgen.store.palette import NAME as PALETTE  # (imports zarr: only here)

        if any(PALETTE in c for c in self.codecs.values()):
            return [line, f"({PALETTE} is vhgen's codec: zarr reads it where vhgen is "
                          "installed; output.palette: false writes zarr-spec codecs only)"]
        return [line]

    def format(self) -> str:
        """A plain-text report: summary, histogram table, valid-pixel statistics, defects."""
        d = self.to_dict()
        lines = [f"{self.store}: {self.num_frames} frames in shards of {self.frames_per_shard}, "
                 f"arrays " + ", ".join(f"{k} {v}" for k, v in self.arrays.items()),
                 f"{self.frames_checked} frames read and checked against the manifest",
                 f"manifest form {self.manifest_form}: {_FORMS.get(self.manifest_form, '')}",
                 *self._codec_lines(),
                 "",
                 f"{'label':>5}  {'part':<20} {'pixels':>14} {'% of body':>9}"]
        body = int(self.histogram[1:].sum()) if len(self.histogram) else 0
        for h in d["histogram"]:
            share = "" if h["label"] == 0 or not body else f"{100 * h['pixels'] / body:9.2f}"
            lines.append(f"{h['label']:>5}  {h['name']:<20} {h['pixels']:>14} {share:>9}")
        if self.valid:
            v = self.valid
            lines += ["", "valid pixels per frame (fraction of the image): "
                      f"min {v['min_fraction']:.4f}  mean {v['mean_fraction']:.4f}  "
                      f"max {v['max_fraction']:.4f}",
                      f"body pixels with a depth: {v['body_valid_fraction']:.4f}; "
                      f"depth of valid pixels: {v['depth_min_mm']:.0f}-"
                      f"{v['depth_max_mm']:.0f} mm"]
        lines.append("")
        if self.defects:
            lines.append(f"{len(self.defects)} defect(s):")
            lines += [f"DEFECT {x}" for x in self.defects]
        else:
            lines.append("OK: no defects")
        return "\n".join(lines)


_FORMS = {0: "no readable manifest",
          1: "the old form (people.footprint a fixed-size list; where it is null, only "
             "pyarrow >= 26 or vhgen's own reader opens it)",
          2: "portable (no null inside a fixed-size list; any Parquet reader opens it)"}


def _codec_names(meta_path: Path) -> str:
    """The codecs of one array's frames, in order ("bytes > vhgen.palette rows > zstd 3"), as
    its zarr.json names them (inside the shards when it is sharded)."""
    try:
        codecs = json.loads(meta_path.read_text())["codecs"]
        if len(codecs) == 1 and codecs[0].get("name") == "sharding_indexed":
            codecs = codecs[0]["configuration"]["codecs"]
        names = []
        for c in codecs:
            conf = c.get("configuration") or {}
            level = conf.get("level", conf.get("clevel"))
            cname = f" {conf['cname']}" if "cname" in conf else ""
            rows = " rows" if conf.get("rows") is True else ""  # vhgen.palette's differences
            names.append(f"{c['name']}{cname}{rows}"
                         + (f" {level}" if level is not None else ""))
        return " > ".join(names)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return "unknown"


def _shard_file(store: Path, name: str, shard: int) -> Path:
    # default v3 chunk key encoding of a (frame, y, x) shard grid: <array>/c/<shard>/0/0
    return store / name / "c" / str(shard) / "0" / "0"


def _check_manifest(rep: InspectReport, man, n: int, fps: int, shape: tuple[int, ...]) -> dict:
    """Frame coverage and per-row consistency; returns frame -> manifest row index."""
    cols = set(man.column_names)
    for c in ("frame", "valid_pixels", "body_pixels"):
        if c not in cols:
            rep.defects.append(f"{MANIFEST_FILE}: column {c!r} missing")
    if "frame" not in cols:
        return {}
    frames = man.column("frame").to_numpy()
    row_of: dict[int, int] = {}
    dups: dict[int, list[int]] = {}
    for r, f in enumerate(frames.tolist()):
        if f in row_of:
            dups.setdefault(f, [row_of[f]]).append(r)
        else:
            row_of[f] = r
    for f, rows in sorted(dups.items()):
        rep.defects.append(f"{MANIFEST_FILE}: frame {f} appears {len(rows)} times "
                           f"(rows {', '.join(map(str, rows))})")
    out_of_range = sorted(f for f in row_of if not 0 <= f < n)
    if out_of_range:
        rep.defects.append(f"{MANIFEST_FILE}: frames {_ranges(out_of_range)} are outside the "
                           f"arrays' 0..{n - 1}")
    missing = sorted(set(range(n)) - set(row_of))
    if missing:
        rep.defects.append(f"{MANIFEST_FILE}: no row for frames {_ranges(missing)} "
                           f"(shards {_ranges(sorted({f // fps for f in missing}))})")
    if "shard" in cols:
        shards = man.column("shard").to_numpy()
        bad = [f for f, r in row_of.items() if fps and shards[r] != f // fps]
        if bad:
            rep.defects.append(f"{MANIFEST_FILE}: frames {_ranges(sorted(bad))} name the wrong "
                               f"shard (expected frame // {fps})")
    for c, want in (("height", shape[1]), ("width", shape[2])):
        if c in cols:
            vals = man.column(c).to_numpy()
            bad = sorted(f for f, r in row_of.items() if vals[r] != want)
            if bad:
                rep.defects.append(f"{MANIFEST_FILE}: frames {_ranges(bad)} have {c} != the "
                                   f"arrays' {want}")
    return row_of


def _ranges(values: list[int]) -> str:
    """[1, 2, 3, 7] -> '1-3, 7' (at most 8 runs, then '...')."""
    runs: list[str] = []
    i = 0
    while i < len(values):
        j = i
        while j + 1 < len(values) and values[j + 1] == values[j] + 1:
            j += 1
        runs.append(str(values[i]) if i == j else f"{values[i]}-{values[j]}")
        i = j + 1
    return ", ".join(runs[:8]) + (f", ... ({len(values)} in all)" if len(runs) > 8 else "")


def inspect_store(path: str | Path) -> InspectReport:
    """Verify the store at ``path``; never raises for a defect inside the store.

    Raises :class:`StoreError` only when ``path`` is not a Zarr v3 group at all.
    """
    import pyarrow.parquet as pq

    store = Path(path)
    root = open_store(store)
    rep = InspectReport(store=str(store))
    attrs = dict(root.attrs)
    names = attrs.get("label_names")
    if not isinstance(names, list):
        rep.defects.append("attributes: 'label_names' missing")
        names = []
    rep.label_names = [str(x) for x in names]
    k = len(rep.label_names)

    arrays: dict[str, Any] = {}
    # listing the group's members warns about manifest.parquet and report.json, which Zarr
    # does not know; the contract's array names are fixed, so look for their metadata
    members = {n for n in CONTRACT_ARRAYS if (store / n / "zarr.json").is_file()}
    for name in REQUIRED_ARRAYS:
        if name not in members:
            rep.defects.append(f"array {name!r} missing")
    for name, dtype in CONTRACT_ARRAYS.items():
        if name not in members:
            continue
        a = root[name]
        rep.arrays[name] = list(a.shape)
        rep.codecs[name] = _codec_names(store / name / "zarr.json")
        if str(a.dtype) != dtype:
            rep.defects.append(f"array {name!r}: dtype {a.dtype}, the contract says {dtype}")
        if a.ndim != 3:
            rep.defects.append(f"array {name!r}: shape {a.shape} is not (N, H, W)")
            continue
        arrays[name] = a
    shapes = {tuple(a.shape) for a in arrays.values()}
    if len(shapes) > 1:
        rep.defects.append("arrays disagree on shape: " +
                           ", ".join(f"{n} {list(a.shape)}" for n, a in arrays.items()))
    if "depth" not in arrays or "labels" not in arrays:
        return rep
    shape = tuple(arrays["depth"].shape)
    n = rep.num_frames = int(shape[0])
    if attrs.get("num_frames") not in (None, n):
        rep.defects.append(f"attributes: num_frames {attrs['num_frames']} but the arrays hold "
                           f"{n} frames")
    fps = int(arrays["depth"].shards[0]) if arrays["depth"].shards else int(
        arrays["depth"].chunks[0])
    rep.frames_per_shard = fps
    for name, a in arrays.items():
        a_fps = a.shards[0] if a.shards else a.chunks[0]
        if a_fps != fps:
            rep.defects.append(f"array {name!r}: {a_fps} frames per shard, depth has {fps}")

    man_path = store / MANIFEST_FILE
    man = None
    row_of: dict[int, int] = {}
    if not man_path.is_file():
        rep.defects.append(f"{MANIFEST_FILE} missing (job not finished? run "
                           "'vhgen generate ... --resume')")
    else:
        try:
            rep.manifest_form = manifest_form(pq.read_schema(man_path))
            man = read_manifest_table(man_path)
        except Exception as e:  # pyarrow raises several types for a damaged file
            rep.defects.append(f"{MANIFEST_FILE}: unreadable ({type(e).__name__}: {e})")
        if man is not None:
            row_of = _check_manifest(rep, man, n, fps, shape)
    valid_col = (man.column("valid_pixels").to_numpy()
                 if man is not None and "valid_pixels" in man.column_names else None)
    body_col = (man.column("body_pixels").to_numpy()
                if man is not None and "body_pixels" in man.column_names else None)
    people_col = (man.column("num_people").to_numpy()
                  if man is not None and "num_people" in man.column_names else None)
    num_classes = len(attrs.get("class_names", SCENE_CLASSES))

    hist = np.zeros(max(k + 1, 1), np.int64)
    valid_frac: list[float] = []
    body_total = body_valid = 0
    dmin, dmax = np.iinfo(np.uint16).max, 0
    npix = shape[1] * shape[2]
    num_shards = math.ceil(n / fps) if fps else 0
    parts = store / MANIFEST_PARTS
    for s in range(num_shards):
        start, stop = s * fps, min(n, (s + 1) * fps)
        where = f"shard {s} (frames {start}-{stop - 1})"
        if man is None and not (parts / f"part-{s:06d}.parquet").is_file():
            rep.defects.append(f"{where}: completion record {MANIFEST_PARTS}/part-{s:06d}.parquet "
                               "missing")
        data: dict[str, np.ndarray] = {}
        for name, a in arrays.items():
            f = _shard_file(store, name, s)
            if not f.is_file():
                rep.defects.append(f"{name} {where}: shard file {f.relative_to(store)} missing")
                continue
            try:
                data[name] = np.asarray(a[start:stop])
            except Exception as e:  # zarr/codec errors come as several exception types
                rep.defects.append(f"{name} {where}: unreadable ({type(e).__name__}: "
                                   f"{str(e)[:160]})")
        if "labels" in data:
            lab = data["labels"]
            top = int(lab.max()) if lab.size else 0
            if top > k:
                bad = [start + i for i in range(len(lab)) if lab[i].max() > k]
                rep.defects.append(f"labels {where}: label {top} > K={k} in frames "
                                   f"{_ranges(bad)}")
            hist += np.bincount(lab.reshape(-1), minlength=len(hist))[:len(hist)]
        for i in range(stop - start):
            frame = start + i
            rep.frames_checked += int("labels" in data and "depth" in data)
            r = row_of.get(frame)
            if "labels" in data:
                body = int((data["labels"][i] > 0).sum())
                if r is not None and body_col is not None and body != int(body_col[r]):
                    rep.defects.append(f"frame {frame} ({where}): labels have {body} body pixels, "
                                       f"manifest body_pixels says {int(body_col[r])}")
            if "labels" in data:
                _check_scene_arrays(rep, data, i, frame, where, num_classes,
                                    int(people_col[r]) if r is not None and
                                    people_col is not None else None)
            if "depth" in data:
                dep = data["depth"][i]
                valid = dep > 0
                nv = int(valid.sum())
                if r is not None and valid_col is not None and nv != int(valid_col[r]):
                    rep.defects.append(f"frame {frame} ({where}): depth has {nv} valid pixels, "
                                       f"manifest valid_pixels says {int(valid_col[r])}")
                valid_frac.append(nv / npix)
                if nv:
                    dmin = min(dmin, int(dep[valid].min()))
                    dmax = max(dmax, int(dep[valid].max()))
                if "labels" in data:
                    on_body = data["labels"][i] > 0
                    body_total += int(on_body.sum())
                    body_valid += int((on_body & valid).sum())
    rep.histogram = hist
    if valid_frac:
        rep.valid = {"min_fraction": float(np.min(valid_frac)),
                     "mean_fraction": float(np.mean(valid_frac)),
                     "max_fraction": float(np.max(valid_frac)),
                     "body_valid_fraction": body_valid / body_total if body_total else 0.0,
                     "depth_min_mm": float(dmin if dmax else 0), "depth_max_mm": float(dmax)}
    return rep


def report_json(rep: InspectReport) -> str:
    """The report as indented JSON (for ``vhgen inspect --json``)."""
    return json.dumps(rep.to_dict(), indent=1)


__all__ = ["InspectReport", "inspect_store", "report_json"]


def _check_scene_arrays(rep: InspectReport, data: dict[str, np.ndarray], i: int, frame: int,
                        where: str, num_classes: int, num_people: int | None) -> None:
    """instances/classes of frame ``frame`` (row ``i`` of the shard) against its labels."""
    body = data["labels"][i] > 0
    if "instances" in data:
        inst = data["instances"][i]
        if (n := int(np.count_nonzero((inst > 0) != body))):
            rep.defects.append(f"frame {frame} ({where}): instances and labels disagree on "
                               f"{n} pixels (person without body part or the reverse)")
        top = int(inst.max())
        if num_people is not None and top > num_people:
            rep.defects.append(f"frame {frame} ({where}): instance {top} but the manifest "
                               f"row has num_people {num_people}")
    if "classes" in data:
        cls = data["classes"][i]
        if (top := int(cls.max())) >= num_classes:
            rep.defects.append(f"frame {frame} ({where}): class {top} is not in class_names "
                               f"(0..{num_classes - 1})")
        if (n := int(np.count_nonzero((cls == PERSON) != body))):
            rep.defects.append(f"frame {frame} ({where}): classes and labels disagree on "
                               f"{n} pixels (person class without body part or the reverse)")
