# kfpga: `make demo` runs the main job, `make test` the test suite; both set up .venv first.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
BUILD  := build

.PHONY: demo test bench lint venv clean cosim-long

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

venv: $(STAMP)

test: $(STAMP)
	$(BIN)/python -m pytest -n auto --dist loadgroup

demo: $(STAMP)
	mkdir -p $(BUILD)
	for v in steady full; do \
	  $(BIN)/kfpga compare --variant $$v --seed 1 --plot $(BUILD)/compare_$$v.png > $(BUILD)/compare_$$v.txt && \
	  $(BIN)/kfpga compare --variant $$v --seed 1 --json > $(BUILD)/compare_$$v.json && \
	  cat $(BUILD)/compare_$$v.txt || exit 1; \
	done
	for v in steady full; do $(BIN)/kfpga generate --variant $$v --out $(BUILD)/$$v || exit 1; done
	for v in steady full; do \
	  $(BIN)/kfpga simulate --variant $$v --samples 2000 --seed 1 --quiet > $(BUILD)/simulate_$$v.txt && \
	  cat $(BUILD)/simulate_$$v.txt || exit 1; \
	done
	@echo "fixed-vs-float reports: $(BUILD)/compare_*.txt, .json, .png; Verilog: $(BUILD)/steady, $(BUILD)/full;"
	@echo "co-simulation: $(BUILD)/simulate_*.txt"

bench: $(STAMP)
	$(BIN)/python bench/bench_model.py
	$(BIN)/python bench/bench_cosim.py

# 20,000 whole-design estimates per variant on both simulators (about 15 min, Icarus the most)
cosim-long: $(STAMP)
	KFPGA_SYSTEM_SAMPLES=20000 $(BIN)/python -m pytest -n auto tests/test_cosim.py -k system_bit_exact

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(BUILD)
