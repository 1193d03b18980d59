"""Real depth in: one reader for organized PCD clouds and 16-bit millimetre PNGs.

:func:`read_depth` turns a file into a :class:`DepthFrame` (uint16 millimetres, 0 = no
measurement, the convention of vhgen's stores and of OpenNI depth), with the camera's
intrinsics recovered from an organized cloud (:func:`recover_intrinsics`) or given by the
caller. :func:`iter_depth_files` walks files and folders and yields one frame or one
error line per file, so one bad file never stops a corpus. :func:`write_pcd` writes all
three PCD encodings. Pure NumPy at import; numba (LZF) and PIL load inside the functions.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vhgen.camera import Intrinsics, backproject
from vhgen.errors import DepthFileError

__all__ = ["DEPTH_SUFFIXES", "DepthFrame", "iter_depth_files", "read_depth", "recover_intrinsics",
           "write_pcd"]

DEPTH_SUFFIXES = (".pcd", ".png")
# Largest RMS (px) of the pinhole fit u = fx x/z + cx, v = fy y/z + cy that is still a
# pinhole image: OpenNI clouds fit to ~1e-4 px (float32 x, y of integer-mm z).
MAX_PINHOLE_RESIDUAL_PX = 0.05


@dataclass(frozen=True)
class DepthFrame:
    """One real depth image.

    depth_mm : (H, W) uint16 planar depth in millimetres, 0 = no measurement (read-only).
    intrinsics : recovered from an organized cloud, or given; None when unknown (a PNG).
    source_format : ``pcd-ascii``, ``pcd-binary``, ``pcd-binary_compressed`` or ``png``.
    """

    path: str
    depth_mm: np.ndarray
    intrinsics: Intrinsics | None
    source_format: str

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool: pixels with a measurement."""
        return self.depth_mm > 0

    @property
    def depth_m(self) -> np.ndarray:
        """(H, W) float64 metres, 0 = no measurement."""
        return self.depth_mm.astype(np.float64) / 1000.0


def recover_intrinsics(points: np.ndarray, path: str | Path = "<cloud>") -> Intrinsics:
    """Pinhole intrinsics of an organized cloud (H, W, 3) metres, NaN = no measurement.

    Least squares of the column u against x/z gives fx, cx; of the row v against y/z gives
    fy, cy (pixel centres at integer coordinates, row 0 on top). DepthFileError naming
    ``path`` when fewer than 100 points are valid, when the points do not span rows and
    columns, or when the RMS residual of either fit exceeds
    :data:`MAX_PINHOLE_RESIDUAL_PX` (the cloud is not a pinhole image: resampled,
    distorted or not in the camera frame).
    """
    p = np.asarray(points, np.float64)
    h, w = p.shape[:2]
    z = p[..., 2]
    ok = np.isfinite(p).all(-1) & (z > 0)
    if ok.sum() < 100:
        raise DepthFileError(path, f"only {int(ok.sum())} valid points: cannot recover the "
                                   "intrinsics (give them)")
    v, u = np.nonzero(ok)
    fit = []
    for axis, pix, name in ((0, u, "column"), (1, v, "row")):
        a = p[v, u, axis] / z[v, u]
        if np.ptp(a) <= 0 or np.ptp(pix) == 0:
            raise DepthFileError(path, f"the points do not span the image {name}s: cannot "
                                       "recover the intrinsics")
        design = np.stack([a, np.ones_like(a)], -1)
        (f, c), *_ = np.linalg.lstsq(design, pix.astype(np.float64), rcond=None)
        rms = float(np.sqrt(np.mean((pix - (f * a + c)) ** 2)))
        if rms > MAX_PINHOLE_RESIDUAL_PX or f <= 0:
            raise DepthFileError(path, f"not a pinhole image: {name} = f * {'xy'[axis]}/z + c "
                                       f"fits with f = {f:.1f}, RMS residual {rms:.3g} px "
                                       f"(at most {MAX_PINHOLE_RESIDUAL_PX} px expected)")
        fit.append((float(f), float(c)))
    (fx, cx), (fy, cy) = fit
    return Intrinsics(w, h, fx, fy, cx, cy)


def _tidy(x: float) -> float:
    """Fitted values within 1e-3 of a round 0.5 px are that value (525.0000004 -> 525)."""
    r = round(x * 2) / 2
    return r if abs(x - r) < 1e-3 else x


def _points_to_mm(z: np.ndarray) -> np.ndarray:
    """Planar depth in metres (NaN, inf, <= 0 = none) -> uint16 mm; depth past 65.535 m
    cannot be held in uint16 and counts as no measurement."""
    mm = np.where(np.isfinite(z) & (z > 0), np.rint(z * 1000.0), 0.0)
    return np.where(mm <= 65535, mm, 0).astype(np.uint16)


