"""Executes a notebook top to bottom as Jupyter would (nbclient, the `python3` kernel of this
interpreter), in the notebook's own folder; any cell's error fails with the cell and its traceback.

    python run_notebook.py NOTEBOOK.ipynb
"""

import sys
from pathlib import Path

import nbformat
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError

path = Path(sys.argv[1]).resolve()
notebook = nbformat.read(path, as_version=4)
client = NotebookClient(notebook, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}})
try:
    client.execute()
except CellExecutionError as error:
    sys.exit(f"{path.name} failed:\n{error}")
for cell in notebook.cells:
    for output in cell.get("outputs", []):
        if output.get("output_type") == "error":
            sys.exit(f"{path.name}: a cell raised {output.get('ename')}: {output.get('evalue')}")
print(f"{path.name}: {len(notebook.cells)} cells ran clean")
