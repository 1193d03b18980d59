"""PCD (Point Cloud Library) files: header, the three DATA encodings, and a writer.

Read: ``VERSION`` 0.7 (and the older 0.6-style headers: ``.6``/``.7`` spellings,
``COLUMNS`` for ``FIELDS``, no ``VIEWPOINT``, no ``COUNT`` meaning 1 each), ``DATA ascii``,
``binary`` (records of all fields one after the other, little-endian) and
``binary_compressed`` (two uint32, compressed and uncompressed size, then LZF of the
fields one after the other: every x, then every y, ...). ``SIZE``/``TYPE``/``COUNT`` are
honoured for every field (F 4/8, I and U 1/2/4/8); only x, y and z are kept.

Every defect is a :class:`vhgen.errors.DepthFileError` naming the file and what is wrong.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vhgen.errors import DepthFileError

ENCODINGS = ("ascii", "binary", "binary_compressed")
_TYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("I", 1): "<i1", ("I", 2): "<i2",
          ("I", 4): "<i4", ("I", 8): "<i8", ("U", 1): "<u1", ("U", 2): "<u2",
          ("U", 4): "<u4", ("U", 8): "<u8"}
_KEYS = ("VERSION", "FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT",
         "VIEWPOINT", "POINTS", "DATA")
MAX_HEADER = 64 * 1024


@dataclass(frozen=True)
class PCDHeader:
    """The parsed header; ``offset`` is where the data starts in the file."""

    fields: tuple[str, ...]
    sizes: tuple[int, ...]
    types: tuple[str, ...]
    counts: tuple[int, ...]
    width: int
    height: int
    points: int
    data: str
    offset: int

    @property
    def point_size(self) -> int:
        """Bytes per point (all fields, all counts)."""
        return sum(s * c for s, c in zip(self.sizes, self.counts, strict=True))

    def dtype(self, i: int) -> np.dtype:
        return np.dtype(_TYPES[(self.types[i], self.sizes[i])])


def _ints(path: Path, key: str, vals: list[str], lo: int = 0) -> tuple[int, ...]:
    try:
        out = tuple(int(v) for v in vals)
    except ValueError:
        raise DepthFileError(path, f"header {key}: not integers: {' '.join(vals)}") from None
    if any(v < lo for v in out):
        raise DepthFileError(path, f"header {key}: values must be >= {lo}: {' '.join(vals)}")
    return out


def parse_header(path: Path, raw: bytes) -> PCDHeader:
    """The header of a PCD file whose bytes are ``raw``; DepthFileError if malformed."""
    entries: dict[str, list[str]] = {}
    pos = 0
    while True:
        end = raw.find(b"\n", pos)
        if end < 0 or end > MAX_HEADER:
            raise DepthFileError(path, "not a PCD file (no DATA line in the header)")
        try:
            line = raw[pos:end].decode("ascii").strip()
        except UnicodeDecodeError:
            raise DepthFileError(path, "not a PCD file (binary bytes in the header)") from None
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *vals = line.split()
        if key not in _KEYS:
            raise DepthFileError(path, f"not a PCD file (unknown header line {line[:40]!r})")
        if key in entries:
            raise DepthFileError(path, f"header {key} appears twice")
        entries[key] = vals
        if key == "DATA":
            break
    fields = entries.get("FIELDS", entries.get("COLUMNS"))
    if not fields:
        raise DepthFileError(path, "header has no FIELDS")
    n = len(fields)
    for key in ("SIZE", "TYPE"):
        if key not in entries:
            raise DepthFileError(path, f"header has no {key}")
    sizes = _ints(path, "SIZE", entries["SIZE"], 1)
    types = tuple(t.upper() for t in entries["TYPE"])
    counts = _ints(path, "COUNT", entries["COUNT"], 1) if "COUNT" in entries else (1,) * n
    for key, count in (("SIZE", len(sizes)), ("TYPE", len(types)), ("COUNT", len(counts))):
        if count != n:
            raise DepthFileError(path, f"header {key} has {count} entries for {n} FIELDS")
    for f, s, t in zip(fields, sizes, types, strict=True):
        if (t, s) not in _TYPES:
            raise DepthFileError(path, f"header: field {f} has TYPE {t} SIZE {s} "
                                       "(expected F 4/8, I or U 1/2/4/8)")
    if "WIDTH" not in entries:
        raise DepthFileError(path, "header has no WIDTH")
    width, = _ints(path, "WIDTH", entries["WIDTH"][:1] or ["x"], 0)
    height, = _ints(path, "HEIGHT", entries.get("HEIGHT", ["1"])[:1] or ["x"], 0)
    points = (_ints(path, "POINTS", entries["POINTS"][:1] or ["x"], 0)[0]
              if "POINTS" in entries else width * height)
    if points != width * height:
        raise DepthFileError(path, f"header POINTS {points} is not WIDTH*HEIGHT "
                                   f"({width}*{height} = {width * height})")
    data = (entries["DATA"] or [""])[0].lower()
    if data not in ENCODINGS:
        raise DepthFileError(path, f"header DATA {data!r}: expected one of {', '.join(ENCODINGS)}")
    return PCDHeader(tuple(fields), sizes, types, counts, width, height, points, data, pos)


def _field_from_soa(h: PCDHeader, blob: np.ndarray, i: int) -> np.ndarray:
    """Field i's first component, (points,) float64, from the field-after-field layout."""
    start = sum(h.sizes[k] * h.counts[k] for k in range(i)) * h.points
    n = h.sizes[i] * h.counts[i] * h.points
    vals = blob[start:start + n].view(h.dtype(i)).reshape(h.points, h.counts[i])
    return vals[:, 0].astype(np.float64)


