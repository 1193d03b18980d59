"""BVH motion capture: a strict parser and float64 forward kinematics vectorised over frames.

Conventions
-----------
* Rotation channels are intrinsic Euler angles in degrees applied in channel order:
  a joint with ``Zrotation Yrotation Xrotation`` has local rotation Rz @ Ry @ Rx.
* Position channels *replace* the joint's OFFSET (Blender's and most tools' reading);
  missing position axes keep the OFFSET component.
* Local transform of joint j: ``x_parent = R_j @ x_j + t_j``; world rotations and
  positions are composed root first.
* Lengths stay in the file's own units; :mod:`vhgen.mocap.retarget` converts.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vhgen.errors import BVHError
from vhgen.rotations import euler_to_matrix

_ROT = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
_POS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}


@dataclass(frozen=True, eq=False)
class Motion:
    """A parsed BVH clip.

    Attributes
    ----------
    names : joint names in file order, End Sites excluded.
    parents : (J,) int64, parent index, -1 for the root(s).
    offsets : (J, 3) float64 OFFSETs in file units.
    end_sites : (J, 3) float64 End Site offset of each joint (NaN where it has none).
    channels : per joint, the channel names in file order.
    frame_time : seconds per frame.
    rotations : (F, J, 3, 3) float64 local rotation matrices.
    translations : (F, J, 3) float64 local translations (OFFSET or position channels).
    source : file path, or None for a string.
    """

    names: list[str]
    parents: np.ndarray
    offsets: np.ndarray
    end_sites: np.ndarray
    channels: list[tuple[str, ...]]
    frame_time: float
    rotations: np.ndarray
    translations: np.ndarray
    source: str | None = None
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def num_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of the joint called ``name``."""
        return self.names.index(name)

    def world_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """World rotations (F, J, 3, 3) and positions (F, J, 3), float64, file units."""
        if "world" not in self._cache:
            self._cache["world"] = forward_kinematics(
                self.parents, self.rotations, self.translations)
        return self._cache["world"]

    def world_positions(self) -> np.ndarray:
        """(F, J, 3) float64 joint positions in the file's own units."""
        return self.world_transforms()[1]

    def rest_positions(self) -> np.ndarray:
        """(J, 3) joint positions with every rotation zero and every translation the OFFSET."""
        f = forward_kinematics(self.parents, np.eye(3)[None, None].repeat(self.num_joints, 1),
                               self.offsets[None])
        return f[1][0]


