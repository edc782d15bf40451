"""The shared K-NET/KiK-net records as ObsPy reads them (obspy.io.nied.knet): a second
independent reader for that format, which keeps the counts and gives the scale factor as
`calib` (in m/s² per count).

Writes records_obspy.json: per file the counts' first 5 and last values, npts, delta, calib and
the header's `accmax` (gal); tests/it/record_formats.rs checks shakeflow's values, in m/s², are
counts × calib (the same numbers, rounded once more).

    /root/.cache/shakeflow/venv/bin/pip install obspy
    python tests/reference/records_obspy.py ../shared/data/records > tests/reference/records_obspy.json
"""
import json
import pathlib
import sys
from importlib.metadata import version

import obspy


def main():
    root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "../shared/data/records")
    files = {}
    for path in sorted((root / "knet").iterdir()):
        trace = obspy.read(str(path), format="KNET")[0]
        files[f"knet/{path.name}"] = {
            "channel": trace.stats.channel,
            "npts": int(trace.stats.npts),
            "delta": float(trace.stats.delta),
            "calib": float(trace.stats.calib),
            "accmax_gal": float(trace.stats.knet.accmax),
            "first_counts": [float(v) for v in trace.data[:5]],
            "last_count": float(trace.data[-1]),
            "sum_counts": float(trace.data.astype("float64").sum()),
        }
    json.dump({"tool": f"obspy {version('obspy')}", "files": files}, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
