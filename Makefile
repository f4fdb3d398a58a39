# Each target creates .venv when missing, installs the project, then runs.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp

.PHONY: demo test studies bench lint clean mutate

# Byte-compile the sources (only what changed since the last time): where PYTHONDONTWRITEBYTECODE
# is set, as on this project's CI machine, every `hopkinson` process a test or the demo starts
# would compile each module it imports again (~0.5 s of CPU per `hopkinson identify`).
COMPILE := $(BIN)/python -m compileall -q -j 0 analysis drivers rig reports lab ui hopkinson config tests >/dev/null

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

demo: $(STAMP)
	$(COMPILE)
	$(BIN)/hopkinson demo --out demo-output

# --dist loadscope: a module's tests share one worker, so a module's fixture (the 140-shot
# coverage study, PTB's analysed record) is computed once, not once per worker (stop 38:
# 505 s against 539 s, 812 against 881 s of CPU on 2 cores). The longest modules of the last
# run start first (tests/scope_order.py). --durations=15: the 15 slowest tests, to keep the
# suite short.
# PYTHONDONTWRITEBYTECODE emptied (unset) for the run: pytest keeps each test module with its
# asserts rewritten in __pycache__ only where bytecode may be written; otherwise every worker
# rewrites all ~170 test modules on every run (collecting took 10-13 s of CPU per worker, 5 s
# with the rewritten modules kept: ~18 s of CPU per `make test` on 3 workers). The sources' own
# bytecode is written by $(COMPILE) above either way. (Not in tests/conftest.py: mutation/warm.py
# must keep compiling each mutant from its source.)
test: $(STAMP)
	$(COMPILE)
	PYTHONDONTWRITEBYTECODE= QT_QPA_PLATFORM=offscreen $(BIN)/python -m pytest -q -n 3 --dist loadscope --durations=15

# Statistical studies too long for the suite: the tests marked `study`, wherever they live (a
# 200-shot coverage study, 60 shots in each of four one-effect worlds, PTB's hybrids over noise
# draws, and the suite's former studies: the 50-shot realistic study, the 140-shot clean one and
# the independent linearity campaigns), each with the power its docstring states (docs/testing.md).
# One process (-n 0): the studies spread their shots over the machine's cores themselves, and the
# 200-shot study takes the 50 shots test_coverage_realistic computed before it (tests/realistic_study.py).
# CI runs them after `make test`.
studies: $(STAMP)
	$(COMPILE)
	$(BIN)/python -m pytest -q -m study -n 0 --timeout 1800 --durations=10 tests

bench: $(STAMP)
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(BIN)/python $$b || exit 1; done

# Mutation testing (docs/mutation-testing.md): cosmic-ray on the safe path, FBSD and the response,
# the DCM's figures and the uncertainty's intervals, each with only its own tests; a copy of the
# tree is mutated, never the checkout. `make mutate TARGETS="safe response"` runs some of them.
TARGETS ?= safe response dcm uncertainty
MUTATE_STAMP := $(VENV)/.mutate-stamp

$(MUTATE_STAMP): pyproject.toml $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[test,mutate]'
	touch $(MUTATE_STAMP)

mutate: $(MUTATE_STAMP)
	nice -n 10 mutation/run $(TARGETS)

lint: $(STAMP)
	$(BIN)/ruff check .

clean:
	rm -rf $(VENV) demo-output test-artifacts .pytest_cache
