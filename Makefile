# Two commands do everything (see README): `make demo` and `make test`.
# Each creates .venv with the project and its test tools when it is missing or stale.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test lint bench clean fuzz sitl

$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,control,dask]'
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/groundstation demo

# The real Crazyflie firmware (GPL-3.0, CrazySim's SITL build) as a program in .sitl/cf2, from
# ../shared/sitl (SITL_SRC=... elsewhere); kept out of the Python package. See docs/sitl.md.
sitl:
	@./tools/build_sitl.sh

test: $(STAMP)
	@$(MAKE) --no-print-directory sitl || echo "make test: no SITL firmware; its tests are skipped"
	$(BIN)/ruff check cfsession cfcommon groundstation sysid tests hw_tests bench
	$(BIN)/python -m pytest -n 2 --dist loadfile

lint: $(STAMP)
	$(BIN)/ruff check .

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test,control,dask,bench]'
	$(BIN)/python -m bench

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache *.egg-info

FUZZ_CASES ?= 2000
# Bigger fuzz campaign (tests/fuzz/harness.py runs the targets of tests/fuzz/targets.py): the
# session reader, the UDP simulator, the importers, model files and flight plans, FUZZ_CASES
# cases each, seed from the date; a case past 10 s is a hang, a process that dies (a crash in
# native code) a failure.
fuzz: $(STAMP)
	$(BIN)/python -m tests.fuzz.harness --cases $(FUZZ_CASES)
