# tofcam: the commands a newcomer needs. `make demo` and `make test` install what is missing,
# configure, build and run.
BUILD       ?= build
ASAN_BUILD  ?= build-asan
TIDY_BUILD  ?= build-tidy
JOBS        ?= $(shell nproc)
CMAKE_FLAGS ?=
# The linker (TOFCAM_LINKER in cmake/TofcamTargetOptions.cmake). auto: lld when installed, which
# scripts/install-deps.sh does, so it is looked up when a recipe runs, after `deps`.
# `make LINKER=` keeps the compiler's default.
LINKER      ?= auto
LINKER_FLAG  = -DTOFCAM_LINKER=$(if $(filter auto,$(LINKER)),$$(command -v ld.lld >/dev/null 2>&1 && echo lld),$(LINKER))
TOFCAM      := $(BUILD)/apps/tofcam/tofcam
MAKEFLAGS   += --no-print-directory

.PHONY: all deps configure build demo test test-sanitize bench format format-check tidy clean \
        fuzz kill-test bench-peers

all: build

deps:
	@scripts/install-deps.sh

configure: deps
	@cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release -DTOFCAM_WERROR=ON \
	  $(LINKER_FLAG) $(CMAKE_FLAGS) >/dev/null

build: configure
	@cmake --build $(BUILD) -j $(JOBS)

demo: build
	$(TOFCAM) demo --out out/demo

test: build
	@ctest --test-dir $(BUILD) --output-on-failure -j $(JOBS)

# Unit tests again under AddressSanitizer + UndefinedBehaviorSanitizer (debug, asserts on), without
# the tests labelled slow (they are not built there either). SANITIZE_DEBUG_INFO: -g1 (line
# tables) is what the sanitizers' reports need for file:line frames; full -g made a
# translation unit take up to 39 % longer to compile (demo_command.cc: 28.4 against 20.4 s), and the CI
# run (.ci/run) must stay under 30 minutes. `make test-sanitize SANITIZE_DEBUG_INFO=-g` for gdb.
SANITIZE_DEBUG_INFO ?= -g1
test-sanitize: deps
	@cmake -S . -B $(ASAN_BUILD) -DCMAKE_BUILD_TYPE=Debug -DTOFCAM_WERROR=ON -DTOFCAM_SANITIZE=ON \
	  -DTOFCAM_BUILD_BENCH=OFF -DTOFCAM_BUILD_SLOW_TESTS=OFF $(LINKER_FLAG) \
	  -DCMAKE_CXX_FLAGS_DEBUG="$(SANITIZE_DEBUG_INFO)" -DCMAKE_C_FLAGS_DEBUG="$(SANITIZE_DEBUG_INFO)" \
	  $(CMAKE_FLAGS) >/dev/null
	@cmake --build $(ASAN_BUILD) -j $(JOBS)
	@ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
	  ctest --test-dir $(ASAN_BUILD) --output-on-failure -j $(JOBS) -LE slow

