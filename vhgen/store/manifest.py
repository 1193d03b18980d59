"""The per-frame manifest: one Parquet row per frame, written as one part per shard.

Two forms exist (:func:`manifest_form`; ``vhgen inspect`` names a store's):

* **form 2** (written since vhgen 0.1.0 of 2026-11): no null inside a fixed-size list.
  The one column that can be absent, ``people.footprint`` (null for a person-only frame),
  is a nullable *variable-size* list of 3 floats. Nullable lists are plain Parquet that
  every reader opens (pyarrow from 15 on, pandas, DuckDB, Polars, Spark); a null stays a
  null (no NaN sentinel to test for, no extra validity column), and the values a reader
  gets are the same as in form 1, so the frames' fingerprints did not change.
* **form 1** (earlier stores): ``people.footprint`` a fixed-size list of 3. pyarrow
  before 26 cannot read a null inside a fixed-size list ("Expected all lists to be of
  size=3 but index 1 had size=0"), so the manifest of a person-only store opened only
  with pyarrow >= 26. :func:`read_manifest_table` reads it with any pyarrow: it drops the
  unreadable column and restores it as nulls (in form 1 the footprint was null exactly
  when the job's scene had no floor, so for every frame of the store).

Every reader of vhgen goes through :func:`read_manifest_table`, which returns form 2.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from vhgen.errors import StoreError
from vhgen.store.record import FrameRecord, PersonRecord, columns
from vhgen.store.zarr_store import (
    MANIFEST_FILE,
    MANIFEST_MERGING,
    MANIFEST_PARTS,
    completed_shards,
)


def _arrow(kind: str, num_joints: int):
    import pyarrow as pa

    scalar = {"int64": pa.int64(), "int32": pa.int32(), "uint64": pa.uint64(),
              "float64": pa.float64(), "float32": pa.float32(), "string": pa.string(),
              "bool": pa.bool_()}
    if kind in scalar:
        return scalar[kind]
    if kind == "people":
        return pa.list_(pa.struct([(n, _arrow(k, num_joints))
                                   for n, k in columns(PersonRecord)]))
    if kind.endswith("[]"):  # a nullable variable-size list (form 2's footprint)
        return pa.list_(scalar[kind[:-2]])
    base, _, n = kind.partition("x")
    size = {"J3": 3 * num_joints, "J2": 2 * num_joints, "J": num_joints}.get(n) or int(n)
    return pa.list_(scalar[base], size)


MANIFEST_FORM = 2  # the form written now (see the module docstring)


def manifest_form(schema) -> int:
    """1 or 2: the form of a manifest with Arrow ``schema`` (the footprint's list type)."""
    import pyarrow as pa

    if "people" not in schema.names:
        return MANIFEST_FORM
    person = schema.field("people").type.value_type
    i = person.get_field_index("footprint")
    if i >= 0 and pa.types.is_fixed_size_list(person.field(i).type):
        return 1
    return MANIFEST_FORM


def _footprint_type():
    import pyarrow as pa

    # "element": the list item's name as Parquet's compliant nested types read it back
    return pa.list_(pa.field("element", pa.float64()))


def _footprint_as_list(people):
    """``people`` (a list<struct> column) with ``footprint`` made a variable-size list
    (form 2), added as nulls where the struct has no footprint (form 1 read without it)."""
    import pyarrow as pa

    chunks = []
    for chunk in people.chunks if isinstance(people, pa.ChunkedArray) else [people]:
        inner = chunk.values  # the structs of every person, in order
        fields = [inner.type.field(k) for k in range(inner.type.num_fields)]
        arrays = [inner.field(k) for k in range(inner.type.num_fields)]
        names = [f.name for f in fields]
        if "footprint" in names:
            k = names.index("footprint")
            fp = arrays[k]
            if pa.types.is_fixed_size_list(fp.type):
                size = fp.type.list_size  # the values of null entries are kept as padding
                fp = pa.ListArray.from_arrays(
                    pa.array(np.arange(len(fp) + 1, dtype=np.int32) * size),
                    fp.values.slice(fp.offset * size, len(fp) * size),
                    type=_footprint_type(), mask=fp.is_null())
            arrays[k] = fp
        else:
            names.append("footprint")
            arrays.append(pa.nulls(len(inner), _footprint_type()))
        structs = pa.StructArray.from_arrays(arrays, names=names, mask=inner.is_null())
        kind = pa.list_(pa.field(chunk.type.value_field.name, structs.type))
        chunks.append(pa.ListArray.from_arrays(chunk.offsets, structs, type=kind,
                                               mask=chunk.is_null()))
    return pa.chunked_array(chunks) if chunks else people


def read_manifest_table(path: Any, columns: list[str] | None = None,
                        row_group: int | None = None):
    """The manifest at ``path`` (a ``manifest.parquet`` or a part, or an open
    ``pyarrow.parquet.ParquetFile``; only its ``row_group`` when given) as an Arrow table
    in form 2, whatever form it was written in and whichever pyarrow reads it."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    pf = path if isinstance(path, pq.ParquetFile) else None

    def read(cols: list[str] | None) -> Any:
        if row_group is not None:
            return (pf or pq.ParquetFile(path)).read_row_group(row_group, columns=cols)
        return pf.read(columns=cols) if pf is not None else pq.read_table(path, columns=cols)

    try:
        table = read(columns)
    except pa.ArrowInvalid as e:
        if "Expected all lists to be of size" not in str(e):
            raise
        # form 1 with null footprints, read by pyarrow < 26: every leaf but the footprint
        pf = pf or pq.ParquetFile(path)
        leaves = [pf.schema.column(i).path for i in range(pf.metadata.num_columns)]
        table = read([p for p in leaves if not p.startswith("people.list.element.footprint")
                      and (columns is None or p.split(".")[0] in columns)])
    if "people" in table.column_names:
        people = table.column("people")
        person = people.type.value_type
        i = person.get_field_index("footprint")
        if i < 0 or pa.types.is_fixed_size_list(person.field(i).type):
            table = table.set_column(table.column_names.index("people"), "people",
                                     _footprint_as_list(people))
    return table


def manifest_schema(num_joints: int):
    """The Arrow schema of the manifest: the fields of :class:`FrameRecord`, in order."""
    import pyarrow as pa

    return pa.schema([(name, _arrow(kind, num_joints)) for name, kind in columns()])


PARQUET_ZSTD_LEVEL = 9


def _parquet_options(schema: Any) -> dict:
    """How every manifest file is written: zstd level 9; dictionary encoding for the
    string columns only (on the float columns it made the file larger); statistics for
    the top-level columns only (no reader filters on a joint coordinate). 2.7 kB a
    cluttered_room frame against 3.5 kB with pyarrow's defaults (docs/performance.md);
    read by any Parquet reader."""
    import pyarrow as pa

    flat = [f.name for f in schema if not pa.types.is_nested(f.type)]
    strings = [p for f in schema for p, t in _leaves(f.name, f.type) if pa.types.is_string(t)]
    return {"compression": "zstd", "compression_level": PARQUET_ZSTD_LEVEL,
            "use_dictionary": strings, "write_statistics": flat}


def write_parquet(table: Any, path: Path) -> None:
    """Write ``table`` to ``path`` atomically (temp file + rename), as
    :func:`_parquet_options` says."""
    import pyarrow.parquet as pq

    tmp = path.with_suffix(".tmp")
    pq.write_table(table, tmp, **_parquet_options(table.schema))
    os.replace(tmp, path)


def _leaves(path: str, kind) -> list[tuple[str, Any]]:
    """(Parquet column path, Arrow type) of each leaf under a field of type ``kind``."""
    import pyarrow as pa

    if pa.types.is_struct(kind):
        return [leaf for k in range(kind.num_fields)
                for leaf in _leaves(f"{path}.{kind.field(k).name}", kind.field(k).type)]
    if pa.types.is_list(kind) or pa.types.is_fixed_size_list(kind):
        # Parquet's compliant nested names (pyarrow's default from 13 on)
        return _leaves(f"{path}.list.element", kind.value_type)
    return [(path, kind)]


def write_part(store: str | Path, shard: int, records: list[FrameRecord],
               num_joints: int) -> Path:
    """Write a shard's records atomically (temp file + rename)."""
    import pyarrow as pa

    schema = manifest_schema(num_joints)
    rows = [r.to_row() for r in records]
    cols = {f.name: [r[f.name] for r in rows] for f in schema}
    table = pa.table(cols, schema=schema)
    out = Path(store) / MANIFEST_PARTS / f"part-{shard:06d}.parquet"
    write_parquet(table, out)
    return out


# the rows of manifest.parquet per row group: the merge holds at most this many rows (and
# one part) in memory, whatever the job's size (about 4 kB a cluttered frame in Arrow)
MANIFEST_ROW_GROUP = 4096


class _OldRows:
    """The rows of an earlier run's ``manifest.parquet``, taken shard by shard in frame
    order, one row group in memory at a time (None when there is none, or it is
    unreadable: its shards then have no rows and are reported missing)."""

    def __init__(self, path: Path):
        import pyarrow as pa
        import pyarrow.parquet as pq

        self.groups: list[int] = []
        self.buf: Any = None
        try:
            self.file = pq.ParquetFile(path) if path.is_file() else None
            if self.file is not None:
                self.groups = list(range(self.file.metadata.num_row_groups))
        except (OSError, pa.ArrowException):
            self.file = None

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None

    def take(self, shard: int) -> Any:
        """The rows of ``shard`` (a table, maybe empty), dropping those of earlier shards."""
        import pyarrow as pa

        pieces = []
        while True:
            if self.buf is None or self.buf.num_rows == 0:
                if self.file is None or not self.groups:
                    break
                try:
                    self.buf = read_manifest_table(self.file, row_group=self.groups.pop(0))
                except (OSError, pa.ArrowException):
                    self.file, self.buf = None, None  # damaged: the rest is missing
                    break
            shards = self.buf.column("shard").to_numpy()
            lo, hi = np.searchsorted(shards, [shard, shard + 1])
            pieces.append(self.buf.slice(lo, hi - lo))
            self.buf = self.buf.slice(hi)
            if self.buf.num_rows:
                break  # the next row is of a later shard
        pieces = [p for p in pieces if p.num_rows]
        return pa.concat_tables(pieces) if pieces else None


class ManifestMerger:
    """Streams the manifest parts of a store into ``manifest.parquet`` in frame order.

    The driver hands each shard to :meth:`add` as it finishes; the rows of every shard up
    to the first one still rendering are appended then, a row group of
    :data:`MANIFEST_ROW_GROUP` frames at a time, to a temporary file that :meth:`finish`
    completes, checks (every frame once) and renames into place before removing the
    parts: the merged file is the one copy of the manifest (a run stopped between the two
    leaves both, which resumes and inspects as well). The merge holds at most one row
    group and one part, so the driver's memory does not grow with the job. A shard not
    rendered in this run takes its part from an earlier run, else its rows from the earlier
    run's ``manifest.parquet`` (a redone shard's part replaces them).

    ``shards``: every shard of the job in frame order, ``todo`` those rendered in this run;
    without them (a merge of what is on disk) everything is merged by :meth:`finish`."""

    def __init__(self, store: str | Path, shards: Sequence[int] | None = None,
                 todo: Iterable[int] = ()):
        self.store = Path(store)
        self.shards = list(shards) if shards is not None else None
        self.waiting = set(todo)  # shards of this run not finished yet
        self.pos = 0  # index in self.shards of the next shard to write
        self.old = _OldRows(self.store / MANIFEST_FILE)
        self.tmp = self.store / MANIFEST_MERGING
        self.writer: Any = None
        self.rows: list[Any] = []
        self.count = 0  # rows buffered
        self.last = -1  # the last frame written
        self.seen = np.zeros(0, np.int32)  # rows per frame
        self.bad: list[str] = []
        self.error: StoreError | None = None

    def add(self, shard: int) -> None:
        """Shard ``shard`` is written: append the rows that are now in frame order. A part
        that cannot be read, or rows that cannot be merged, are reported by
        :meth:`finish` (the job goes on)."""
        self.waiting.discard(shard)
        if self.error is None:
            try:
                self._advance()
            except StoreError as e:
                self.error = e

    def _advance(self) -> None:
        while self.shards is not None and self.pos < len(self.shards):
            shard = self.shards[self.pos]
            if shard in self.waiting:
                break
            self._write_shard(shard)
            self.pos += 1

    def _write_shard(self, shard: int) -> None:
        import pyarrow as pa

        old = self.old.take(shard)  # consumed in any case: the rows stay in step
        path = self.store / MANIFEST_PARTS / f"part-{shard:06d}.parquet"
        table = old
        if path.is_file():
            try:
                table = read_manifest_table(path)
            except (OSError, pa.ArrowException) as e:
                self.bad.append(f"{path.name} ({type(e).__name__}: {_first_line(e)})")
                return
        if table is None or table.num_rows == 0:
            return  # no rows: finish() counts its frames missing
        table = table.sort_by("frame")
        frames = table.column("frame").to_numpy()
        if frames[0] <= self.last:  # shards out of frame order: a damaged store
            raise StoreError(f"{self.store}: cannot merge the manifest: shard {shard}'s "
                             f"frames start at {frames[0]}, before frame {self.last} of an "
                             "earlier shard")
        self.last = int(frames[-1])
        if self.last >= len(self.seen):
            self.seen = np.concatenate([self.seen, np.zeros(
                max(self.last + 1 - len(self.seen), len(self.seen)), np.int32)])
        np.add.at(self.seen, frames, 1)
        self.rows.append(table)
        self.count += table.num_rows
        if self.count >= MANIFEST_ROW_GROUP:
            self._flush()

    def _flush(self) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not self.rows:
            return
        table = pa.concat_tables(self.rows)
        self.rows, self.count = [], 0
        if self.writer is None:
            self.writer = pq.ParquetWriter(self.tmp, table.schema, **_parquet_options(
                table.schema))
        try:
            self.writer.write_table(table, row_group_size=len(table))
        except ValueError as e:  # another schema (a part of another vhgen version)
            raise StoreError(f"{self.store}: cannot merge the manifest: {_first_line(e)}; "
                             "the store's parts were written by different versions") from None

    def finish(self, num_frames: int) -> Path:
        """Append the shards not written yet (of an earlier run, or every shard when
        merging what is on disk), check every frame appears once, rename the file into
        place and remove the parts."""
        if self.shards is None:
            self.shards = sorted(completed_shards(self.store))
        self.waiting.clear()
        try:
            if self.error is not None:
                raise self.error
            self._advance()
            if self.bad:
                raise StoreError(
                    f"{self.store}: cannot merge the manifest: {len(self.bad)} part(s) "
                    f"unreadable: {'; '.join(self.bad[:3])}"
                    f"{' ...' if len(self.bad) > 3 else ''}; every shard and part is kept: "
                    "fix the cause, then rerun with --resume (a part still unreadable then "
                    "is rendered again)")
            self._flush()
            seen = self.seen[:num_frames]
            rows = int(self.seen.sum())
            if self.writer is None:
                raise StoreError(f"{self.store}: no manifest parts")
            if rows != num_frames or len(seen) < num_frames or (seen != 1).any():
                dup = int(np.maximum(self.seen - 1, 0).sum())
                missing = num_frames - int((seen > 0).sum())
                raise StoreError(f"{self.store}: manifest has {rows} rows for {num_frames} "
                                 f"frames ({dup} duplicated, {missing} missing)")
            self.writer.close()
            self.writer = None
            self.old.close()
            os.replace(self.tmp, self.store / MANIFEST_FILE)
        finally:
            if self.writer is not None:
                self.writer.close()
                self.tmp.unlink(missing_ok=True)
        parts = self.store / MANIFEST_PARTS
        for p in parts.glob("part-*.parquet"):
            p.unlink()
        if parts.is_dir() and not any(parts.iterdir()):
            parts.rmdir()
        return self.store / MANIFEST_FILE


def _first_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return text[0][:200] if text else ""


def unreadable_parts(store: str | Path) -> list[int]:
    """Shards whose manifest part exists but cannot be read (damaged or truncated): read
    whole, as the merge reads it, so a part that passes here merges."""
    import pyarrow as pa

    bad = []
    for p in sorted((Path(store) / MANIFEST_PARTS).glob("part-*.parquet")):
        try:
            read_manifest_table(p)
        except (OSError, pa.ArrowException):
            bad.append(int(p.stem.split("-")[1]))
    return bad


def merge_parts(store: str | Path, num_frames: int) -> Path:
    """Concatenate the parts into ``manifest.parquet``; check every frame appears once."""
    return ManifestMerger(store).finish(num_frames)


def read_manifest(store: str | Path, columns: list[str] | None = None):
    """A store's ``manifest.parquet`` (form 2, see :func:`read_manifest_table`)."""
    path = Path(store) / MANIFEST_FILE
    if not path.is_file():
        raise StoreError(f"{store}: no {MANIFEST_FILE} (job not finished?)")
    return read_manifest_table(path, columns)


# fixed-size list columns returned as arrays of this shape (-1: as many rows as needed)
ARRAY_COLUMNS = {"world_to_camera": (4, 4), "joints_cam": (-1, 3), "body_offset": (3,)}


def array_dtype(name: str) -> type:
    """The NumPy dtype of array column ``name`` (joints in float32, as written)."""
    return np.float32 if name == "joints_cam" else np.float64


class ManifestColumns:
    """A manifest table kept as columns, made into row dicts only when asked for.

    Numbers are NumPy arrays and the :data:`ARRAY_COLUMNS` one (n, ...) array each
    (read-only); strings, JSON, the ``people`` structs and columns with nulls stay Arrow
    arrays and become Python objects row by row. :meth:`row` gives exactly what
    ``table.slice(i, 1).to_pylist()[0]`` gives, with the array columns as NumPy arrays of
    their :data:`ARRAY_COLUMNS` shape; :meth:`take` gives a batch, column by column.
    """

    def __init__(self, table: Any):
        import pyarrow as pa

        self.names: list[str] = list(table.column_names)
        self.num_rows = int(table.num_rows)
        self._numbers: dict[str, np.ndarray] = {}
        self._arrays: dict[str, np.ndarray] = {}
        self._arrow: dict[str, Any] = {}
        for name in self.names:
            col = table.column(name).combine_chunks()
            typ = col.type
            if col.null_count == 0 and (pa.types.is_integer(typ) or pa.types.is_floating(typ)
                                        or pa.types.is_boolean(typ)):
                values = np.asarray(col.to_numpy(zero_copy_only=False))
                values.setflags(write=False)
                self._numbers[name] = values
            elif (name in ARRAY_COLUMNS and col.null_count == 0
                  and pa.types.is_fixed_size_list(typ)):
                flat: np.ndarray = np.asarray(col.flatten().to_numpy(zero_copy_only=False),
                                              array_dtype(name))
                values = flat.reshape(self.num_rows, -1)
                values.setflags(write=False)
                self._arrays[name] = values
            else:
                self._arrow[name] = col

    def row(self, i: int) -> dict[str, Any]:
        """Row ``i`` as a dict (fresh objects: changing them changes nothing here)."""
        out: dict[str, Any] = {}
        for name in self.names:
            if name in self._numbers:
                out[name] = self._numbers[name].item(i)
            elif name in self._arrays:
                out[name] = self._arrays[name][i].reshape(ARRAY_COLUMNS[name]).copy()
            else:
                value = self._arrow[name][i].as_py()
                if name in ARRAY_COLUMNS and value is not None:
                    value = np.asarray(value, array_dtype(name)).reshape(ARRAY_COLUMNS[name])
                out[name] = value
        return out

    def take(self, rows: np.ndarray) -> dict[str, Any]:
        """Rows ``rows`` column by column: numbers as (B,) arrays (the column's dtype), the
        array columns as (B, ...) arrays, other columns as lists of B Python objects."""
        import pyarrow as pa

        rows = np.asarray(rows, np.int64)
        out: dict[str, Any] = {}
        for name in self.names:
            if name in self._numbers:
                out[name] = self._numbers[name][rows]
            elif name in self._arrays:
                shape = ARRAY_COLUMNS[name]
                out[name] = self._arrays[name][rows].reshape(len(rows), *shape)
            else:
                values = self._arrow[name].take(pa.array(rows)).to_pylist()
                if name in ARRAY_COLUMNS:
                    values = [None if v is None else np.asarray(v, array_dtype(name))
                              .reshape(ARRAY_COLUMNS[name]) for v in values]
                out[name] = values
        return out


def read_parts(store: str | Path) -> Any:
    """The manifest parts of the shards finished so far as one table sorted by frame (a
    store still being written has no ``manifest.parquet`` yet); None if there are none."""
    import pyarrow as pa

    parts = sorted((Path(store) / MANIFEST_PARTS).glob("part-*.parquet"))
    if not parts:
        return None
    return pa.concat_tables([read_manifest_table(p) for p in parts]).sort_by("frame")
