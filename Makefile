# The single entry point. `make demo` and `make test` work on a fresh Debian 12
# machine as root: both install what is missing, build, then run.
BUILD ?= build
JOBS ?= $(shell nproc 2>/dev/null || echo 2)
CMAKE_FLAGS ?=
# Debian's own Python sees python3-torch / python3-scipy; another python3 may be first on PATH.
PYTHON ?= /usr/bin/python3

DEB_PACKAGES := build-essential cmake pkg-config \
  libeigen3-dev libceres-dev libcli11-dev nlohmann-json3-dev libfmt-dev \
  libgtest-dev libgmock-dev libbenchmark-dev \
  libtorch-dev libopenblas0-openmp \
  pybind11-dev python3-dev python3-numpy python3-torch python3-scipy python3-dask python3-distributed \
  gnuplot-nox \
  libroscpp-dev librosbag-dev libsensor-msgs-dev python3-rosmaster \
  libsqlite3-dev libzstd-dev liblz4-dev libyaml-cpp-dev cyclonedds-dev cyclonedds-tools libfastrtps-dev

.PHONY: deps build test build-sanitize test-sanitize demo live-demo bench coverage learning-curve batch-speed docs-figures docs-cli soak fuzz fuzz-deps clean

# Idempotent: asks dpkg first and calls apt only for what is missing.
deps:
	@missing=""; for p in $(DEB_PACKAGES); do \
	  dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q '^install ok installed$$' || missing="$$missing $$p"; \
	done; \
	if [ -z "$$missing" ]; then echo "deps: all Debian packages present"; \
	elif [ "$$(id -u)" != 0 ]; then echo "deps: missing:$$missing -- run 'make deps' as root" >&2; exit 1; \
	else echo "deps: installing$$missing"; \
	  export DEBIAN_FRONTEND=noninteractive; \
	  apt-get update -qq && apt-get install -y -qq --no-install-recommends $$missing; \
	fi

$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release -DPython3_EXECUTABLE=$(PYTHON) $(CMAKE_FLAGS)

build: deps $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j $(JOBS)

test: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

# The library, CLI, nodes and tests built with AddressSanitizer and
# UndefinedBehaviorSanitizer (any report fails its test), then every test. Not
# instrumented: the Python module (loaded by an uninstrumented interpreter), the
# benchmarks (timing programs, not tests) and the LibTorch training code (a
# network's training is mostly LibTorch's own, uninstrumented, code; the
# library's LSTM and MLP inference is instrumented); the other Debian
# libraries are called from instrumented code but are not instrumented themselves.
# -O2 -DNDEBUG, as the release build: out-of-bounds accesses that Eigen's
# asserts would stop are ASan's reports here. ASan's use-after-scope check is
# off: it poisons and unpoisons every temporary of Ceres's automatic
# differentiation and made the instrumented Jet arithmetic 6 times slower
# (heap, stack and global overflows, use after free and leaks are still caught).
# UBSan's null, alignment and pointer-overflow checks are off: on Eigen's
# pointer arithmetic they lengthen the instrumented build most (the compile
# column of bench/sanitizer_cost.py's table); a null dereference still faults and
# ASan reports it with its stack, as it does an access out of bounds.
# The random-session property test runs one session of two trials instrumented.
# The library is shared (RCM_SHARED_LIBS): linked statically, each of the 77
# programs would hold its own 48 MB instrumented copy, 3.2 GB in all (the disk
# each phase leaves: docs/validation-reliability.md).
SANITIZE_BUILD ?= build-sanitize
SANITIZE_FLAGS := -O2 -g1 -DNDEBUG -fsanitize=address,undefined -fno-sanitize-recover=all \
  -fno-sanitize=null,alignment,pointer-overflow \
  -fno-sanitize-address-use-after-scope -fno-omit-frame-pointer
build-sanitize: deps
	cmake -S . -B $(SANITIZE_BUILD) -DCMAKE_BUILD_TYPE=Sanitize \
	  -DCMAKE_CXX_FLAGS_SANITIZE="$(SANITIZE_FLAGS)" -DCMAKE_C_FLAGS_SANITIZE="$(SANITIZE_FLAGS)" \
	  -DCMAKE_EXE_LINKER_FLAGS_SANITIZE="-fsanitize=address,undefined" \
	  -DCMAKE_SHARED_LINKER_FLAGS_SANITIZE="-fsanitize=address,undefined" \
	  -DCMAKE_MODULE_LINKER_FLAGS_SANITIZE="-fsanitize=address,undefined" \
	  -DRCM_BUILD_BENCH=OFF -DRCM_WITH_PYTHON=OFF -DRCM_WITH_TORCH=OFF -DRCM_SHARED_LIBS=ON -DPython3_EXECUTABLE=$(PYTHON) $(CMAKE_FLAGS)
	cmake --build $(SANITIZE_BUILD) -j $(JOBS)

test-sanitize: build-sanitize
	cd $(SANITIZE_BUILD) && ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
	  RCM_PROPERTY_SESSIONS=1 RCM_PROPERTY_TRIALS=2 RCM_STATISTICAL_TESTS=0 ctest --output-on-failure -j $(JOBS)

demo: build
	$(BUILD)/bin/rcm demo --out demo-out

# Docking to the first estimate on the robot's own interfaces (CRTK over
# loopback DDS) against the simulated PSM: excitation, baseline, calibration,
# rcm setup, the live estimate, then a 35 mm step of the incision with the loop
# closed across processes (docs/howto-procedure.md). Under 3 minutes on 2
# cores (the monitors load the tissue model rcm setup saved); writes
# live-demo-out/live_demo.json.
live-demo: build
	$(PYTHON) bench/live_demo.py --build $(BUILD) --out live-demo-out

