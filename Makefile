# shakeflow — `make demo` runs the demo study, `make test` runs every check.
#
# Builds go to a persistent target directory outside the clone, so a fresh clone on a machine
# that built shakeflow before rebuilds in seconds. Override with CARGO_TARGET_DIR=... .
CARGO_TARGET_DIR ?= $(HOME)/.cache/shakeflow-target
export CARGO_TARGET_DIR
# .cargo/config.toml builds for x86-64-v3. On an x86-64 CPU without it (or where the loader cannot
# tell), build for baseline x86-64 instead: the same artifacts, a little slower.
ifeq ($(shell uname -m),x86_64)
ifneq ($(shell /lib64/ld-linux-x86-64.so.2 --help 2>/dev/null | grep -c 'x86-64-v3 .supported'),1)
export CARGO_TARGET_X86_64_UNKNOWN_LINUX_GNU_RUSTFLAGS := -C target-cpu=x86-64
endif
endif
CARGO ?= cargo
PYTHON ?= python3
# Python is only an independent reference (numpy, scipy, pyarrow, mcap, duckdb) for tests and benchmarks.
VENV ?= $(HOME)/.cache/shakeflow/venv
VENV_PY := $(VENV)/bin/python
PY_STAMP := $(VENV)/.requirements-$(shell cksum < tests/reference/requirements.txt | cut -d' ' -f1)
BIN := $(CARGO_TARGET_DIR)/release/shakeflow

.PHONY: all demo test wheel wheel-dev bench bench-scale convergence prove prove-rolling prove-check release schema docs fmt lint clean help rolling-findings fuzz

help:
	@echo "make demo    build (release) and run the demo study: runs/demo-archive -> runs/demo"
	@echo "make test    build and run the whole test suite (installs the Python references it needs)"
	@echo "make wheel   the PyPI wheel (manylinux2014, baseline x86-64, zig) and sdist in dist/ (docs/packaging.md)"
	@echo "make bench   the demo study's artifact footprint vs its raw archive; load+baseline and the whole demo study vs numpy/scipy/pyarrow scripts; the rocking and rolling models vs scipy and RK4; CPT matching and 1080p tracking vs OpenCV"
	@echo "make convergence  the convergence study of the models' numerical defaults over the shared real records (docs/convergence.md)"
	@echo "make bench-scale  the per-record stages over a generated archive of TESTS=200 tests (e.g. TESTS=100,1000,10000), local and on the test Slurm; no-op rerun"
	@echo "make prove   fresh concealed-effect cases (prove/generate_cases.py) scored against shakeflow diagnose"
	@echo "             [SEED=n] [PER_EFFECT=5] [PROVE_JOBS=2]; make prove-check re-checks the generator's physics"
	@echo "make prove-rolling   the same for rolling units (prove/rolling/) [SEED=n] [ROLLING_PER_EFFECT=4]"
	@echo "make schema  regenerate schemas/pipeline.schema.json from the stage registry"
	@echo "make docs    regenerate docs/stages.md from the stage declarations"
	@echo "make rolling-findings  the study's rolling findings on the demo archive, as tables (docs/models/rolling.md)"
	@echo "make fuzz    coverage-guided fuzzing of every file reader and the pipeline parser (docs/fuzzing.md)"
	@echo "             [FUZZ_SECONDS=120 per target] [FUZZ_TARGETS=\"at2 pipeline ...\"]"

# The executable is linked statically where glibc's static libraries are (x86-64 Linux with
# libc6-dev): no dynamic loader at each start, ~1.3 ms less CPU a `stage` call (docs/benchmarks.md,
# "Per call"). Cargo cannot ask for a static C runtime for one binary of a package (the flag would
# reach the proc macros), hence `cargo rustc`; `cargo test` links the same code dynamically.
STATIC := $(if $(and $(filter x86_64,$(shell uname -m)),$(wildcard /usr/lib/x86_64-linux-gnu/libc.a)),-C target-feature=+crt-static -C relocation-model=static)

release:
	$(CARGO) rustc --release --locked --bin shakeflow $(if $(STATIC),-- $(STATIC))

demo: release
	$(BIN) demo-archive runs/demo-archive
	$(BIN) run pipelines/demo.yaml
	@echo "Study summary (runs/demo/report/summary/data.parquet):"
	@$(BIN) show runs/demo/report/summary/data.parquet
	@echo "Rolling units (runs/demo/report/rolling/data.parquet; figures in runs/demo/rolling_*/figures/):"
	@$(BIN) show runs/demo/report/rolling/data.parquet
	@echo "Mismatch diagnosis of the archive's cases (runs/demo/diagnosis/: <case>/diagnosis.json and reports/<case>.png per case):"
	@$(BIN) show runs/demo/diagnosis/diagnosis/data.parquet --columns case,verdict,window_start_s,window_end_s,rmse_before,rmse_after
	@echo "The study report: open runs/demo/report/index.html in a browser"

