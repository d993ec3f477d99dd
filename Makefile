# tofcam: the commands a newcomer needs. `make demo` and `make test` install what is missing,
# configure, build and run.
BUILD       ?= build
ASAN_BUILD  ?= build-asan
JOBS        ?= $(shell nproc)
CMAKE_FLAGS ?=
TOFCAM      := $(BUILD)/apps/tofcam/tofcam
MAKEFLAGS   += --no-print-directory

.PHONY: all deps configure build demo test test-sanitize bench format format-check tidy clean

all: build

deps:
	@scripts/install-deps.sh

configure: deps
	@cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release -DTOFCAM_WERROR=ON $(CMAKE_FLAGS) >/dev/null

build: configure
	@cmake --build $(BUILD) -j $(JOBS)

demo: build
	$(TOFCAM) info

test: build
	@ctest --test-dir $(BUILD) --output-on-failure -j $(JOBS)

# Unit tests again under AddressSanitizer + UndefinedBehaviorSanitizer (debug, asserts on).
test-sanitize: deps
	@cmake -S . -B $(ASAN_BUILD) -DCMAKE_BUILD_TYPE=Debug -DTOFCAM_WERROR=ON -DTOFCAM_SANITIZE=ON \
	  -DTOFCAM_BUILD_BENCH=OFF $(CMAKE_FLAGS) >/dev/null
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

tidy: configure
	@clang-tidy -p $(BUILD) --quiet --extra-arg=-Wno-unknown-warning-option $(filter %.cc,$(FORMAT_FILES))

clean:
	rm -rf $(BUILD) $(ASAN_BUILD)