bench: build
	@for b in $(BUILD)/bench/*_bench; do echo "== $$b"; $$b --benchmark_min_time=0.2; done

FORMAT_FILES = $(shell git ls-files '*.cc' '*.h' 2>/dev/null)
format:
	@clang-format -i $(FORMAT_FILES)

format-check:
	@clang-format --dry-run --Werror $(FORMAT_FILES) && echo "format-check: clean"

# Its own configured tree: clang-tidy cannot read GCC's precompiled headers (TOFCAM_TEST_PCH,
# TOFCAM_PCH), which compile_commands.json names with -include.
tidy: deps
	@cmake -S . -B $(TIDY_BUILD) -DCMAKE_BUILD_TYPE=Release -DTOFCAM_TEST_PCH=OFF -DTOFCAM_PCH=OFF \
	  $(CMAKE_FLAGS) >/dev/null
	@clang-tidy -p $(TIDY_BUILD) --quiet --extra-arg=-Wno-unknown-warning-option $(filter %.cc,$(FORMAT_FILES))

clean:
	rm -rf $(BUILD) $(ASAN_BUILD) $(TIDY_BUILD)

# libFuzzer: every parser for FUZZ_SECONDS each (clang, ASan), seeded with small valid files. A
# finding stops the run with the crashing input saved in $(FUZZ_BUILD)/artifacts/.
FUZZ_BUILD   ?= build-fuzz
FUZZ_SECONDS ?= 30
# OSS-Fuzz's optimisation for fuzzing builds: fast enough to run, quicker to compile than -O2 -g
# (the CI run compiles this tree too and must stay under 30 minutes); line tables for reports.
FUZZ_OPT_FLAGS ?= -O1 -gline-tables-only
# fuzz_ifm_o3d3xx is built but not in the default list: third-party o3d3xx files use HDF5's
# unchecksummed format, and libhdf5 1.10 itself has heap overflows in its attribute parser on
# damaged such files (found by this fuzzer; see docs/importers.md). Run it with
# `make fuzz FUZZERS=fuzz_ifm_o3d3xx`.
FUZZERS      ?= fuzz_recording fuzz_adi fuzz_azure_calibration fuzz_mesa_dat fuzz_ros2_images
fuzz: deps
	@CC=clang CXX=clang++ cmake -S . -B $(FUZZ_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="$(FUZZ_OPT_FLAGS)" -DCMAKE_C_FLAGS_RELWITHDEBINFO="$(FUZZ_OPT_FLAGS)" \
	  -DTOFCAM_BUILD_FUZZ=ON -DTOFCAM_BUILD_TESTS=OFF -DTOFCAM_BUILD_BENCH=OFF \
	  -DTOFCAM_BUILD_APPS=OFF -DTOFCAM_BUILD_SIM=OFF $(LINKER_FLAG) >/dev/null
	@cmake --build $(FUZZ_BUILD) -j $(JOBS) --target tofcam_fuzzers
	@rm -rf $(FUZZ_BUILD)/corpus && mkdir -p $(FUZZ_BUILD)/artifacts
	@ASAN_OPTIONS=detect_leaks=1 $(FUZZ_BUILD)/fuzz/fuzz_seed_writer $(FUZZ_BUILD)/corpus .
	@for f in $(FUZZERS); do \
	  echo "== $$f ($(FUZZ_SECONDS) s)"; mkdir -p $(FUZZ_BUILD)/corpus/$$f; \
	  LSAN_OPTIONS=suppressions=$(CURDIR)/fuzz/lsan.supp ASAN_OPTIONS=allocator_may_return_null=1 \
	  $(FUZZ_BUILD)/fuzz/$$f -max_total_time=$(FUZZ_SECONDS) -rss_limit_mb=2048 -timeout=10 \
	    -max_len=65536 -print_final_stats=1 -artifact_prefix=$(FUZZ_BUILD)/artifacts/$$f- \
	    $(FUZZ_BUILD)/corpus/$$f >$(FUZZ_BUILD)/$$f.log 2>&1; rc=$$?; \
	  grep -E "^(Done|stat::number_of_executed_units|stat::peak_rss_mb)" $(FUZZ_BUILD)/$$f.log; \
	  if [ $$rc -ne 0 ]; then tail -n 60 $(FUZZ_BUILD)/$$f.log; exit 1; fi; \
	done

# Crash safety: kill a real recorder with SIGKILL mid-run and read the file back (also in ctest).
kill-test: build
	@scripts/kill_recorder_test.sh $(TOFCAM) .

# Peer comparison (issue 7, not part of CI): Open3D's and PCL's statistical / radius outlier
# removal beside tofcam's filters on the same simulated frames (exposure: the may-incremental
# controller's settled register), judged against the simulator's ground truth. Installs
# python3-open3d and libpcl-dev if missing, builds tofcam and the PCL peer
# (-DTOFCAM_BUILD_PEERS=ON), exports, runs both peers; table in $(PEERS_DIR).txt.
PEERS_DIR ?= $(BUILD)/bench-peers
bench-peers: build
	@(/usr/bin/python3 -c "import open3d" 2>/dev/null && dpkg -s libpcl-dev >/dev/null 2>&1) || \
	  (apt-get update && apt-get install -y --no-install-recommends python3-open3d libpcl-dev)
	@cmake -S . -B $(BUILD) -DTOFCAM_BUILD_PEERS=ON >/dev/null
	@cmake --build $(BUILD) -j $(JOBS) --target tofcam_cli pcl_outlier_removal
	@mkdir -p $(PEERS_DIR)
	@$(TOFCAM) bench --frames 8 --threads 1 --peers-only --export-peers $(PEERS_DIR)
	@$(BUILD)/bench/peers/pcl_outlier_removal $(PEERS_DIR) > $(PEERS_DIR)/pcl.txt
	@OMP_NUM_THREADS=1 /usr/bin/python3 bench/peers/peer_outlier_removal.py $(PEERS_DIR) \
	  --json $(PEERS_DIR)/peers.json | tee $(PEERS_DIR).txt
	@cmake -S . -B $(BUILD) -DTOFCAM_BUILD_PEERS=OFF >/dev/null  # keep PCL out of later builds

# The paper's experiments against ground truth (issue 5): CSVs and false-colour PNGs in
# out/experiments, plots and the generated docs/results.md (committed).
.PHONY: experiments
experiments: build
	$(TOFCAM) experiment all --out out/experiments --image-prefix results/
	@mkdir -p docs/results
	/usr/bin/python3 scripts/plot_experiments.py out/experiments docs/results
	@cp out/experiments/*.png docs/results/
	@cp out/experiments/results.md docs/results.md
	@echo "docs/results.md and docs/results/*.png regenerated"