$(PY_STAMP): tests/reference/requirements.txt
	$(PYTHON) -m venv $(VENV)
	$(VENV_PY) -m pip install --quiet --disable-pip-version-check -r tests/reference/requirements.txt
	touch $@

# The tests build with the release profile, the one `make demo` builds: the dependencies compile
# once for both commands, not once per profile (docs/benchmarks.md, cold start).
# The Slurm tests run against a multi-node test Slurm started here and stopped after (by pid, also when
# tests fail; left running if it already ran). Without root it cannot start: those tests then fail, saying so.
test: $(PY_STAMP) wheel-dev
	sh tests/system/install-r.sh
	sh tests/system/chromium.sh
	@was_running=$$(tests/system/slurm.sh status >/dev/null 2>&1 && echo yes); \
	tests/system/slurm.sh start || echo "make test: the test Slurm did not start; the Slurm tests will fail"; \
	SHAKEFLOW_PYTHON=$(VENV_PY) SHAKEFLOW_WHEEL=$$(ls $(DEV_WHEELS)/shakeflow-*.whl) \
	  $(CARGO) test --release --locked --no-fail-fast; status=$$?; \
	[ -n "$$was_running" ] || tests/system/slurm.sh stop; exit $$status

# The wheel the tests install (tests/it/wheel.rs): maturin over the same release build the tests
# use, so it costs a relink, not a rebuild.
DEV_WHEELS := $(CARGO_TARGET_DIR)/wheels-dev
wheel-dev: $(PY_STAMP)
	rm -rf $(DEV_WHEELS)
	$(VENV_PY) -m maturin build --release --locked --quiet --out $(DEV_WHEELS)

# The release wheel and sdist (docs/packaging.md): manylinux2014 through zig (maturin finds it
# through the venv's python, hence the PATH), baseline x86-64, in a target folder of their own.
WHEEL_TARGET_DIR ?= $(HOME)/.cache/shakeflow-wheel-target
wheel: $(PY_STAMP)
	$(VENV_PY) -m pip install --quiet --disable-pip-version-check "ziglang>=0.13"
	PATH=$(VENV)/bin:$$PATH CARGO_TARGET_DIR=$(WHEEL_TARGET_DIR) CARGO_TARGET_X86_64_UNKNOWN_LINUX_GNU_RUSTFLAGS="-C target-cpu=x86-64" \
	  $(VENV_PY) -m maturin build --release --locked --zig --compatibility manylinux2014 --out dist
	$(VENV_PY) -m maturin sdist --out dist

BENCH_SUMMARY := runs/bench-summary.txt
bench: export SHAKEFLOW_BENCH_SUMMARY = $(abspath $(BENCH_SUMMARY))
bench: release $(PY_STAMP)
	$(BIN) demo-archive runs/demo-archive
	rm -f $(BENCH_SUMMARY)
	$(VENV_PY) bench/footprint.py --shakeflow $(BIN) --archive runs/demo-archive
	$(VENV_PY) bench/parquet_encodings.py --archive runs/demo-archive
	$(VENV_PY) bench/load_baseline.py --shakeflow $(BIN) --archive runs/demo-archive
	$(VENV_PY) bench/demo_study.py --shakeflow $(BIN) --archive runs/demo-archive
	$(VENV_PY) bench/rocking.py --shakeflow $(BIN)
	$(VENV_PY) bench/rolling.py --shakeflow $(BIN)
	$(CARGO) build --release --locked --example cpt_match
	$(VENV_PY) bench/cpt.py --shakeflow $(BIN) --matcher $(CARGO_TARGET_DIR)/release/examples/cpt_match
	$(VENV_PY) bench/load_formats.py --shakeflow $(BIN)
	$(VENV_PY) bench/stage_call.py --shakeflow $(BIN)
	@echo "Ratios side by side:"; cat $(BENCH_SUMMARY)

# The convergence study of the numerical defaults (docs/convergence.md): rolling, then rocking.
convergence:
	$(CARGO) build --release --locked --example convergence
	$(CARGO_TARGET_DIR)/release/examples/convergence --out docs/convergence
	$(CARGO_TARGET_DIR)/release/examples/convergence --out docs/convergence --law stick_slip --sweeps friction_eps,friction_eps_swivel
	$(CARGO_TARGET_DIR)/release/examples/convergence --out docs/convergence --rocking

# Scale: the demo's per-record stages over a generated archive of TESTS tests, local and on the
# multi-node test Slurm (started and stopped here when it was not running; needs root), no-op rerun.
# Above 1000 tests the archive repeats the 1000-test one's variation tests as hard links (10⁴: 2.3 GB).
TESTS ?= 200
bench-scale: release $(PY_STAMP)
	$(VENV_PY) bench/scale.py --shakeflow $(BIN) --tests $(TESTS)

