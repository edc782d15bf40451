# Reads a `shakeflow export` CSV with R's two usual readers and dumps what each read, floats as
# %.17g (exact), for tests/reference/export_check.py to compare with the Parquet files.
# Usage: Rscript export_check.R TABLE.csv READ_CSV_DUMP.csv FREAD_DUMP.csv
args <- commandArgs(trailingOnly = TRUE)
stopifnot(length(args) == 3)
dump <- function(d, path) {
  d <- as.data.frame(d)
  for (n in names(d)) {
    x <- d[[n]]
    if (is.double(x)) {
      d[[n]] <- ifelse(is.na(x) & !is.nan(x), NA, sprintf("%.17g", x))
      d[[n]][is.nan(x)] <- "NaN"
      d[[n]][is.infinite(x)] <- ifelse(x[is.infinite(x)] > 0, "Inf", "-Inf")
    }
  }
  write.csv(d, path, row.names = FALSE, na = "NA")
}
# Text columns stay text (partition values such as `090` are names, not numbers).
a <- read.csv(args[1], na.strings = "NA", stringsAsFactors = FALSE, check.names = FALSE)
b <- data.table::fread(args[1], na.strings = "NA")
stopifnot(identical(names(a), names(b)), nrow(a) == nrow(b))
for (n in names(a)) {
  if (is.double(a[[n]])) stopifnot(identical(a[[n]], b[[n]]))
}
dump(a, args[2])
dump(b, args[3])
cat("R", format(getRversion()), "data.table", format(packageVersion("data.table")), ":", nrow(a), "rows\n")
