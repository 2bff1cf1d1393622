"""Human, JSON Lines, CSV and Parquet views of dissector records."""

from __future__ import annotations

from pathlib import Path
from typing import IO, Any

from eyeq_spi import io as formats
from eyeq_spi.codec.message import MessageCodec
from eyeq_spi.errors import EyeqError, MissingExtra, OutputError, UnknownFormatError

RESET, RED, GREEN, CYAN, YELLOW = "\x1b[0m", "\x1b[31m", "\x1b[32m", "\x1b[36m", "\x1b[33m"


def flatten(values: Any, prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    if isinstance(values, dict):
        for key, value in values.items():
            out.update(flatten(value, f"{prefix}.{key}" if prefix else key))
    elif isinstance(values, list):
        for index, value in enumerate(values):
            out.update(flatten(value, f"{prefix}[{index}]"))
    else:
        out[prefix] = values
    return out


class HumanWriter:
    def __init__(self, fh: IO[str], codec: MessageCodec, color: bool, tree: bool = True) -> None:
        self.fh = fh
        self.codec = codec
        self.color = color
        self.tree = tree
        # a message or event line keeps a blank frame-index column (and a time as wide as a
        # frame line's) only where frame lines are shown, so that it lines up with them; a run
        # that shows messages alone (--id, --name) fits 80 columns
        self._wide = False
        self._origin: float | None = None  # time of the file's first timestamped record
        self._file: object = None

    def _c(self, code: str, text: str) -> str:
        return f"{code}{text}{RESET}" if self.color else text

    def see(self, record: dict[str, Any]) -> None:
        """Note a record the filters may drop: the time origin is the file's first timestamped
        record, whatever is printed."""
        file_name = record.get("file")
        if file_name != self._file:
            self._file, self._origin = file_name, None
        if self._origin is None:
            self._origin = record.get("time")

    def _when(self, record: dict[str, Any]) -> str:
        """Seconds since the first timestamped record of the record's file (the origin of
        ``eyeq-spi plot``'s time axis); ``-`` for a record without a time (raw, plain hex)."""
        self.see(record)
        time_s = record.get("time")
        if time_s is None or self._origin is None:
            return "-"
        return f"{time_s - self._origin:.6f}"

    def write(self, record: dict[str, Any]) -> None:
        kind = record["kind"]
        when = self._when(record) if kind != "stats" else "-"
        if kind == "frame":
            ok = self._c(GREEN, "crc ok") if record["crc_ok"] else self._c(RED, "CRC BAD")
            if "length" in record:
                ok = self._c(RED, f"bad length {record['length']}")
            ft = record["frame_type"]
            tr = ""
            if record["transport"]:
                tid = record["transfer_id"]
                tr = record["transport"] + ("" if tid is None else f" id={tid}")
            reason = record["nak_reason"]
            nak = f" reason=0x{reason:03X}" if reason is not None else ""
            num = "-" if record["num"] is None else record["num"]
            rsp = "-" if record["rsp"] is None else record["rsp"]
            self._wide = True
            direction = record["direction"] or "-"
            self.fh.write(f"{record['index']:8d} {when:>14s} {direction:3s} {ft:7s} "
                          f"NUM={num!s:>4s} RSP={rsp!s:>4s} {ok} {tr}{nak}\n")
        elif kind == "message":
            name = record["name"] or "?"
            head = " ".join(f"{k}={v}" for k, v in record["header"].items())
            errors = record["errors"]
            errs = "" if not errors else " " + self._c(RED, "; ".join(errors[:3]))
            self.fh.write(f"{self._lead(when)} {record.get('direction') or '-':3s} "
                          f"{self._c(CYAN, record['protocol'])} {self._c(CYAN, name)} "
                          f"{record['length']} bytes {head}{errs}\n")
            if self.tree and record["fields"]:
                self._tree(record)
        elif kind == "event":
            rest = " ".join(f"{k}={v}" for k, v in record.items()
                            if k not in ("kind", "type", "time", "direction", "file"))
            self.fh.write(f"{self._lead(when)} {record.get('direction') or '-':3s} "
                          + self._c(YELLOW, f"event {record['type']}") + f" {rest}\n")

    def _lead(self, when: str) -> str:
        return f"{'':8s} {when:>14s}" if self._wide else f"{when:>12s}"

    def _tree(self, record: dict[str, Any]) -> None:
        self._walk(record["fields"], record_layout(self.codec, record), 2)

    def _walk(self, values: Any, lay: Any, depth: int) -> None:
        pad = "  " * depth
        for key, value in values.items():
            field = layout_field(lay, key)
            child = lay.children.get(key) if lay is not None else None
            if isinstance(value, dict):
                self.fh.write(f"{pad}{key}\n")
                self._walk(value, child, depth + 1)
            elif isinstance(value, list) and value and isinstance(value[0], dict):
                for index, item in enumerate(value):
                    self.fh.write(f"{pad}{key}[{index}]\n")
                    self._walk(item, child, depth + 1)
            else:
                extra = ""
                if field is not None:
                    member = field.member
                    enum = self.codec.cat.enums.get(member.enum or "")
                    if enum is not None and isinstance(value, int):
                        label = enum.label(value)
                        if label:
                            extra = f" ({label})"
                        elif enum.kind != "flags" and enum.complete:  # flags 0: no bit set
                            extra = self._c(RED, " (undefined)")
                    elif member.values and isinstance(value, int) and value in member.values:
                        extra = f" ({member.values[value]})"
                    if member.units and member.units not in ("n/a", "NA"):
                        extra += f" {member.units}"
                if isinstance(value, float):
                    value = f"{value:.6g}"
                self.fh.write(f"{pad}{key} = {value}{extra}\n")


def record_layout(codec: MessageCodec, record: dict[str, Any]) -> Any:
    """The layout of a DASP, DIAG or BOOT message record, or None."""
    if record["protocol"] not in ("DASP", "DIAG", "BOOT") or not record["name"]:
        return None
    try:
        return codec.layout(codec.cat.message(record["name"]))
    except EyeqError:
        return None


def layout_field(lay: Any, name: str) -> Any:
    """The layout's member ``name``, or None (no layout, or a name it does not have)."""
    if lay is None:
        return None
    try:
        return lay.field(name)
    except KeyError:
        return None


def _as_list(column: Any) -> list[Any]:
    return column.tolist() if hasattr(column, "tolist") else list(column)


def _arrow(pa: Any, column: Any) -> Any:
    """``pa.array(v)``; a numpy int64/float64 column (no nulls) wraps its buffer instead: same
    type, same values, and pyarrow's masked-array check does not import numpy.ma (13 ms)."""
    kind = getattr(column, "dtype", None)
    if kind is not None and kind.kind in "if" and kind.itemsize == 8 and column.ndim == 1:
        import numpy as np  # loaded already: only the fast path makes numpy columns

        column = np.ascontiguousarray(column)
        return pa.Array.from_buffers(pa.from_numpy_dtype(column.dtype), len(column),
                                     [None, pa.py_buffer(column)])
    return pa.array(column)


def _parquet_writer(pq: Any, path: Path, schema: Any) -> Any:
    """A Parquet writer that dictionary-encodes only the columns that are not numbers (the
    direction, MESP strings): a dictionary per numeric column (1,117 in the obstacles table)
    cost a third of the writing time and made the files bigger. Same values, same schema."""
    import pyarrow as pa

    words = [f.name for f in schema
             if not (pa.types.is_integer(f.type) or pa.types.is_floating(f.type))]
    return pq.ParquetWriter(str(path), schema, use_dictionary=words)


def table_name(record: dict[str, Any]) -> str:
    """The table a message record goes in: its name; a MESP reply in ``NAME.reply`` (a request
    and its reply share a name but not their fields)."""
    name: str = record["name"] or record["protocol"]
    return f"{name}.reply" if record["header"].get("reply") is True else name


class TableWriter:
    """One table per message type, flattened field names: CSV files or Parquet files. Every
    message is a row (a table's row count is ``--stats``'s count). A table's columns are those
    of its first row (Parquet: of its first row group); a later row with a column it lacks
    (another release's struct) starts a new part, ``NAME.2.csv``, which pyarrow and DuckDB
    (``union_by_name``) join."""

    def __init__(self, directory: str, fmt: str, batch: int = 2000,
                 column_type: Any = None, *, errors: bool = False, hive: bool = False) -> None:
        """``column_type(table, column)``: the Arrow type ("float64", "int64", "string") of a
        column whose first rows are all NULL (a Parquet schema is fixed by its first row group).
        ``errors``: an ``errors`` column after ``direction``. ``hive``:
        ``DIR/message=NAME/part-N.parquet`` with no ``file`` column, else ``DIR/NAME.parquet``."""
        tables = [f.name for f in formats.formats(formats.RECORD_WRITER)
                  if f.target == f"{__name__}:TableWriter"]
        if fmt not in tables:
            raise UnknownFormatError(f"unknown table format {fmt!r} (one of {', '.join(tables)})")
        self.dir = Path(directory)
        self.column_type = column_type
        try:
            self.dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"cannot create {self.dir}: {exc}") from exc
        self.fmt = fmt
        self.batch = batch
        self.errors, self.hive = errors, hive
        self.file: str | None = None  # the capture being written: every row's first column
        self._parts: dict[str, list[tuple[IO[str], Any, list[str]]]] = {}  # CSV parts
        self._last: dict[str, tuple[list[str], tuple[IO[str], Any, list[str]]]] = {}
        self._rows: dict[str, list[dict[str, Any]]] = {}
        self._pq_parts: dict[str, list[Any]] = {}
        self._tables: dict[str, list[Any]] = {}  # column batches not yet written
        if fmt == "parquet":
            try:
                import pyarrow  # noqa: F401
            except ImportError as exc:
                extra = formats.get("parquet", formats.RECORD_WRITER).extra
                raise MissingExtra(extra or "parquet", "--parquet needs pyarrow") from exc

    def write(self, record: dict[str, Any]) -> None:
        if record["kind"] != "message":
            return
        name = table_name(record)
        row: dict[str, Any] = {} if self.hive else {"file": record.get("file", self.file)}
        row.update({"frame_index": record["frames"][-1] if record["frames"] else None,
                    "time": record.get("time"), "direction": record.get("direction")})
        if self.errors:
            row["errors"] = "; ".join(record["errors"])
        row.update({f"header.{k}": v for k, v in record["header"].items()})
        row.update(flatten(record["fields"]))
        if self.fmt == "csv":
            self._csv_part(name, list(row))[1].writerow(row)
        else:
            self._rows.setdefault(name, []).append(row)
            self._flush(name, self.batch)

    def write_columns(self, name: str, columns: dict[str, Any]) -> None:
        """Rows given as columns (numpy arrays or lists, equal lengths, in the order of the
        row :meth:`write` makes): the fast path's vectorised groups. Same tables."""
        count = len(columns["frame_index"])
        if not count:
            return
        if not self.hive:
            columns = {"file": [self.file] * count, **columns}
        if self.fmt == "csv":
            entry = self._csv_part(name, list(columns))
            cols = [_as_list(columns[c]) if c in columns else [""] * count for c in entry[2]]
            import csv  # here: --stats and Parquet never need it

            csv.writer(entry[0]).writerows(zip(*cols, strict=True))
            return
        import pyarrow as pa

        self._table_rows(name)  # rows of this table written as dicts come first
        self._tables.setdefault(name, []).append(
            pa.table({k: _arrow(pa, v) for k, v in columns.items()}))
        self._flush(name, self.batch)

    def _table_rows(self, name: str) -> None:
        """The rows of ``name`` written as dicts, as one table at the end of its pending ones."""
        import pyarrow as pa

        rows = self._rows.get(name)
        if rows:
            keys = list(dict.fromkeys(k for r in rows for k in r))  # every row's columns, in order
            self._tables.setdefault(name, []).append(
                pa.table({k: [r.get(k) for r in rows] for k in keys}))
            rows.clear()

    def _flush(self, name: str, at_least: int = 1) -> None:
        """The pending rows of ``name``, dicts and column batches in their order, written as one
        row group (few row groups: each costs per column) once there are ``at_least``; the
        columns of the group are those of all its rows, however they came, so the reference and
        the fast path put the same rows in the same part."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        pending = self._tables.get(name, [])
        if len(self._rows.get(name, ())) + sum(t.num_rows for t in pending) < at_least:
            return
        self._table_rows(name)
        pending = self._tables[name]
        table = pending[0] if len(pending) == 1 else pa.concat_tables(pending,
                                                                     promote_options="permissive")
        pending.clear()
        self._write_parquet(pq, name, table)

    def _write_parquet(self, pq: Any, name: str, table: Any) -> None:
        """``table`` into the first part of ``name`` whose columns hold all of its columns (a
        missing one written as NULL), else into a new part."""
        import pyarrow as pa

        parts = self._pq_parts.setdefault(name, [])
        for writer in parts:
            if set(table.column_names) <= set(writer.schema.names):
                if not table.schema.equals(writer.schema):
                    table = pa.table({f.name: table.column(f.name) if f.name in table.column_names
                                      else pa.nulls(table.num_rows, f.type) for f in writer.schema})
                    table = table.cast(writer.schema)
                writer.write_table(table)
                return
        schema = self._schema(name, table.schema)  # all-NULL columns typed where known
        writer = _parquet_writer(pq, self._path(name, len(parts), "parquet"), schema)
        parts.append(writer)
        writer.write_table(table if table.schema.equals(schema) else table.cast(schema))

    def _schema(self, name: str, schema: Any) -> Any:
        """``schema`` with its all-NULL columns typed by ``column_type`` where it knows them."""
        import pyarrow as pa

        if self.column_type is None:
            return schema
        for index, field in enumerate(schema):
            if pa.types.is_null(field.type):
                alias = self.column_type(name, field.name)
                if alias is not None:
                    schema = schema.set(index, pa.field(field.name, pa.type_for_alias(alias)))
        return schema

    def _csv_part(self, name: str, keys: list[str]) -> tuple[IO[str], Any, list[str]]:
        """The first CSV part of ``name`` whose header holds every column of ``keys``; a new
        part (``NAME.csv``, then ``NAME.2.csv``...) with ``keys`` as its header if none does."""
        last = self._last.get(name)
        if last is not None and last[0] == keys:  # the common case: the same columns again
            return last[1]
        parts = self._parts.setdefault(name, [])
        want = set(keys)
        for entry in parts:
            if want <= set(entry[2]):
                self._last[name] = (keys, entry)
                return entry
        path = self._path(name, len(parts), "csv")
        try:
            fh = open(path, "w", newline="", encoding="utf-8")  # noqa: SIM115
        except OSError as exc:
            raise OutputError(f"cannot write {path}: {exc}") from exc
        import csv

        writer = csv.DictWriter(fh, fieldnames=keys, extrasaction="ignore")  # a row never has more
        writer.writeheader()
        entry = (fh, writer, keys)
        parts.append(entry)
        self._last[name] = (keys, entry)
        return entry

    def _path(self, name: str, part: int, suffix: str) -> Path:
        """The file of a table's part ``part`` (0: the first)."""
        if not self.hive:
            return self.dir / (f"{name}.{suffix}" if not part else f"{name}.{part + 1}.{suffix}")
        where = self.dir / f"message={name}"
        try:
            where.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"cannot create {where}: {exc}") from exc
        return where / f"part-{part}.{suffix}"

    def close(self) -> None:
        for parts in self._parts.values():
            for fh, _, _ in parts:
                fh.close()
        for name in dict.fromkeys([*self._tables, *self._rows]):
            self._flush(name)
        for writers in self._pq_parts.values():
            for writer in writers:
                writer.close()
