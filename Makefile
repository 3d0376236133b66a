# Depict: `make run` (install + start with an example) and `make test` (install + the whole suite).
# Everything is installed here on first use: Debian's libosmesa6 when missing (apt, as root or
# with sudo), uv in .uv/, and the locked dependencies in .venv/ (uv.lock).

PYTHON ?= python3
VENV := .venv
UV := .uv/bin/uv
UV_VERSION := 0.13.8
BIN := $(VENV)/bin
export UV_PROJECT_ENVIRONMENT := $(VENV)
export UV_PYTHON_DOWNLOADS := never
# Bytecode compiled at install, so that no `depict` process compiles a module from source (where
# PYTHONDONTWRITEBYTECODE is set, or the install is read-only, that cost ~1 s per process).
export UV_COMPILE_BYTECODE := 1
export PYOPENGL_PLATFORM := osmesa

.PHONY: install osmesa extras run example test lint typecheck pytest bench gallery corpus quality openapi docs clean

install: osmesa $(VENV)/.installed

osmesa:
	@if ! ldconfig -p | grep -q libOSMesa.so; then \
		echo "installing Debian's libosmesa6 (OSMesa, for headless rendering)"; \
		SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
		$$SUDO apt-get update -qq && $$SUDO apt-get install -y -qq libosmesa6 >/dev/null; \
	fi

# Optional system programs: Blender (the corpus, the add-on and the Blender tests), Chromium (the
# web viewer's browser tests and screenshots), Xvfb (the add-on screenshot). Tests that need them
# skip with a reason when they are absent.
extras:
	SUDO=$$( [ "$$(id -u)" = 0 ] || echo sudo ); \
	$$SUDO apt-get update -qq && $$SUDO apt-get install -y -qq blender chromium xvfb >/dev/null

$(UV):
	$(PYTHON) -m venv .uv
	.uv/bin/python -m pip install -q uv==$(UV_VERSION)

$(VENV)/.installed: pyproject.toml uv.lock Makefile | $(UV)
	$(UV) sync --frozen --python $(PYTHON)
	$(BIN)/python -m compileall -q analysis gbuffer ops service
	$(BIN)/depict warmup
	@touch $@

example: install
	@mkdir -p example
	$(BIN)/depict render examples/spot.obj -o example/gbuffer.exr --width 960 --height 720
	$(BIN)/depict preview example/gbuffer.exr -o example/gbuffer.png
	@echo "example ready: example/gbuffer.exr (preview example/gbuffer.png)"

HOST ?= 127.0.0.1
PORT ?= 8000

run: example
	@echo
	@echo "Depict serves on http://$(HOST):$(PORT) (Ctrl-C stops it). Try, from another shell:"
	@echo "  curl -sf -F file=@example/gbuffer.exr -o example/enhanced.exr http://$(HOST):$(PORT)/v1/enhance"
	@echo "  curl -sf -F file=@example/gbuffer.exr -F 'pipeline={\"steps\": [{\"op\": \"light_alignment\"}]}' \\"
	@echo "       -o example/aligned.png 'http://$(HOST):$(PORT)/v1/enhance?preview=png'"
	@echo "  curl -sf -F file=@example/gbuffer.exr http://$(HOST):$(PORT)/v1/score"
	@echo "  open http://$(HOST):$(PORT)/docs for the API, or run .venv/bin/depict --help"
	@echo
	DEPICT_HOST=$(HOST) DEPICT_PORT=$(PORT) exec $(BIN)/depict serve

lint: install
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

typecheck: install
	$(BIN)/mypy

pytest: install
	$(BIN)/pytest -q

test: lint typecheck pytest

bench: install
	@for b in bench/bench_*.py; do $(BIN)/python -m bench.$$(basename $$b .py) || exit 1; done

gallery: install
	$(BIN)/python -m bench.gallery_corpus
	$(BIN)/python -m bench.gallery
	$(BIN)/python -m bench.gallery_masks

# Blender Cycles renders of the corpus/ scenes (every size and sample count; hours on 2 cores)
# and Depict's renders of the optional meshes, into corpus/frames/
corpus: install
	$(BIN)/python -m bench.corpus render
	$(BIN)/python -m bench.corpus meshes

openapi: install
	$(BIN)/python -m service.openapi

docs: install
	$(BIN)/python -m service.docs

clean:
	rm -rf $(VENV) .uv example gallery .pytest_cache .mypy_cache .ruff_cache
