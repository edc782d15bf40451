"""The shared strong-motion records as USGS gmprocess reads them: an independent reader to check
shakeflow's COSMOS, CSMIP/DMG, SMC, K-NET/KiK-net, ESM and GeoNet readers against.

Writes records_gmprocess.json: for every file in ../shared/data/records/<format>/ (the PEER AT2
aside: gmprocess has no reader for it), each trace gmprocess gives with its channel code,
horizontal orientation, units, npts, delta, and values: every 97th sample (from the first), the
last one, the peak (largest |value|, with its index), and the exact sum (math.fsum).
tests/it/record_formats.rs compares shakeflow's `load` output with them.

gmprocess is heavy (it pulls openquake, numba, geopandas) and pins numpy < 2.4, so it is not in
requirements.txt: run this in a venv of its own.

    python -m venv /tmp/gm && /tmp/gm/bin/pip install gmprocess==2.8.0
    /tmp/gm/bin/python tests/reference/records_gmprocess.py ../shared/data/records > tests/reference/records_gmprocess.json
"""
import json
import math
import pathlib
import sys
from importlib.metadata import version

import numpy as np
from gmprocess.io.cosmos.core import read_cosmos
from gmprocess.io.dmg.core import read_dmg
from gmprocess.io.esm.core import read_esm
from gmprocess.io.geonet.core import read_geonet
from gmprocess.io.knet.core import read_knet
from gmprocess.io.smc.core import read_smc

READERS = {
    "cosmos": read_cosmos,
    "dmg": read_dmg,
    "smc": read_smc,
    "knet": read_knet,
    "esm": read_esm,
    "geonet": read_geonet,
}
STRIDE = 97


def summary(trace):
    data = np.asarray(trace.data, dtype=np.float64)
    peak = int(np.argmax(np.abs(data)))
    standard = trace.stats.standard
    orientation = standard.get("horizontal_orientation", float("nan"))
    return {
        "channel": trace.stats.channel,
        "horizontal_orientation": None if math.isnan(orientation) else orientation,
        "units": standard.get("units", ""),
        "npts": int(trace.stats.npts),
        "delta": float(trace.stats.delta),
        "dtype": str(trace.data.dtype),
        "stride": STRIDE,
        "samples": [float(v) for v in data[::STRIDE]],
        "last": float(data[-1]),
        "peak_index": peak,
        "peak": float(data[peak]),
        "fsum": math.fsum(float(v) for v in data),
    }


def main():
    root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "../shared/data/records")
    files = {}
    for fmt, reader in READERS.items():
        for path in sorted((root / fmt).iterdir()):
            streams = reader(str(path))
            files[f"{fmt}/{path.name}"] = [summary(trace) for stream in streams for trace in stream]
    json.dump({"tool": f"gmprocess {version('gmprocess')}, obspy {version('obspy')}, numpy {np.__version__}",
               "files": files}, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
