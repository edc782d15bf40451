"""Checks `shakeflow export` against independent readers (tests/it/export.rs runs it).

pyarrow reads every partition file of the stage output on its own (keys from the folder names,
percent-decoded); the exported CSV (Python's csv module, polars), the exported Parquet (pyarrow,
DuckDB, polars), the R readers' dumps (read.csv and data.table::fread, written with %.17g) and
<stem>.meta.json must hold exactly those values, units and provenance. Prints one line of counts.
"""

import argparse
import csv
import json
import math
import pathlib
import struct
import sys
import urllib.parse

import duckdb
import polars as pl
import pyarrow.parquet as pq


def bits(x):
    return struct.pack("<d", x)


def same(expected, got):
    """Exact equality, NaN included; None is null."""
    if expected is None or got is None:
        return expected is None and got is None
    if isinstance(expected, bool) or isinstance(expected, str):
        return expected == got
    if isinstance(expected, float):
        return isinstance(got, float) and (bits(expected) == bits(got) or (math.isnan(expected) and math.isnan(got)))
    return expected == got


def text_value(cell, kind):
    """A CSV cell (NA for null) as the value it stands for."""
    if cell == "NA":
        return None
    if kind == "float64":
        return {"NaN": math.nan, "Inf": math.inf, "-Inf": -math.inf}.get(cell) or float(cell)
    if kind == "int64":
        return int(cell)
    if kind == "bool":
        return {"TRUE": True, "FALSE": False}[cell]
    return cell


def expected_rows(dataset):
    """The stage output as pyarrow reads it, part by part: (column names, rows, units, metadata)."""
    root = pathlib.Path(dataset)
    files = sorted(p for p in root.rglob("data.parquet") if not any(c.startswith(".") for c in p.relative_to(root).parts))
    assert files, f"no data.parquet below {dataset}"
    key_names, columns, units, rows, metadata = [], [], {}, [], []
    parts = []
    for f in files:
        rel = f.relative_to(dataset).parent
        keys = [tuple(urllib.parse.unquote(s) for s in seg.split("=", 1)) for seg in rel.parts]
        table = pq.read_table(f)
        # Provenance where pyarrow users look for it (issue 22): the schema's metadata.
        schema_meta = pq.read_schema(f).metadata
        assert schema_meta and b"shakeflow.stage" in schema_meta, f"{f}: read_schema().metadata lacks provenance"
        assert table.schema.metadata and b"shakeflow.params" in table.schema.metadata, f"{f}: read_table().schema.metadata"
        for k, _ in keys:
            if k not in key_names:
                key_names.append(k)
        for field in table.schema:
            if field.name not in columns:
                columns.append(field.name)
            unit = (field.metadata or {}).get(b"unit", b"").decode()
            assert units.setdefault(field.name, unit) == unit, f"{field.name}: two units"
        parts.append((dict(keys), table))
        metadata.append({k.decode(): v.decode() for k, v in pq.ParquetFile(f).metadata.metadata.items() if k != b"ARROW:schema"})
    names = key_names + columns
    for keys, table in parts:
        data = table.to_pydict()
        for i in range(table.num_rows):
            rows.append([keys.get(k) for k in key_names] + [data[c][i] if c in data else None for c in columns])
    return names, key_names, rows, units, metadata


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--dataset", required=True)
    ap.add_argument("--csv", required=True)
    ap.add_argument("--parquet", required=True)
    ap.add_argument("--r-dump", nargs="*", default=[], help="CSV dumps the R readers wrote (%.17g)")
    args = ap.parse_args()
    names, key_names, rows, units, metadata = expected_rows(args.dataset)

    table_csv = pathlib.Path(args.csv)
    meta = json.loads((table_csv.parent / (table_csv.stem + ".meta.json")).read_text())
    assert list(meta["columns"]) == names, (list(meta["columns"]), names)
    kinds = {n: meta["columns"][n]["type"] for n in names}
    for n in names:
        assert meta["columns"][n]["unit"] == units.get(n, ""), (n, meta["columns"][n]["unit"], units.get(n))
        assert meta["columns"][n]["description"], n
    for k in key_names:
        assert meta["columns"][k]["partition_key"] is True
    # Provenance: every file's stage, parameters, input hashes and version are in the meta file.
    entries = meta["provenance"]
    for m in metadata:
        match = [e for e in entries if e["stage"] == m["shakeflow.stage"] and e["output"] == m["shakeflow.output"]
                 and e["parameters"] == json.loads(m["shakeflow.params"])
                 and e["input_hashes"] == json.loads(m["shakeflow.inputs"])
                 and e["shakeflow_version"] == m["shakeflow.version"]
                 and str(e["stage_version"]) == m["shakeflow.stage_version"]]
        assert len(match) == 1, f"no provenance entry for {m['shakeflow.partition']}"
        hashes = [p.get("input_hash") for p in match[0]["partitions"]]
        assert m.get("shakeflow.input_hash") in hashes

    # The CSV through Python's csv module: the header, then every value exactly.
    with open(args.csv, newline="") as f:
        lines = list(csv.reader(f))
    assert lines[0] == names, (lines[0], names)
    got = [[text_value(c, kinds[n]) for c, n in zip(line, names)] for line in lines[1:]]
    assert len(got) == len(rows), (len(got), len(rows))
    compare("csv", rows, got, names)
    assert open(args.csv, "rb").read().count(b"\r\n") == len(rows) + 1, "RFC 4180 line ends"

    # The exported Parquet: pyarrow values and units, DuckDB and polars see the same table.
    table = pq.read_table(args.parquet)
    assert table.column_names == names
    for field in table.schema:
        assert (field.metadata or {}).get(b"unit", b"").decode() == units.get(field.name, ""), field.name
    assert b"shakeflow.export" in table.schema.metadata
    data = table.to_pydict()
    compare("parquet", rows, [[data[n][i] for n in names] for i in range(table.num_rows)], names)
    count = duckdb.sql(f"SELECT count(*) FROM read_parquet('{args.parquet}')").fetchall()[0][0]
    assert count == len(rows), count
    frame = pl.read_parquet(args.parquet)
    compare("polars parquet", rows, [list(r) for r in frame.iter_rows()], names)
    schema = {n: {"float64": pl.Float64, "int64": pl.Int64, "bool": pl.Boolean, "string": pl.String}[kinds[n]] for n in names}
    from_csv = pl.read_csv(args.csv, null_values="NA", schema=schema)
    compare("polars csv", rows, [list(r) for r in from_csv.iter_rows()], names)

    # The R readers' dumps: floats as %.17g, so equality is exact.
    for dump in args.r_dump:
        with open(dump, newline="") as f:
            lines = list(csv.reader(f))
        assert lines[0] == names, (dump, lines[0], names)
        got = []
        for line in lines[1:]:
            row = []
            for c, n in zip(line, names):
                row.append(text_value(c, kinds[n]))
            got.append(row)
        compare(pathlib.Path(dump).name, rows, got, names)
    print(f"ok: {len(rows)} rows x {len(names)} columns; csv, parquet, duckdb, polars, {len(args.r_dump)} R dump(s) agree")


def compare(what, expected, got, names):
    assert len(expected) == len(got), (what, len(expected), len(got))
    for i, (e, g) in enumerate(zip(expected, got)):
        for n, a, b in zip(names, e, g):
            if not same(a, b):
                sys.exit(f"{what}: row {i} column {n}: expected {a!r}, got {b!r}")


if __name__ == "__main__":
    main()