# The proof: a fresh set of concealed-effect cases (new seed unless SEED is given), diagnosed and scored.
PROVE_DIR ?= runs/prove
PER_EFFECT ?= 5
PROVE_JOBS ?= 2
SEED ?=

prove: release $(PY_STAMP)
	rm -rf $(PROVE_DIR)
	$(VENV_PY) prove/generate_cases.py $(PROVE_DIR)/cases --per-effect $(PER_EFFECT) --jobs $(PROVE_JOBS) $(if $(SEED),--seed $(SEED))
	$(VENV_PY) prove/score.py $(PROVE_DIR)/cases --shakeflow $(BIN) --jobs $(PROVE_JOBS)

# The rolling proof: fresh concealed rolling cases (prove/rolling/generate.py), diagnosed and scored.
PROVE_ROLLING_DIR ?= runs/prove-rolling
ROLLING_PER_EFFECT ?= 4

prove-rolling: release $(PY_STAMP)
	rm -rf $(PROVE_ROLLING_DIR)
	$(VENV_PY) prove/rolling/generate.py $(PROVE_ROLLING_DIR)/cases --per-effect $(ROLLING_PER_EFFECT) --jobs $(PROVE_JOBS) $(if $(SEED),--seed $(SEED))
	$(VENV_PY) prove/rolling/score.py $(PROVE_ROLLING_DIR)/cases --shakeflow $(BIN) --jobs $(PROVE_JOBS) --out $(PROVE_ROLLING_DIR)

prove-check: $(PY_STAMP)
	$(VENV_PY) prove/check_generator.py

schema:
	$(CARGO) run --quiet --locked -- schema > schemas/pipeline.schema.json

docs:
	$(CARGO) run --quiet --locked -- stages --markdown > docs/stages.md

rolling-findings:
	$(CARGO) test --release --locked --test it rolling_findings -- --nocapture

fmt:
	$(CARGO) fmt

lint:
	$(CARGO) clippy --all-targets -- -D warnings

# Coverage-guided fuzzing (cargo-fuzz, libFuzzer) of the readers and the pipeline parser, seeded
# with the real files in ../shared and the pipelines; fuzz/ is its own workspace, outside `make
# test`. Stable Rust: RUSTC_BOOTSTRAP lets cargo-fuzz pass its -Z flags (docs/fuzzing.md).
FUZZ_SECONDS ?= 120
FUZZ_TARGETS ?= at2 renadic_v1 simcenter_json delimited control_points equipment pipeline load
FUZZ_SEEDS_at2 := ../shared/data/ground_motions/*.AT2 ../shared/data/records/nga/*
FUZZ_SEEDS_renadic_v1 := ../shared/data/ground_motions/*.v1
FUZZ_SEEDS_simcenter_json := ../shared/data/ground_motions/*.json
FUZZ_SEEDS_delimited := ../shared/cases/*/demo_01/*.csv ../shared/data/records/esm/* ../shared/data/records/knet/*.EW
FUZZ_SEEDS_control_points := fuzz/seeds/control_points.csv
FUZZ_SEEDS_equipment := ../shared/cases/demo/demo_01/equipment.yaml ../shared/cases/rolling_demo/demo_01/equipment.yaml
FUZZ_SEEDS_pipeline := pipelines/*.yaml
FUZZ_SEEDS_load := ../shared/data/ground_motions/Rinaldi228.AT2 ../shared/cases/demo/demo_01/floor.csv

fuzz:
	command -v cargo-fuzz >/dev/null || $(CARGO) install cargo-fuzz --locked
	@for t in $(FUZZ_TARGETS); do \
	  mkdir -p fuzz/corpus/$$t && \
	  case $$t in \
	    at2) seeds="$(FUZZ_SEEDS_at2)";; renadic_v1) seeds="$(FUZZ_SEEDS_renadic_v1)";; \
	    simcenter_json) seeds="$(FUZZ_SEEDS_simcenter_json)";; delimited) seeds="$(FUZZ_SEEDS_delimited)";; \
	    control_points) seeds="$(FUZZ_SEEDS_control_points)";; equipment) seeds="$(FUZZ_SEEDS_equipment)";; \
	    pipeline) seeds="$(FUZZ_SEEDS_pipeline)";; load) seeds="$(FUZZ_SEEDS_load)";; \
	  esac; \
	  for f in $$seeds; do cp -n "$$f" fuzz/corpus/$$t/ || exit 1; done; \
	  echo "fuzzing $$t for $(FUZZ_SECONDS) s"; \
	  CARGO_TARGET_DIR=$(CARGO_TARGET_DIR)/fuzz RUSTC_BOOTSTRAP=1 $(CARGO) fuzz run --sanitizer none $$t fuzz/corpus/$$t -- \
	    -max_total_time=$(FUZZ_SECONDS) -rss_limit_mb=4096 -max_len=262144 -print_final_stats=1 || exit 1; \
	done

clean:
	rm -rf runs
