"""Checks what issue 22 found wrong in fragility tables, with the readers a user has
(tests/it/export.rs runs it on a toppling_fragility output made from `record=…` partitions).

- pyarrow: provenance in the Arrow schema metadata (`read_schema(f).metadata`).
- DuckDB: `runs.record` holds the record names other tables hold (no `record=` prefix), and
  `GROUP BY im` gives one group per level with every record in it (no 0.9999999999999999).
- polars: `level` is an integer index and equal levels have bit-equal `im`.
Prints the groups.
"""

import argparse
import json

import duckdb
import polars as pl
import pyarrow.parquet as pq


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", required=True, help="the runs table (data.parquet)")
    ap.add_argument("--levels", required=True, help="the im_levels, JSON")
    ap.add_argument("--records", required=True, help="the record names, JSON")
    args = ap.parse_args()
    levels, records = json.loads(args.levels), sorted(json.loads(args.records))

    meta = pq.read_schema(args.runs).metadata
    assert meta and meta[b"shakeflow.stage_type"] == b"toppling_fragility", meta
    assert json.loads(meta[b"shakeflow.params"])["im_levels"] == levels

    names = sorted(r[0] for r in duckdb.sql(f"SELECT DISTINCT record FROM read_parquet('{args.runs}')").fetchall())
    assert names == records, (names, records)
    groups = duckdb.sql(
        f"SELECT im, count(*), count(DISTINCT record), min(level), max(level) FROM read_parquet('{args.runs}') GROUP BY im ORDER BY im"
    ).fetchall()
    assert [g[0] for g in groups] == levels, groups
    for im, n, distinct, lo, hi in groups:
        assert n == distinct == len(records) and lo == hi, (im, n, distinct, lo, hi)

    runs = pl.read_parquet(args.runs)
    assert runs.schema["level"] == pl.Int64, runs.schema
    by_level = runs.group_by("level").agg(pl.col("im").n_unique().alias("values"), pl.col("im").first())
    assert by_level["values"].to_list() == [1] * len(levels), by_level
    assert sorted(by_level["im"].to_list()) == levels
    print("ok:", groups)


if __name__ == "__main__":
    main()