def forward_kinematics(parents: np.ndarray, rotations: np.ndarray,
                       translations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Compose local transforms root first.

    parents : (J,) int, each parent index below its child's.
    rotations : (..., J, 3, 3); translations : (..., J, 3).
    Returns world rotations (..., J, 3, 3) and world positions (..., J, 3), float64.
    """
    rotations = np.asarray(rotations, dtype=np.float64)
    translations = np.asarray(translations, dtype=np.float64)
    shape = np.broadcast_shapes(rotations.shape[:-3], translations.shape[:-2])
    j = len(parents)
    world_r = np.empty(shape + (j, 3, 3), dtype=np.float64)
    world_p = np.empty(shape + (j, 3), dtype=np.float64)
    for i, p in enumerate(parents):
        if p < 0:
            world_r[..., i, :, :] = rotations[..., i, :, :]
            world_p[..., i, :] = translations[..., i, :]
        else:
            pr = world_r[..., p, :, :]
            world_r[..., i, :, :] = pr @ rotations[..., i, :, :]
            world_p[..., i, :] = world_p[..., p, :] + np.einsum(
                "...ab,...b->...a", pr, translations[..., i, :])
    return world_r, world_p


class _Lines:
    """Line cursor over the header that remembers 1-based line numbers."""

    def __init__(self, lines: list[str], path: str | None):
        self.lines = lines
        self.i = 0
        self.path = path

    def next_tokens(self, expect: str) -> tuple[list[str], int]:
        while self.i < len(self.lines):
            self.i += 1
            toks = self.lines[self.i - 1].split()
            if toks:
                return toks, self.i
        raise BVHError(self.path, self.i, f"unexpected end of file, expected {expect}")

    def error(self, line: int, message: str) -> BVHError:
        return BVHError(self.path, line, message)


def _float(cur: _Lines, tok: str, line: int, what: str) -> float:
    try:
        v = float(tok)
    except ValueError:
        raise cur.error(line, f"{what}: {tok!r} is not a number") from None
    if not np.isfinite(v):
        raise cur.error(line, f"{what}: non-finite value {tok!r}")
    return v


def parse_bvh(text: str, path: str | Path | None = None, *,
              allow_truncated: bool = False) -> Motion:
    """Parse BVH text. See :func:`read_bvh`."""
    src = None if path is None else str(path)
    if "\x00" in text:
        raise BVHError(src, None, "binary data (NUL bytes): not a BVH text file")
    lines = re.split(r"\r\n|\r|\n", text)
    cur = _Lines(lines, src)
    toks, ln = cur.next_tokens("HIERARCHY")
    if toks[0].upper() != "HIERARCHY":
        raise cur.error(ln, f"expected 'HIERARCHY', found {' '.join(toks)[:40]!r}")

    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    end_sites: dict[int, list[float]] = {}
    channels: list[tuple[str, ...]] = []
    seen: dict[str, int] = {}
    stack: list[int] = []  # joint index per open brace; -2 marks an End Site

    toks, ln = cur.next_tokens("ROOT")
    while True:
        kw = toks[0]
        if kw in ("ROOT", "JOINT"):
            if kw == "ROOT" and stack:
                raise cur.error(ln, "ROOT inside another joint")
            if kw == "JOINT" and not stack:
                raise cur.error(ln, "JOINT outside any ROOT")
            if len(toks) < 2:
                raise cur.error(ln, f"{kw} without a name")
            name = " ".join(toks[1:])
            if name in seen:
                raise cur.error(ln, f"duplicate joint name {name!r} (first on line {seen[name]})")
            seen[name] = ln
            parent = stack[-1] if stack else -1
            if parent == -2:
                raise cur.error(ln, "JOINT inside an End Site")
            t, l2 = cur.next_tokens("'{'")
            if t != ["{"]:
                raise cur.error(l2, f"expected '{{' after {kw} {name}, found {' '.join(t)!r}")
            t, l2 = cur.next_tokens("OFFSET")
            if t[0] != "OFFSET" or len(t) != 4:
                raise cur.error(l2, f"expected 'OFFSET x y z' for joint {name}")
            off = [_float(cur, v, l2, f"OFFSET of {name}") for v in t[1:]]
            t, l2 = cur.next_tokens("CHANNELS")
            if t[0] != "CHANNELS" or len(t) < 2:
                raise cur.error(l2, f"expected 'CHANNELS n ...' for joint {name}")
            try:
                n = int(t[1])
            except ValueError:
                raise cur.error(l2, f"channel count {t[1]!r} is not an integer") from None
            chans = tuple(t[2:])
            if len(chans) != n:
                raise cur.error(l2, f"CHANNELS says {n} but lists {len(chans)}")
            for c in chans:
                if c not in _ROT and c not in _POS:
                    raise cur.error(l2, f"unknown channel {c!r} in joint {name} "
                                        "(expected X/Y/Z rotation or position)")
            if len(set(chans)) != len(chans):
                raise cur.error(l2, f"repeated channel in joint {name}")
            names.append(name)
            parents.append(parent)
            offsets.append(off)
            channels.append(chans)
            stack.append(len(names) - 1)
        elif kw == "End" and len(toks) >= 2 and toks[1] == "Site":
            if not stack or stack[-1] < 0:
                raise cur.error(ln, "End Site outside a joint")
            owner = stack[-1]
            t, l2 = cur.next_tokens("'{'")
            if t != ["{"]:
                raise cur.error(l2, "expected '{' after End Site")
            t, l2 = cur.next_tokens("OFFSET")
            if t[0] != "OFFSET" or len(t) != 4:
                raise cur.error(l2, "expected 'OFFSET x y z' in End Site")
            end_sites[owner] = [_float(cur, v, l2, "End Site OFFSET") for v in t[1:]]
            stack.append(-2)
        elif kw == "}":
            if not stack:
                raise cur.error(ln, "unbalanced '}'")
            stack.pop()
        elif kw.upper() == "MOTION":
            if stack:
                raise cur.error(ln, f"MOTION before {len(stack)} open brace(s) were closed")
            break
        else:
            raise cur.error(ln, f"unexpected {' '.join(toks)[:40]!r} in HIERARCHY")
        if kw == "MOTION":
            break
        toks, ln = cur.next_tokens("MOTION")

    if not names:
        raise cur.error(ln, "no joints before MOTION")

    t, l2 = cur.next_tokens("'Frames:'")
    if t[0] != "Frames:" or len(t) != 2:
        raise cur.error(l2, f"expected 'Frames: N', found {' '.join(t)!r}")
    try:
        num_frames = int(t[1])
    except ValueError:
        raise cur.error(l2, f"frame count {t[1]!r} is not an integer") from None
    if num_frames < 1:
        raise cur.error(l2, f"frame count {num_frames} < 1")
    t, l2 = cur.next_tokens("'Frame Time:'")
    if t[:2] != ["Frame", "Time:"] or len(t) != 3:
        raise cur.error(l2, f"expected 'Frame Time: seconds', found {' '.join(t)!r}")
    frame_time = _float(cur, t[2], l2, "Frame Time")
    if frame_time <= 0:
        raise cur.error(l2, f"Frame Time {frame_time} <= 0")

    nchan = sum(len(c) for c in channels)
    data_first = cur.i + 1  # 1-based line number of the first data line
    rows = [r for r in lines[cur.i:]]
    # drop trailing blank lines; blank lines inside the data are an error (row miscount)
    while rows and not rows[-1].strip():
        rows.pop()
    data = _parse_rows(rows, nchan, num_frames, data_first, cur, allow_truncated)

    parents_a = np.asarray(parents, dtype=np.int64)
    offsets_a = np.asarray(offsets, dtype=np.float64)
    ends = np.full((len(names), 3), np.nan)
    for j, e in end_sites.items():
        ends[j] = e
    rotations, translations = _local_transforms(data, channels, offsets_a)
    for a in (parents_a, offsets_a, ends, rotations, translations):
        a.setflags(write=False)
    return Motion(names=names, parents=parents_a, offsets=offsets_a, end_sites=ends,
                  channels=channels, frame_time=frame_time, rotations=rotations,
                  translations=translations, source=src)


def _parse_rows(rows: list[str], nchan: int, num_frames: int, first_line: int,
                cur: _Lines, allow_truncated: bool) -> np.ndarray:
    if len(rows) < num_frames and not allow_truncated:
        raise cur.error(first_line + len(rows),
                        f"Frames: says {num_frames} but {len(rows)} data rows were found "
                        "(pass allow_truncated=True to keep the complete rows)")
    if len(rows) > num_frames:
        raise cur.error(first_line + num_frames,
                        f"Frames: says {num_frames} but {len(rows)} data rows were found")
    try:
        flat = np.array(" ".join(rows).split(), dtype=np.float64)
    except ValueError:
        flat = None
    counts = None
    if flat is None or flat.size != len(rows) * nchan:
        counts = [len(r.split()) for r in rows]
        for k, c in enumerate(counts):
            if c != nchan:
                if allow_truncated and k == len(rows) - 1:
                    rows = rows[:-1]
                    break
                raise cur.error(first_line + k,
                                f"data row has {c} values, expected {nchan}")
        flat_rows = []
        for k, r in enumerate(rows):
            try:
                flat_rows.append(np.array(r.split(), dtype=np.float64))
            except ValueError:
                bad = next(tok for tok in r.split() if not _is_number(tok))
                raise cur.error(first_line + k, f"{bad!r} is not a number") from None
        if not flat_rows:
            raise cur.error(first_line, "no complete data row")
        flat = np.concatenate(flat_rows)
    data = flat.reshape(-1, nchan)
    nonfinite = ~np.isfinite(data)
    if nonfinite.any():
        r, c = np.argwhere(nonfinite)[0]
        raise cur.error(first_line + int(r), f"non-finite value in column {int(c) + 1}")
    return data


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _local_transforms(data: np.ndarray, channels: list[tuple[str, ...]],
                      offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    f = data.shape[0]
    j = len(channels)
    rotations = np.empty((f, j, 3, 3), dtype=np.float64)
    translations = np.broadcast_to(offsets, (f, j, 3)).copy()
    col = 0
    for k, chans in enumerate(channels):
        order = "".join(_ROT[c] for c in chans if c in _ROT)
        rot_cols = [col + n for n, c in enumerate(chans) if c in _ROT]
        for n, c in enumerate(chans):
            if c in _POS:
                translations[:, k, _POS[c]] = data[:, col + n]
        if order:
            rotations[:, k] = euler_to_matrix(np.deg2rad(data[:, rot_cols]), order)
        else:
            rotations[:, k] = np.eye(3)
        col += len(chans)
    return rotations, translations


def read_bvh(path: str | Path, *, allow_truncated: bool = False) -> Motion:
    """Read a BVH file.

    Strict: any deviation from the grammar raises :class:`vhgen.errors.BVHError` naming
    the file, the line and what was expected. A file with fewer data rows than
    ``Frames:`` says is an error unless ``allow_truncated`` (then complete rows are kept).
    Accepts LF, CRLF, CR and mixed line endings, tabs or spaces, scientific notation.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise BVHError(path, None, f"cannot read: {e.strerror}") from None
    if not raw.strip():
        raise BVHError(path, None, "empty file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        try:
            text = raw.decode("latin-1")
        except UnicodeDecodeError:  # pragma: no cover - latin-1 decodes every byte
            raise BVHError(path, None, "not a text file") from None
    return parse_bvh(text, path, allow_truncated=allow_truncated)