def _read_xyz(path: Path, h: PCDHeader, raw: bytes) -> np.ndarray:
    """(points, 3) float64 x, y, z (other fields skipped)."""
    idx = [h.fields.index(f) for f in ("x", "y", "z")]
    body = raw[h.offset:]
    if h.data == "ascii":
        per_point = sum(h.counts)
        text = body.decode("ascii", errors="replace")
        lines = [ln for ln in text.splitlines() if ln.strip()]
        if len(lines) != h.points:
            raise DepthFileError(path, f"DATA ascii has {len(lines)} points, the header says "
                                       f"{h.points}")
        try:
            vals = np.array(text.split(), dtype=np.float64)
        except ValueError:
            raise DepthFileError(path, "DATA ascii holds a value that is not a number") from None
        if vals.size != h.points * per_point:
            raise DepthFileError(path, f"DATA ascii has {vals.size} values, expected "
                                       f"{h.points} points x {per_point}")
        vals = vals.reshape(h.points, per_point)
        cols = np.cumsum((0,) + h.counts)
        return np.stack([vals[:, cols[i]] for i in idx], -1)
    if h.data == "binary":
        need = h.points * h.point_size
        if len(body) < need:
            raise DepthFileError(path, f"DATA binary truncated: {len(body)} bytes, expected "
                                       f"{need} ({h.points} points x {h.point_size} bytes)")
        names = [f"f{k}" for k in range(len(h.fields))]
        dt = np.dtype({"names": names,
                       "formats": [(h.dtype(k), (c,)) if c > 1 else h.dtype(k)
                                   for k, c in enumerate(h.counts)]})
        rec = np.frombuffer(body, dt, count=h.points)
        return np.stack([np.asarray(rec[names[i]], np.float64).reshape(h.points, -1)[:, 0]
                         for i in idx], -1)
    from vhgen.depthfile import lzf

    if len(body) < 8:
        raise DepthFileError(path, "DATA binary_compressed truncated: no size words")
    csize, usize = (int(v) for v in np.frombuffer(body[:8], "<u4"))
    need = h.points * h.point_size
    if usize != need:
        raise DepthFileError(path, f"DATA binary_compressed: uncompressed size {usize} bytes, "
                                   f"expected {need} ({h.points} points x {h.point_size} bytes)")
    if len(body) - 8 < csize:
        raise DepthFileError(path, f"DATA binary_compressed truncated: {len(body) - 8} bytes "
                                   f"of the {csize} the header words say")
    try:
        blob = lzf.decompress(body[8:8 + csize], usize)
    except ValueError as e:
        raise DepthFileError(path, f"DATA binary_compressed: {e}") from None
    return np.stack([_field_from_soa(h, blob, i) for i in idx], -1)


