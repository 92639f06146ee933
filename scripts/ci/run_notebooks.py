"""Executes every notebook of a folder headless (nbclient, the `python3` kernel of the running
environment), each in its own folder, after checking that the repository holds it with its outputs
stripped. Exit 1 on a notebook with outputs or one whose cell raised. Each kernel's temporary
directory (TMPDIR: where a notebook writes its results) is a scratch directory removed afterwards,
so that the runs leave nothing behind."""

import os
import sys
import tempfile
import time
from pathlib import Path

import nbclient
import nbformat


def main(folder: Path) -> int:
    notebooks = sorted(folder.glob("*.ipynb"))
    if not notebooks:
        print(f"{folder}: no notebook", file=sys.stderr)
        return 1
    for path in notebooks:
        nb = nbformat.read(path, as_version=4)
        kept = [i for i, c in enumerate(nb.cells) if c.cell_type == "code" and (c.outputs or c.execution_count is not None)]
        if kept:
            print(f"{path}: cells {kept} carry outputs: strip them (jupyter nbconvert --clear-output --inplace)", file=sys.stderr)
            return 1
        start = time.monotonic()
        before = os.environ.get("TMPDIR")
        with tempfile.TemporaryDirectory(prefix="calsim-notebook-") as scratch:
            os.environ["TMPDIR"] = scratch  # the kernel inherits it
            try:
                nbclient.NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}).execute()
            except nbclient.exceptions.CellExecutionError as e:
                print(f"{path}: {e}", file=sys.stderr)
                return 1
            finally:
                if before is None:
                    del os.environ["TMPDIR"]
                else:
                    os.environ["TMPDIR"] = before
        cells = sum(1 for c in nb.cells if c.cell_type == "code")
        print(f"ci: notebook {path.name}: {cells} cells executed in {time.monotonic() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(Path(sys.argv[1])))
