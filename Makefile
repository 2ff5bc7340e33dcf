# colossus: every target sets up what it needs first, so `make demo` or `make test` works on a
# fresh machine.  A CPython >= 3.12 is found by tools/find-python (pyenv versions included).
VENV    := .venv
PY      := $(VENV)/bin/python
STAMP   := $(VENV)/.installed
OUT     := out

.PHONY: setup demo test bench fuzz samples clean

setup: $(STAMP)

# The old distribution name ("colossus") is uninstalled, and numba's on-disk caches are dropped:
# they are keyed by file, not by module name, so caches made before the one-package move name
# modules (runtime.kernels...) that no longer exist.  Then the kernels of a game's first frame are
# compiled into the cache (bench.runtime.precompile_first_frame): a first frame after setup loads
# them (~1 s of CPU) instead of compiling them (~10 s).
$(STAMP): pyproject.toml
	@set -e; py=$$(tools/find-python 12); echo "using $$py ($$($$py --version))"; \
	  [ -x $(PY) ] || $$py -m venv $(VENV); \
	  $(PY) -m pip install -q --upgrade pip; \
	  $(PY) -m pip uninstall -q -y colossus 2>/dev/null || true; \
	  find runtime pipeline validators -name '*.nb[ic]' -delete; \
	  $(PY) -m pip install -q -e '.[test,bench,dask]'
	@echo "compiling the kernels of a game's first frame (once per install; issue 22 item 4)"
	$(PY) -m colossus.bench.runtime first-frame
	@touch $(STAMP)

demo: setup
	@mkdir -p $(OUT)
	$(VENV)/bin/colossus import samples/creature.glb -o $(OUT)/creature.usda
	$(VENV)/bin/colossus validate $(OUT)/creature.usda
	$(VENV)/bin/colossus render $(OUT)/creature.usda -o $(OUT)/creature.png --clip walk --time 12
	$(VENV)/bin/colossus play $(OUT)/creature.usda --clip walk -o $(OUT)/play.gif

test: setup
	$(PY) -m pytest -q

bench: setup
	$(VENV)/bin/colossus bench

# A long fuzz campaign over every seed format (samples/ and ../shared/corpus/; seeds up to
# MAX_SEED bytes, 0 for all of them); every bad case is saved under $(FUZZ_OUT)/ with its recipe
# (python -m tests.fuzz --replay $(FUZZ_OUT)).
N        ?= 10000
FUZZ_OUT ?= fuzz-cases
MAX_SEED ?= 1e6
fuzz: setup
	$(PY) -m tests.fuzz -n $(N) --max-seed-bytes $(MAX_SEED) --out $(FUZZ_OUT)

# Regenerate the Blender samples with bpy (CPython 3.11 only, in its own venv).
samples:
	@set -e; py=$$(tools/find-python 11 11); \
	  [ -x .venv-bpy/bin/python ] || $$py -m venv .venv-bpy; \
	  .venv-bpy/bin/python -c "import bpy" 2>/dev/null || .venv-bpy/bin/pip install -q 'bpy==5.0.1'; \
	  .venv-bpy/bin/python samples/make_samples.py

clean:
	rm -rf $(OUT) .pytest_cache fuzz-cases
