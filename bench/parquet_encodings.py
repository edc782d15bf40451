"""`make bench`: which Parquet encoding suits measured float samples (the choice in src/io/parquet.rs).

Writes every record of the demo archive (SI floats, as `load` makes them) with pyarrow in each
compression × {plain, byte-stream split} and prints the write time and the size relative to the raw
floats. Measured samples hardly compress as plain 8-byte floats; split into byte streams, their
sign/exponent bytes do, and a light codec (lz4) then keeps up with zstd's size in a fraction of
its time.
"""
import argparse
import io
import pathlib
import time

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv
import pyarrow.parquet as pq

G = 9.80665


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--archive", required=True)
    args = ap.parse_args()
    tables = []
    groups = pathlib.Path(args.archive) / "NEES-2009-0722.groups"
    for path in sorted(groups.glob("Experiment-*/Trial-*/Rep-1/*_Data/*_DAQ*.*")):
        # NEES text: 4 preamble lines, names, descriptions and units rows; the values as SI-sized
        # doubles (their encoding is what is measured, not the calibration).
        names = path.read_text().split("\n", 5)[4].split("\t")
        t = pcsv.read_csv(path, read_options=pcsv.ReadOptions(skip_rows=7, column_names=names),
                          parse_options=pcsv.ParseOptions(delimiter="\t"))
        tables.append(pa.table({n: pc.multiply(t.column(n), G) for n in t.column_names}))
    raw = sum(t.nbytes for t in tables)
    print(f"Parquet encodings of {len(tables)} demo records ({raw / 1e6:.1f} MB of float64), pyarrow {pa.__version__}")
    print(f"{'compression':<12}{'encoding':<19}{'write ms':>9}{'size / raw':>12}")
    for codec, level in (("zstd", 1), ("lz4", None), ("snappy", None), ("none", None)):
        for split in (False, True):
            started, size = time.perf_counter(), 0
            for t in tables:
                sink = io.BytesIO()
                pq.write_table(t, sink, compression=codec, compression_level=level, use_dictionary=False, use_byte_stream_split=split)
                size += sink.tell()
            ms = 1e3 * (time.perf_counter() - started)
            print(f"{codec:<12}{'byte-stream split' if split else 'plain':<19}{ms:>9.1f}{size / raw:>12.3f}")


if __name__ == "__main__":
    main()
