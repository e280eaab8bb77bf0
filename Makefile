# mipray: the whole set-up and the everyday commands.
#
#   make render   set up, then render examples/$(EXAMPLE).usda to out/ and print the image paths
#   make test     set up, then cargo tests (core, bridge, plugin) and the pytest suites
#
# Both start with scripts/setup.sh, which installs what is missing (Debian
# packages, .venv, Python packages) and builds the extension into .venv.

SHELL := /bin/bash
.DEFAULT_GOAL := help
export PATH := $(HOME)/.cargo/bin:$(PATH)

VENV    ?= .venv
PY      := $(VENV)/bin/python
RECORD  := $(VENV)/bin/mipray-record
EXAMPLE ?= subdiv_showcase
WIDTH   ?= 320
OUT     ?= out
EXAMPLE_FILES := examples/subdiv_showcase.usda examples/forest.usda examples/render_settings.usda examples/textured.usda examples/implicit_prims.usda examples/curves.usda
# Textures of examples/textured.usda: drawn by a script, made into tiled MIP maps by maketx.
TEXTURES := examples/textures/bricks_color.tx examples/textures/bricks_height.tx
# pyo3's build script finds Python through this when cargo checks mipray-py.
ifneq ($(wildcard $(PY)),)
export PYO3_PYTHON ?= $(abspath $(PY))
endif

.PHONY: help setup build examples render test test-rust test-python fmt lint clean figures bench-cache

help: ## List the targets
	@grep -E '^[a-z-]+:.*## ' $(MAKEFILE_LIST) | awk -F':.*## ' '{printf "  make %-12s %s\n", $$1, $$2}'

setup: ## Install what is missing and build the extension into .venv
	@bash scripts/setup.sh

build: setup ## Build the Rust workspace and the extension
	cargo build --workspace --exclude mipray-py

$(EXAMPLE_FILES):
	@[ -f $@ ] || $(PY) examples/make_examples.py

$(TEXTURES): examples/make_textures.py
	@$(PY) examples/make_textures.py >/dev/null

examples: setup $(EXAMPLE_FILES) $(TEXTURES) ## Write the example scenes and textures if missing

render: setup $(EXAMPLE_FILES) $(TEXTURES) ## Render examples/$(EXAMPLE).usda to $(OUT)/$(EXAMPLE).exr and .png
	@mkdir -p $(OUT)
	@$(RECORD) --imageWidth $(WIDTH) --aovs color,depth,normal \
		--stats $(OUT)/$(EXAMPLE).stats.json examples/$(EXAMPLE).usda $(OUT)/$(EXAMPLE).exr
	@if command -v oiiotool >/dev/null 2>&1 && oiiotool $(OUT)/$(EXAMPLE).exr --ch R,G,B \
		--colorconvert linear sRGB -d uint8 -o $(OUT)/$(EXAMPLE).png 2>/dev/null; then \
		echo $(OUT)/$(EXAMPLE).png; \
	else \
		$(RECORD) --imageWidth $(WIDTH) examples/$(EXAMPLE).usda $(OUT)/$(EXAMPLE).png; \
	fi

test: setup $(EXAMPLE_FILES) $(TEXTURES) ## Run every test (both suites run; fails if either fails)
	@status=0; \
	$(MAKE) --no-print-directory test-rust || status=1; \
	$(MAKE) --no-print-directory test-python || status=1; \
	exit $$status

test-rust:
	cargo test --workspace --exclude mipray-py

test-python:
	$(PY) -m pytest tests -q

fmt: ## Format Rust and Python sources
	cargo fmt --all
	@if [ -x $(VENV)/bin/ruff ] || command -v ruff >/dev/null; then \
		$$( [ -x $(VENV)/bin/ruff ] && echo $(VENV)/bin/ruff || echo ruff ) format \
			--config python/pyproject.toml python/mipray tests examples; \
	else echo "ruff not installed (pip install ruff): Python not formatted"; fi

lint: ## cargo fmt --check, clippy -D warnings, ruff, mypy and stubtest (_mipray.pyi) if installed
	cargo fmt --all --check
	cargo clippy --workspace --all-targets -- -D warnings
	@RUFF=$$( [ -x $(VENV)/bin/ruff ] && echo $(VENV)/bin/ruff || command -v ruff || true ); \
	if [ -n "$$RUFF" ]; then \
		$$RUFF check --config python/pyproject.toml python/mipray tests examples && \
		$$RUFF format --check --config python/pyproject.toml python/mipray tests examples; \
	else echo "ruff not installed (pip install ruff): Python not linted"; fi
	@if [ -x $(VENV)/bin/mypy ]; then cd python && ../$(VENV)/bin/mypy; \
	else echo "mypy not installed in $(VENV): Python not type-checked"; fi
	@if [ -x $(VENV)/bin/stubtest ] && $(VENV)/bin/python -c "import mipray._mipray" 2>/dev/null; then \
		cd python && ../$(VENV)/bin/python -m mypy.stubtest mipray._mipray --allowlist ../tests/stubtest_allowlist.txt; \
	else echo "stubtest or the extension missing in $(VENV): _mipray.pyi not checked"; fi

