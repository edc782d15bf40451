"""Independent readers on shakeflow artifacts: pyarrow, DuckDB, and the `mcap` package with
Google's protobuf runtime (`mcap-protobuf-support`, the decoding Foxglove does with protobufjs).

Usage: check_artifacts.py OUTPUT_DIR STAGE
Checks that every Parquet part of OUTPUT_DIR/STAGE/records carries units and descriptions per
column and provenance per file, that pyarrow.dataset and DuckDB scan the folder as one
Hive-partitioned dataset, and that each MCAP twin (OUTPUT_DIR/STAGE/mcap/records/...) holds the
same samples as its Parquet part: every float column at the first, middle and last sample, bit for
bit, with its unit and description in the channel metadata.
"""
import json
import math
import pathlib
import sys

import duckdb
import pyarrow.dataset as ds
import pyarrow.parquet as pq
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory


def main(out_dir, stage):
    root = pathlib.Path(out_dir) / stage / "records"
    parts = sorted(root.rglob("data.parquet"))
    assert parts, f"no parts under {root}"
    total = 0
    for part in parts:
        table = pq.read_table(part)
        meta = pq.read_metadata(part).metadata
        assert meta[b"shakeflow.stage"] == stage.encode(), meta.keys()
        for key in (b"shakeflow.params", b"shakeflow.inputs", b"shakeflow.version", b"shakeflow.input_hash"):
            assert key in meta, f"{part}: no {key!r}"
        json.loads(meta[b"shakeflow.params"])
        for field in table.schema:
            fm = field.metadata or {}
            assert b"unit" in fm and b"description" in fm, f"{part}: column {field.name} lacks unit/description"
        assert table.schema.field("time_s").metadata[b"unit"] == b"s"
        total += table.num_rows

        mcap_path = root.parent / "mcap" / "records" / part.relative_to(root).with_name("data.mcap")
        assert mcap_path.exists(), mcap_path
        with open(mcap_path, "rb") as f:
            reader = make_reader(f, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            schemas = {s.encoding for s in summary.schemas.values()}
            assert schemas == {"protobuf"}, schemas
            # Compressed chunks (lz4), which this reader decompresses as Foxglove does.
            compressions = {c.compression for c in summary.chunk_indexes}
            assert compressions == {"lz4"}, compressions
            messages = [(ch.topic, ch.metadata, decoded, msg.log_time) for _, ch, msg, decoded in reader.iter_decoded_messages()]
        assert len(messages) == table.num_rows, (len(messages), table.num_rows)
        floats = [field for field in table.schema if field.type == "double"]
        assert len(floats) > 1, floats
        times = table.column("time_s").to_pylist()
        for i in (0, table.num_rows // 2, table.num_rows - 1):
            topic, channel_metadata, decoded, log_time = messages[i]
            for field in floats:
                value, twin = table.column(field.name)[i].as_py(), getattr(decoded, field.name)
                assert twin == value or (math.isnan(twin) and math.isnan(value)), (field.name, i, twin, value)
                assert channel_metadata[f"unit.{field.name}"] == field.metadata[b"unit"].decode()
                assert channel_metadata[f"description.{field.name}"] == field.metadata[b"description"].decode()
            assert abs(log_time - round(times[i] * 1e9)) <= 1
        assert topic.startswith(f"/{stage}/records"), topic

    dataset = ds.dataset(root, format="parquet", partitioning="hive")
    scanned = dataset.to_table()
    assert scanned.num_rows == total, (scanned.num_rows, total)
    partition_keys = [name for name in scanned.column_names if name not in pq.read_table(parts[0]).column_names]
    assert partition_keys, "no Hive partition columns found"

    con = duckdb.connect()
    rows = con.execute(
        f"SELECT count(*) FROM read_parquet('{root}/**/*.parquet', hive_partitioning = true)"
    ).fetchone()[0]
    assert rows == total, (rows, total)
    print(f"OK: {len(parts)} parts, {total} rows, partitions {partition_keys}, MCAP twins match")


if __name__ == "__main__":
    main(*sys.argv[1:])
