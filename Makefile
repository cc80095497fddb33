# iblbake: `make demo` sets everything up and bakes the examples; `make test` runs the tests.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.iblbake-installed
PANOS  := examples/panoramas
OUT    := examples/out

.PHONY: demo test install opencl assets bench clean

install: $(STAMP)
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $@

opencl: $(STAMP)
	sh scripts/ensure_opencl.sh $(BIN)/iblbake

assets:
	sh examples/fetch_panoramas.sh $(PANOS)

demo: opencl assets
	mkdir -p $(OUT)/sh
	for p in $(PANOS)/*.exr; do \
	    n=$$(basename $$p .exr); \
	    $(BIN)/iblbake sh $$p --bands 3 -o $(OUT)/sh/$$n.json -q || exit 1; \
	    $(BIN)/iblbake mips $$p --cache $(OUT)/cache -q || exit 1; \
	    echo "demo: $$n: SH in $(OUT)/sh/$$n.json, mips in $(OUT)/cache"; \
	done
	$(BIN)/iblbake sh $(PANOS)/studio.exr --glsl -q > $(OUT)/sh/studio.glsl
	$(BIN)/iblbake mips $(PANOS)/city.exr --cache $(OUT)/cache
	@echo "demo: done (the last line shows a second run reusing the cache)"

test: opencl assets
	$(BIN)/python -m pytest -q tests

bench: opencl assets
	$(BIN)/python benchmarks/bench_sh.py
	$(BIN)/python benchmarks/bench_mips.py

clean:
	rm -rf $(OUT) .pytest_cache