# Every Google Benchmark program, the rosbag2 anchors (sqlite3, zstd), the live
# nodes' end-to-end tests (their per-sample timings), PyTorch beside LibTorch and
# the scipy cross-check; writes their tables into docs/benchmarks.md.
bench: build
	$(PYTHON) bench/run_benchmarks.py --build $(BUILD)

# Each method's error on the worst seed and its spread, interval coverage, the
# calibration's bias correction before and after, and the self-check's hits,
# over 10 seeds x 3 tissue laws x 3 free-space rows on the default bench, as
# independent tasks through rcm.batch (COVERAGE_JOBS local workers, or the
# workers of SCHEDULER, below), in COVERAGE_WORK (kept: a rerun
# resumes; summary.json holds every task's figures); writes its tables into
# docs/validation.md. Its wall time is in the table's heading.
COVERAGE_SEEDS ?= 1,2,3,4,5,6,7,8,9,10
COVERAGE_JOBS ?= 2
COVERAGE_WORK ?= coverage-work
coverage: build
	$(PYTHON) bench/interval_coverage.py --build $(BUILD) --seeds $(COVERAGE_SEEDS) --work $(COVERAGE_WORK) \
	  $(if $(SCHEDULER),--scheduler $(SCHEDULER),--workers $(COVERAGE_JOBS))

# The free-space model's held-out torque error and estimate error against the
# length of teleoperation and excitation data (about 10 minutes on 2 cores);
# prints its table (bench/learning_curve.py --doc writes it and its figure into
# docs/validation-free-space.md). REAL=DIR adds the curve of
# real recordings (NAME_full.csv / NAME_half.csv pairs).
# SCHEDULER=tcp://HOST:8786 runs the independent runs of the learning curve and
# of the closed-loop bench on that Dask scheduler's workers instead of a local
# cluster (docs/howto-batch.md); the tables are the same.
SCHEDULER ?=
learning-curve: build
	$(PYTHON) bench/learning_curve.py --build $(BUILD) $(if $(REAL),--real $(REAL)) $(if $(SCHEDULER),--scheduler $(SCHEDULER))

# `rcm batch` on 8 simulated sessions with 1 and 2 workers against `rcm run` one
# after another, results compared (about 30 minutes on 2 cores); writes its
# table into docs/benchmarks.md.
batch-speed: build
	$(PYTHON) bench/batch_speed.py --build $(BUILD)

# The accuracy figures of docs/validation.md, from runs on this machine, with the
# date and machine: the worst-case tables (make coverage), the demo's table with
# their worst seed (and its wall times, docs/benchmarks.md) and the
# closed-loop bench.
docs-figures: coverage
	$(PYTHON) bench/demo_table.py --build $(BUILD) --coverage-summary $(COVERAGE_WORK)/summary.json
	$(PYTHON) bench/closed_loop_report.py --build $(BUILD) $(if $(SCHEDULER),--scheduler $(SCHEDULER))

# The command reference, docs/cli.md (rcm), docs/cli-programs.md (the nodes and DDS
# tools) and docs/cli-files.md, from every program's --help and the files of a quick
# study (tools/gen_cli_reference.py; the ctest docs_cli_reference checks them).
docs-cli: build
	$(PYTHON) tools/gen_cli_reference.py --build $(BUILD)

# The long reliability runs (about 25 minutes on 2 cores): the live stream soak,
# SOAK_MESSAGES joint-state messages with faults through the live nodes'
# per-message path, and the estimate's properties on 200 random sessions' trials;
# writes their tables into docs/validation-reliability.md.
SOAK_MESSAGES ?= 10000000
soak: build
	$(PYTHON) bench/soak_report.py --build $(BUILD) --messages $(SOAK_MESSAGES)

# libFuzzer on every reader of outside data (docs/reliability.md, "Fuzzing"):
# a clang build with ASan and UBSan in FUZZ_BUILD, then each target for
# FUZZ_SECONDS on a scratch corpus seeded from fuzz/corpus (the repository's
# corpus is never grown). FUZZ_TARGETS="mcap cdr" runs some; FUZZ_DOC=docs/validation-reliability.md
# writes the figures table there. Fails when any target finds a bug.
FUZZ_BUILD ?= build-fuzz
FUZZ_SECONDS ?= 60
FUZZ_TARGETS ?=
FUZZ_SCRATCH ?= /tmp/rcm-fuzz
FUZZ_DOC ?=
FUZZ_PACKAGES := clang-14 libclang-rt-14-dev

fuzz-deps: deps
	@$(MAKE) --no-print-directory deps DEB_PACKAGES="$(FUZZ_PACKAGES)"

$(FUZZ_BUILD)/CMakeCache.txt:
	cmake -S . -B $(FUZZ_BUILD) -DRCM_FUZZ=ON -DCMAKE_CXX_COMPILER=clang++-14 \
	  -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-O1 -g" -DRCM_BUILD_TESTS=OFF -DRCM_BUILD_BENCH=OFF \
	  -DRCM_WITH_TORCH=OFF -DRCM_WITH_PYTHON=OFF -DRCM_WITH_DDS=OFF -DPython3_EXECUTABLE=$(PYTHON) $(CMAKE_FLAGS)

fuzz: fuzz-deps $(FUZZ_BUILD)/CMakeCache.txt
	cmake --build $(FUZZ_BUILD) -j $(JOBS) --target fuzz_all
	$(PYTHON) fuzz/run_fuzz.py --build $(FUZZ_BUILD) --seconds $(FUZZ_SECONDS) --scratch $(FUZZ_SCRATCH) \
	  $(if $(FUZZ_DOC),--doc $(FUZZ_DOC)) $(FUZZ_TARGETS)

clean:
	rm -rf $(BUILD)