def read_pcd_points(path: str | Path) -> tuple[PCDHeader, np.ndarray]:
    """An organized PCD file -> (header, (HEIGHT, WIDTH, 3) float64 x y z, NaN = none)."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise DepthFileError(p, f"cannot read ({e.strerror or e})") from None
    h = parse_header(p, raw)
    missing = [f for f in ("x", "y", "z") if f not in h.fields]
    if missing:
        raise DepthFileError(p, f"no {'/'.join(missing)} field (FIELDS {' '.join(h.fields)})")
    if h.height <= 1 or h.width <= 1:
        raise DepthFileError(p, f"an unorganized cloud (WIDTH {h.width} HEIGHT {h.height}): "
                                "a depth image needs an organized one (rows x columns)")
    xyz = _read_xyz(p, h, raw)
    return h, xyz.reshape(h.height, h.width, 3)


def _header(fields: list[tuple[str, str, int]], width: int, height: int, data: str,
            version: str) -> bytes:
    lines = [f"# .PCD v{version} - Point Cloud Data file format", f"VERSION {version}",
             "FIELDS " + " ".join(f for f, _, _ in fields),
             "SIZE " + " ".join(str(np.dtype(d).itemsize) for _, d, _ in fields),
             "TYPE " + " ".join(np.dtype(d).kind.upper() for _, d, _ in fields),
             "COUNT " + " ".join(str(c) for _, _, c in fields),
             f"WIDTH {width}", f"HEIGHT {height}"]
    if version == "0.7":
        lines.append("VIEWPOINT 0 0 0 1 0 0 0")
    lines += [f"POINTS {width * height}", f"DATA {data}"]
    return ("\n".join(lines) + "\n").encode("ascii")


def write_pcd_points(path: str | Path, points: np.ndarray, *, encoding: str = "binary_compressed",
                     rgb: np.ndarray | None = None, version: str = "0.7") -> Path:
    """Write an organized cloud: ``points`` (H, W, 3) metres (NaN = no measurement) as
    float32 x y z, plus a PCL-packed ``rgb`` float field when ``rgb`` (H, W, 3) uint8 is
    given. ``encoding`` is one of :data:`ENCODINGS`; ``version`` ``0.7`` or ``0.6`` (no
    VIEWPOINT line)."""
    if encoding not in ENCODINGS:
        raise ValueError(f"encoding must be one of {ENCODINGS}, got {encoding!r}")
    if version not in ("0.7", "0.6"):
        raise ValueError(f"version must be 0.7 or 0.6, got {version!r}")
    pts = np.asarray(points, np.float32)
    if pts.ndim != 3 or pts.shape[2] != 3:
        raise ValueError(f"points must be (H, W, 3), got {pts.shape}")
    h, w, _ = pts.shape
    cols: list[tuple[str, np.ndarray]] = [(n, pts[..., k].reshape(-1)) for k, n in
                                          enumerate("xyz")]
    if rgb is not None:
        c = np.asarray(rgb, np.uint8).reshape(h * w, 3).astype(np.uint32)
        packed = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
        cols.append(("rgb", packed.view(np.float32)))  # PCL packs rgb into a float
    spec = [(n, "<f4", 1) for n, _ in cols]
    head = _header(spec, w, h, encoding, version)
    if encoding == "ascii":
        import io

        buf = io.StringIO()  # %.9g: every float32 reads back bit for bit
        np.savetxt(buf, np.stack([a for _, a in cols], -1).astype(np.float64), fmt="%.9g")
        body = buf.getvalue().encode("ascii")
    elif encoding == "binary":
        body = np.stack([a for _, a in cols], -1).astype("<f4").tobytes()
    else:
        from vhgen.depthfile import lzf

        soa = b"".join(a.astype("<f4").tobytes() for _, a in cols)
        comp = lzf.compress(soa)
        body = np.array([len(comp), len(soa)], "<u4").tobytes() + comp
    out = Path(path)
    out.write_bytes(head + body)
    return out
