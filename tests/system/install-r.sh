#!/bin/sh
# R for the export tests (tests/it/export.rs): Debian's r-base-core, r-cran-data.table (fread) and
# r-cran-jsonlite (the README's R snippet reads <stem>.meta.json with it). Quick when they are
# already there. Without root or apt it installs nothing and says so: the R test then fails
# with the same advice, it never skips.
set -u
if command -v Rscript >/dev/null 2>&1 &&
  Rscript -e 'quit(status = !all(sapply(c("data.table", "jsonlite"), requireNamespace, quietly = TRUE)))' >/dev/null 2>&1; then
  exit 0
fi
advice="install R with: sudo apt-get install r-base-core r-cran-data.table r-cran-jsonlite"
if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "tests/system/install-r.sh: R is missing and this is not root with apt-get; the R export test will fail. $advice" >&2
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
if ! apt-get install -y -q --no-install-recommends r-base-core r-cran-data.table r-cran-jsonlite >/dev/null; then
  apt-get update -q >/dev/null &&
    apt-get install -y -q --no-install-recommends r-base-core r-cran-data.table r-cran-jsonlite >/dev/null ||
    echo "tests/system/install-r.sh: apt-get could not install R; the R export test will fail. $advice" >&2
fi
