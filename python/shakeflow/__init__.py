"""shakeflow's command-line tool, installed as a binary by this wheel.

There is no Python API: run ``shakeflow`` (or ``python -m shakeflow``), and read what it writes
(Parquet, MCAP) with pyarrow, polars, pandas or DuckDB.
"""

import os
import sys
import sysconfig

__all__ = ["find_shakeflow_bin"]


def find_shakeflow_bin() -> str:
    """The path of the ``shakeflow`` binary this package installed."""
    exe = "shakeflow" + (sysconfig.get_config_var("EXE") or "")
    candidates = [os.path.join(sysconfig.get_path("scripts"), exe)]
    # `pip install --user`: the user scheme's scripts folder.
    if sys.version_info >= (3, 10):
        user_scheme = sysconfig.get_preferred_scheme("user")
    elif sys.platform == "darwin" and getattr(sys, "_framework", None):
        user_scheme = "osx_framework_user"
    else:
        user_scheme = "posix_user"
    candidates.append(os.path.join(sysconfig.get_path("scripts", scheme=user_scheme), exe))
    # A target folder (`pip install --target DIR`): DIR/bin beside the package.
    candidates.append(os.path.join(os.path.dirname(os.path.dirname(__file__)), "bin", exe))
    for path in candidates:
        if os.path.isfile(path):
            return path
    raise FileNotFoundError(
        "the shakeflow binary is not installed beside this package (looked in: "
        + ", ".join(candidates)
        + "); reinstall with `pip install --force-reinstall shakeflow`"
    )