clean: ## Remove build outputs and renders (keeps .venv)
	cargo clean
	rm -rf $(OUT) .pytest_cache tests/.pytest_cache python/.pytest_cache .ruff_cache python/.mypy_cache
	rm -f python/mipray/_mipray*.so
	find python tests examples -name __pycache__ -type d -prune -exec rm -rf {} +

figures: ## Re-make the pictures of docs/ray-differentials.md
	cargo run --release -p hd-mipray --bin mipray-figures -- docs/images

bench-cache: setup ## The paper's §6.3.2 cache tables: docs/cache-benchmark{,-latlong}.{md,json,png}
	cargo run --release -p hd-mipray --bin mipray-bench-cache -- --out docs/cache-benchmark
	cargo run --release -p hd-mipray --bin mipray-bench-cache -- --scene latlong --out docs/cache-benchmark-latlong
	$(VENV)/bin/python -m pip install -q 'matplotlib>=3.7'
	$(VENV)/bin/python scripts/plot_cache_bench.py docs/cache-benchmark.json docs/cache-benchmark.png
	$(VENV)/bin/python scripts/plot_cache_bench.py docs/cache-benchmark-latlong.json docs/cache-benchmark-latlong.png

.PHONY: blender-addon
blender-addon: setup ## The Blender add-on zip: $(OUT)/mipray_blender.zip (Install from Disk in Blender)
	$(PY) scripts/make_blender_addon.py $(OUT)/mipray_blender.zip

.PHONY: accuracy
accuracy: setup ## Accuracy against time (mipray-sweep): docs/accuracy-vs-time.{md,json}, docs/images/accuracy-*.png
	$(VENV)/bin/python -m pip install -q 'matplotlib>=3.7'
	$(PY) examples/accuracy_report.py

.PHONY: mitsuba
mitsuba: setup ## mipray against Mitsuba 3 on the same scenes: docs/mitsuba-comparison.md
	$(PY) -m mipray.reference.compare --out docs/mitsuba-comparison.md

.PHONY: bench-irradiance
bench-irradiance: ## Irradiance/occlusion cache: time and error against its error bound: docs/irradiance-cache.{md,json}
	cargo run --release -p hd-mipray --bin mipray-irradiance-bench -- --out docs/irradiance-cache

# The Embree harness of bench-throughput, built against Debian's libembree-dev (installed here if
# missing, never by scripts/setup.sh: CI does not need it) and OpenImageIO.
EMBREE_HARNESS := $(OUT)/throughput/embree_throughput
THROUGHPUT_ARGS ?=

$(EMBREE_HARNESS): scripts/bench/embree_throughput.cpp
	@dpkg -s libembree-dev >/dev/null 2>&1 || { \
		SUDO=$$( [ "$$(id -u)" -eq 0 ] || echo sudo ); \
		echo "bench-throughput: installing libembree-dev" >&2; \
		$$SUDO apt-get update -qq && \
		DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends libembree-dev; }
	@mkdir -p $(@D)
	g++ -O2 -std=c++17 -Wall -Wextra -o $@ $< -lembree3 $$(pkg-config --cflags --libs OpenImageIO) -pthread

.PHONY: bench-throughput
bench-throughput: $(EMBREE_HARNESS) ## mipray's rays/s by ray type against Embree's: docs/throughput.md
	@MIPRAY_SKIP_BUILD=1 bash scripts/setup.sh
	@# Timings need the release extension (setup.sh builds the dev profile).
	VIRTUAL_ENV=$(abspath $(VENV)) PATH="$(abspath $(VENV))/bin:$$PATH" \
		$(VENV)/bin/maturin develop --release -q -m python/Cargo.toml
	$(PY) -m mipray.tools.throughput --embree-bin $(EMBREE_HARNESS) --work $(OUT)/throughput \
		$(THROUGHPUT_ARGS)

.PHONY: bench-cycles
bench-cycles: ## mipray against Cycles (bpy) end to end on the plain throughput scene: docs/cycles-comparison.md
	@MIPRAY_SKIP_BUILD=1 bash scripts/setup.sh
	VIRTUAL_ENV=$(abspath $(VENV)) PATH="$(abspath $(VENV))/bin:$$PATH" \
		$(VENV)/bin/maturin develop --release -q -m python/Cargo.toml
	@[ -f $(OUT)/throughput/plain.usda ] || $(PY) -c 'from pathlib import Path; \
		from mipray.tools.throughput import prepare_scene; prepare_scene("plain", Path("$(OUT)/throughput"))'
	$(PY) -m mipray.tools.cycles_peer $(OUT)/throughput/plain.usda $(CYCLES_ARGS)

.PHONY: bench-distributed
bench-distributed: setup ## Frames and tiles on Dask LocalClusters of 1 and 2 workers, warm and cold caches, tile size: docs/distributed.md
	$(PY) -m mipray.tools.distributed_bench --out docs/distributed.md $(DISTRIBUTED_ARGS)
