# `make demo` / `make test` install the Debian packages they need (system-packages.txt) and create
# .venv on first use; nothing else needs installing by hand.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.kadv-installed
TEST_STAMP := $(VENV)/.kadv-test-installed
DEMO_PACKAGES := $(shell sed -n 's/^demo://p' system-packages.txt)
TEST_PACKAGES := $(DEMO_PACKAGES) $(shell sed -n 's/^test://p' system-packages.txt)

DOCS_STAMP := $(VENV)/.kadv-docs-installed

.PHONY: demo test test-kernels docs lint bench figures clean demo-packages test-packages

# Installs the missing ones of $(1) with apt-get as root; otherwise prints the one line to run and stops.
# dpkg-query's status, not `dpkg -s`: a removed package whose configuration remains still passes `dpkg -s`.
define require_packages
	@missing=""; for package in $(1); do dpkg-query -W -f='$${Status}' $$package 2>/dev/null | grep -q 'ok installed' || missing="$$missing $$package"; done; \
	if [ -n "$$missing" ]; then \
	  if [ "$$(id -u)" = 0 ]; then \
	    echo "Installing Debian packages:$$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null || exit 1; \
	  else echo "kadv needs Debian packages that are missing. Run:  sudo apt-get install -y$$missing   then retry."; exit 1; fi; \
	fi
endef

demo-packages:
	$(call require_packages,$(DEMO_PACKAGES))

test-packages:
	$(call require_packages,$(TEST_PACKAGES))

# The demo needs the core only, and --no-compile skips pip's byte-compiling of every module of
# torch, transformers, Open3D and the rest (one process imports a fraction of them, compiled on
# first use). The tests add their tools, the reference path tracer and diffusers, and compile everything on
# both cores: they start dozens of Python processes, each of which would otherwise compile its
# imports from source where bytecode is not written (PYTHONDONTWRITEBYTECODE). As in pip's own
# compiling, a file that does not compile is left alone (torch ships one for Python 3.12 only).
$(STAMP): pyproject.toml | demo-packages
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --no-compile torch==2.13.0 -e .
	touch $@

$(TEST_STAMP): $(STAMP)
	$(BIN)/pip install --quiet --no-compile -e ".[test,reference,diffusers]"
	$(BIN)/python -m compileall -q -j 0 $(VENV)/lib >/dev/null || true
	touch $@

demo: demo-packages $(STAMP)
	$(BIN)/kadv-attack

# two workers (pytest-xdist), each test file on one of them, so that a module's shared runs are made
# once; a worker that dies ends the run rather than leaving its file's tests waiting
test: test-packages $(TEST_STAMP)
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --max-worker-restart 0

# the render, attack and report tests with torch's portable kernels (no AVX) and one OpenMP thread:
# the rounding of another CPU, simulated on this one; the references' tolerances must absorb it
test-kernels: test-packages $(TEST_STAMP)
	ATEN_CPU_CAPABILITY=default OMP_NUM_THREADS=1 $(BIN)/python -m pytest -q -n 2 --dist loadfile \
	  --max-worker-restart 0 tests/render tests/attack tests/report

$(DOCS_STAMP): pyproject.toml | $(STAMP)
	$(BIN)/pip install --quiet -e ".[docs]"
	touch $@

# the site (site/index.html) from docs/ and the docstrings; any warning fails the build
docs: $(DOCS_STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --quiet
	$(BIN)/python tools/check_api_reference.py site

lint: $(TEST_STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

bench: demo-packages $(TEST_STAMP)
	cd benchmarks && for b in render reflections bake large_scenes penalty gradcheck warp_reach tiny_accuracy attack_step step_ops search_anytime ranking reference_render view_choice; do ../$(BIN)/python $$b.py || exit 1; done

# the docs' tables of figures made again from the records in benchmarks/results/ (a test fails while
# a page is out of date with them)
figures: $(STAMP)
	$(BIN)/python benchmarks/figures.py

clean:
	rm -rf $(VENV) outputs multirun .pytest_cache site
