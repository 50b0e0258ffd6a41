# Two commands: `make run` (set up + dvc repro) and `make test` (set up + the whole test suite).
# Set-up is idempotent: system libraries, a pinned uv in .tools/, and .venv/ from uv.lock, its bytecode
# compiled at install: every DVC stage is a fresh Python process, and where PYTHONDONTWRITEBYTECODE is set
# (as on this project's machines) each would otherwise compile numpy, pandas and trimesh from source.
SHELL := /bin/bash
PYTHON ?= python3.11
UV_VERSION := 0.13.9
UV := .tools/bin/uv
VENV := .venv
export UV_PYTHON_DOWNLOADS := never
export UV_PROJECT_ENVIRONMENT := $(abspath $(VENV))
export PATH := $(abspath $(VENV))/bin:$(PATH)

.PHONY: setup run test lint bench sysdeps clean

setup: sysdeps $(VENV)/.synced

# open3d links libusb-1.0 at import time
sysdeps:
	@if ! ldconfig -p | grep -q 'libusb-1.0.so.0'; then \
		echo "installing libusb-1.0-0 (needed by open3d)"; \
		if [ "$$(id -u)" = 0 ]; then SUDO=; else SUDO=sudo; fi; \
		$$SUDO apt-get update -qq && $$SUDO apt-get install -y -qq libusb-1.0-0 >/dev/null; \
	fi

$(UV):
	$(PYTHON) -m venv .tools
	.tools/bin/pip install -q uv==$(UV_VERSION)

$(VENV)/.synced: $(UV) pyproject.toml uv.lock
	$(UV) sync --frozen --compile-bytecode --python $(PYTHON)
	touch $@

run: setup
	python -m pipeline.repro  # dvc repro, the objects in parallel lanes (pipeline/repro.py)
	@echo "report: $(CURDIR)/report/report.md (figures in report/figures/, every trial in report/trials.parquet)"
	@echo "        dvc metrics show | dvc plots show (writes dvc_plots/index.html) | artefacts in data/<object>/<scale>/"

test: setup
	python -m pytest -q -n 2 --dist loadfile

lint: setup
	ruff check pipeline stages tests
	ruff format --check pipeline stages tests

bench: setup
	python -m pipeline bench

clean:
	rm -rf .tools $(VENV)
