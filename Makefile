# The two commands a fresh machine needs: `make demo` and `make test`.
# Both create .venv, install the package with its all, test and docs extras,
# and install Debian's graphviz for the block diagrams when they can (root
# with apt-get); otherwise the block diagram is skipped with a message.
# `make test` = lint, `make docs` (API reference, warnings are errors), pytest with
# the notebooks and the wheel check (the wheel installed outside the checkout).
PYTHON ?= python3
# The install and Debian's graphviz (each waiting on the network) run side by side
# (set at the top level only: a sub-make inherits it).
ifeq ($(MAKELEVEL),0)
MAKEFLAGS += -j2
endif
# uv trusts the system's certificate store, as pip does (Debian's ca-certificates and any
# CA an administrator added there): with its own bundled roots uv fails where PyPI is
# reached through a proxy whose CA only the system knows (measured: a non-root user's
# make test stopped at the install, "invalid peer certificate: UnknownIssuer"). Exported:
# the wheel check (tools/check_wheel.py) installs through uv too.
export UV_SYSTEM_CERTS := 1
# Python writes its bytecode beside the sources (in __pycache__, ignored by git, where
# numba's cache already lives), whatever the calling shell says: with
# PYTHONDONTWRITEBYTECODE set every one of make test's some forty Python processes
# (pytest's workers, the notebooks' kernels, the CLI's subprocesses, the wheel check's)
# compiled the package's and its dependencies' sources again (the CLI alone about 3 s of
# CPU a start, measured here).
unexport PYTHONDONTWRITEBYTECODE
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test test-slow lint format bench clean venv system-deps docs wheel-check

# The install goes through uv (itself from PyPI, by the venv's pip): the same packages
# from the same index as pip, in about a third of the time (17 s with an empty cache
# against 48 s for pip with a warm one, measured here), which `make test`'s budget needs.
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet "uv>=0.13"
	$(BIN)/python -m uv pip install --quiet --python $(BIN)/python -e ".[all,test,docs]"
	touch $(STAMP)

venv: $(STAMP)

system-deps:
	@if command -v dot >/dev/null 2>&1; then :; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
	  echo "Installing Debian's graphviz (block diagrams)..."; \
	  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq graphviz >/dev/null) \
	    || echo "note: could not install graphviz; block diagrams will be skipped"; \
	else \
	  echo "note: Graphviz's 'dot' is missing and needs root + apt-get to install; block diagrams will be skipped"; \
	fi

demo: $(STAMP) system-deps
	$(BIN)/geovs-drake demo --out results

# The notebooks run once, in `make docs` (two kernels side by side, GEOVS_FAST=1: the
# same code paths, fewer samples), which renders them with their outputs; a failing
# cell fails the build, and tests/test_docs.py (-m built_docs) checks each page's
# figures. -n auto runs one pytest process per core (pytest-xdist); the slow studies
# are `make test-slow`.
test: $(STAMP) system-deps
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	@# First the numba kernels compile once into their on-disk cache (geovs_drake.batch.warm):
	@# on a fresh checkout pytest's workers and the notebooks' kernels, started side by
	@# side, would each compile them (about 20 s of CPU apiece), while the wheel check
	@# (its own installs: it reads no cache of ours) runs beside it from the start. The
	@# free rig's half first, beside the arm's (about 26 s and 44 s of CPU); then the docs
	@# (with the notebooks, which need only the free half) and pytest start beside the
	@# arm's half (tests/conftest.py runs the arm kernels' tests last, once it is done);
	@# last the tests that read the built HTML.
	@$(MAKE) --no-print-directory wheel-check > .wheel-check.log 2>&1 & wheel=$$!; \
	$(BIN)/python -m geovs_drake.batch.warm arm & arm=$$!; \
	$(BIN)/python -m geovs_drake.batch.warm free; warmed=$$?; \
	$(MAKE) --no-print-directory docs > .docs-build.log 2>&1 & docs=$$!; \
	GEOVS_FAST=1 $(BIN)/python -m pytest -q -n auto -m "not slow and not built_docs and not wheel"; \
	tests=$$?; wait $$arm; armed=$$?; wait $$docs; built=$$?; wait $$wheel; wheeled=$$?; \
	cat .wheel-check.log .docs-build.log; rm -f .wheel-check.log .docs-build.log; \
	test $$warmed -eq 0 && test $$armed -eq 0 && test $$tests -eq 0 && test $$built -eq 0 \
	  && test $$wheeled -eq 0
	@# The built pages' tests live in one file: collecting only it spares the whole
	@# suite's collection (6 s, on one core, at the end).
	$(BIN)/python -m pytest -q -p no:cacheprovider -m built_docs tests/test_docs.py

# The long studies and the real-cluster sweeps (pytest -m slow), outside `make test`'s budget.
test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow

# The manual, the notebooks (executed here) and the API reference into docs/_build/html; a warning (a broken docstring, an
# undocumented public object, a module on no page) fails the build.
docs: $(STAMP)
	$(BIN)/python -m sphinx -E -W --keep-going -q -b html docs docs/_build/html
	@echo "API reference: docs/_build/html/index.html"

# Build the sdist and wheel, install the wheel in fresh venvs outside the checkout
# (no extras, then [all]) and run the CLI there (tools/check_wheel.py).
wheel-check: $(STAMP)
	$(BIN)/python -m pytest -q -rA -p no:cacheprovider -m wheel tests/test_wheel.py

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

format: $(STAMP)
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

# Each benchmark rewrites its benchmarks/results/NAME.json, which the docs render.
bench: $(STAMP)
	$(BIN)/python benchmarks/bench_camera_map.py
	$(BIN)/python benchmarks/bench_closed_loop.py
	$(BIN)/python benchmarks/bench_batch.py
	$(BIN)/python benchmarks/bench_rendered.py
	$(BIN)/python benchmarks/bench_arm.py
	$(BIN)/python benchmarks/bench_moving_target.py
	$(BIN)/python benchmarks/bench_quadrotor.py
	$(BIN)/python benchmarks/bench_linearize.py
	$(BIN)/python benchmarks/bench_sweep.py overhead
	$(BIN)/python benchmarks/time_to_converge.py

clean:
	rm -rf $(VENV) results .pytest_cache docs/_build build dist
