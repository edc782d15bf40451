"""``python -m shakeflow ...``: runs the installed ``shakeflow`` binary with the same arguments."""

import os
import sys

from shakeflow import find_shakeflow_bin


def main() -> None:
    binary = os.fsdecode(find_shakeflow_bin())
    if sys.platform == "win32":
        import subprocess

        sys.exit(subprocess.run([binary, *sys.argv[1:]]).returncode)
    os.execv(binary, [binary, *sys.argv[1:]])


if __name__ == "__main__":
    main()
