"""LabVIEW Measurement files as lvm_read reads them (J. Slavič's reader on PyPI, `pip install
lvm_read`): an independent reader of the `.lvm` format for tests/it/record_formats.rs.

No real LabVIEW export is public domain and at hand here, so the files in tests/reference/lvm/
were written to NI's published layout (a tab file with decimal commas in two segments, X column
and Comment column; a comma file without X column, times from X0/Delta_X). lvm_read parses them
on its own rules; the test checks shakeflow reads the same channels, units and numbers.

    /root/.cache/shakeflow/venv/bin/pip install lvm_read==1.26
    python tests/reference/records_lvm.py tests/reference/lvm > tests/reference/records_lvm.json
"""
import json
import pathlib
import sys
from importlib.metadata import version

import lvm_read


def main():
    root = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else "tests/reference/lvm")
    files = {}
    for path in sorted(root.glob("*.lvm")):
        lvm = lvm_read.read(str(path), read_from_pickle=False, dump_file=False)
        segments = []
        for s in range(lvm["Segments"]):
            seg = lvm[s]
            names = [n for n in seg["Channel names"] if n not in ("X_Value", "Comment")]
            x_columns = 0 if lvm.get("X_Columns") == "No" else 1
            segments.append({
                "channels": names,
                "units": [u for u in seg.get("Y_Unit_Label", [])][: len(names)],
                "x0": seg["X0"][0],
                "delta_x": seg["Delta_X"][0],
                "x": [float(v) for v in seg["data"][:, 0]] if x_columns else None,
                "values": [[float(v) for v in seg["data"][:, x_columns + c]] for c in range(len(names))],
            })
        files[path.name] = {"decimal_separator": lvm["Decimal_Separator"], "segments": segments}
    json.dump({"tool": f"lvm_read {version('lvm_read')}", "files": files}, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
