# kfpga: `make demo` runs the main job, `make test` the test suite; both set up .venv first.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
BUILD  := build

.PHONY: demo check test test-long models docs bench lint venv clean formal mutate mutate-source regress

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

venv: $(STAMP)

# the fast tier: lint (ruff and the import contracts) with the unit and model tests, no simulator
# and no synthesis (about 1 minute on 2 cores; tests/conftest.py lists its files)
check: $(STAMP)
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -n auto -m check

test: $(STAMP)
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -n auto --dist loadgroup -m "not models and not long"

# the long tier: the slowest runs (the roll predictor's 12,000-cycle updates on the folded core,
# Icarus on the paper's roll series, a planted rounding on the folded core, an equivalence proof) and
# the half of the bus and missing-sample co-simulations' combinations that make test leaves out
test-long: $(STAMP)
	$(BIN)/python -m pytest -n auto --dist loadgroup -m "long and not models"

# the example models of examples/models, default and proposed formats, both variants: RMSE within
# 1 % of float's on unseen seeds and co-simulation on both simulators (see docs/own-model.md)
models: $(STAMP)
	$(BIN)/python -m pytest -n auto --dist loadgroup -m models tests/test_models.py

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

# the manual (docs/, Sphinx with MyST Markdown) as HTML under build/docs; a warning is an error
docs: $(STAMP)
	$(BIN)/sphinx-build -W --keep-going -q -b html docs $(BUILD)/docs
	@echo "manual: $(BUILD)/docs/index.html"

bench: $(STAMP)
	$(BIN)/python bench/bench_model.py
	$(BIN)/python bench/bench_cosim.py
	$(BIN)/python bench/bench_propose.py

# the formal properties of kfpga/verify/properties.py, proven with SymbiYosys; prints the table (about 15 min on 2 cores)
formal: $(STAMP)
	$(BIN)/python -m kfpga.verify.formal

# mutation testing of every block: Yosys mutants, killed by the benches or the properties, then
# mutants of the Python source of hw/, killed by the tests that run their line (see docs/verification.md)
mutate: $(STAMP)
	$(BIN)/python -m kfpga.verify.mutate; netlist=$$?; \
	$(BIN)/python -m kfpga.verify.srcmutate; source=$$?; \
	exit $$(( netlist || source ))

# the source-level mutants alone (about 3 hours on 2 cores from scratch; an interrupted run resumes,
# a mutant of an unchanged file keeps its verdict: see docs/verification.md)
mutate-source: $(STAMP)
	$(BIN)/python -m kfpga.verify.srcmutate

# long regressions: 10^6 whole-design estimates per variant on Verilator, in one-channel and in
# six-channel mode, and 10^5 per variant on Icarus, each with its own seed (printed); 0 mismatches
# or a non-zero exit (about 30 minutes on 2 cores, see docs/verification.md)
REGRESS_VERILATOR ?= 1000000
REGRESS_ICARUS ?= 100000
regress: $(STAMP)
	for v in steady full; do for c in 1 6; do \
	  $(BIN)/kfpga simulate --variant $$v --channels $$c --simulator verilator --samples $(REGRESS_VERILATOR) || exit 1; \
	done; done
	for v in steady full; do \
	  $(BIN)/kfpga simulate --variant $$v --simulator icarus --samples $(REGRESS_ICARUS) || exit 1; \
	done

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(BUILD)