def read_png_mm(path: str | Path) -> np.ndarray:
    """A single-channel 16-bit PNG of millimetres -> (H, W) uint16; DepthFileError else."""
    from PIL import Image, UnidentifiedImageError

    p = Path(path)
    try:
        with Image.open(p) as im:
            mode = im.mode
            fmt = im.format
            arr = np.array(im)
    except (UnidentifiedImageError, OSError) as e:
        raise DepthFileError(p, f"not an image ({e})") from None
    if arr.ndim != 2 or mode not in ("I;16", "I;16B", "I;16L", "I"):
        raise DepthFileError(p, f"expected a single-channel 16-bit depth PNG in millimetres, "
                                f"got a {fmt} of mode {mode}, shape {arr.shape}")
    if arr.min(initial=0) < 0 or arr.max(initial=0) > 65535:
        raise DepthFileError(p, "depth values outside 0..65535 mm")
    return arr.astype(np.uint16)


def read_depth(path: str | Path, intrinsics: Intrinsics | None = None) -> DepthFrame:
    """A depth file -> :class:`DepthFrame`.

    ``.pcd``: an organized cloud (see :mod:`vhgen.depthfile.pcd`); depth is its z in mm,
    NaN = no measurement; the intrinsics are recovered from x/z and y/z unless given
    (given ones are used as they are). ``.png``: 16-bit single channel, millimetres.
    Anything else, or a malformed file, is a DepthFileError naming the file.
    """
    p = Path(path)
    if not p.is_file():
        raise DepthFileError(p, "no such file")
    suffix = p.suffix.lower()
    if suffix == ".png":
        mm = read_png_mm(p)
        fmt = "png"
        intr = intrinsics
    elif suffix == ".pcd":
        from vhgen.depthfile.pcd import read_pcd_points

        header, pts = read_pcd_points(p)
        mm = _points_to_mm(pts[..., 2])
        fmt = f"pcd-{header.data}"
        if intrinsics is None:
            r = recover_intrinsics(pts, p)
            intr = Intrinsics(r.width, r.height, _tidy(r.fx), _tidy(r.fy), _tidy(r.cx),
                              _tidy(r.cy))
        else:
            intr = intrinsics
    else:
        raise DepthFileError(p, f"unknown depth file type {p.suffix!r} (expected "
                                f"{' or '.join(DEPTH_SUFFIXES)})")
    if intr is not None and (intr.width, intr.height) != (mm.shape[1], mm.shape[0]):
        raise DepthFileError(p, f"{mm.shape[1]}x{mm.shape[0]} px, the intrinsics are for "
                                f"{intr.width}x{intr.height}")
    mm.setflags(write=False)
    return DepthFrame(str(p), mm, intr, fmt)


def depth_files(paths: Iterable[str | Path]) -> list[Path]:
    """Files as given, folders expanded to their ``.pcd``/``.png`` files (recursively,
    sorted); a path that does not exist is kept (reading it gives its error line)."""
    out: list[Path] = []
    for item in paths:
        p = Path(item)
        if p.is_dir():
            out += sorted(f for f in p.rglob("*") if f.is_file()
                          and f.suffix.lower() in DEPTH_SUFFIXES)
        else:
            out.append(p)
    return out


def iter_depth_files(paths: Iterable[str | Path], intrinsics: Intrinsics | None = None
                     ) -> Iterator[DepthFrame | DepthFileError]:
    """Every depth file under ``paths`` (see :func:`depth_files`) read with
    :func:`read_depth`: a DepthFrame, or the DepthFileError (one line, naming the file) in
    its place, so one bad file never stops a folder."""
    for f in depth_files(paths):
        try:
            yield read_depth(f, intrinsics)
        except DepthFileError as e:
            yield e


def write_pcd(path: str | Path, data: np.ndarray, intrinsics: Intrinsics | None = None, *,
              encoding: str = "binary_compressed", rgb: np.ndarray | None = None,
              version: str = "0.7") -> Path:
    """Write an organized PCD: ``data`` is a depth image (H, W) uint16 mm (0 = none, back-
    projected through ``intrinsics``, which it then needs) or points (H, W, 3) metres (NaN
    = none). ``encoding``: ascii, binary or binary_compressed (LZF with back-references).
    Points with no measurement are written as NaN, as OpenNI grabbers do."""
    from vhgen.depthfile.pcd import write_pcd_points

    a = np.asarray(data)
    if a.ndim == 2:
        if intrinsics is None:
            raise ValueError("a depth image needs the intrinsics to become points")
        z = a.astype(np.float64) / 1000.0
        pts = backproject(intrinsics, z)
        pts[a == 0] = np.nan
    elif a.ndim == 3 and a.shape[2] == 3:
        pts = a.astype(np.float64)
    else:
        raise ValueError(f"data must be (H, W) depth in mm or (H, W, 3) points, got {a.shape}")
    return write_pcd_points(path, pts, encoding=encoding, rgb=rgb, version=version)
