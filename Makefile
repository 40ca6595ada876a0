# `make demo` / `make test` create .venv on first use; nothing else needs installing by hand.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.kadv-installed

.PHONY: demo test bench clean

$(STAMP): pyproject.toml
	@if ! dpkg -s libusb-1.0-0 >/dev/null 2>&1; then \
	  if [ "$$(id -u)" = 0 ]; then apt-get update -qq && apt-get install -y -qq libusb-1.0-0; \
	  else echo "Open3D needs libusb. Run:  sudo apt-get install -y libusb-1.0-0   then retry."; exit 1; fi; \
	fi
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet torch==2.13.0 -e ".[test,reference]"
	touch $@

demo: $(STAMP)
	$(BIN)/kadv-attack

test: $(STAMP)
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	cd benchmarks && for b in render penalty gradcheck tiny_accuracy attack_step attack_vs_baselines reference_render; do ../$(BIN)/python $$b.py || exit 1; done

clean:
	rm -rf $(VENV) outputs multirun .pytest_cache
