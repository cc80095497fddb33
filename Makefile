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

assets: $(STAMP)
	sh examples/fetch_panoramas.sh $(PANOS)
	test -f examples/meshes/knot.ply || $(BIN)/python examples/make_mesh.py examples/meshes/knot.ply

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
	$(BIN)/iblbake render examples/scenes/sphere_grid.yaml -o $(OUT)/sphere_grid.png --cache $(OUT)/cache --report
	$(BIN)/iblbake render examples/scenes/sphere_grid.yaml -o $(OUT)/sphere_grid_importance.png --cache $(OUT)/cache \
	    --set effects.specular=importance --set effects.samples=40 -q
	$(BIN)/iblbake render examples/scenes/mesh.yaml -o $(OUT)/mesh.png --cache $(OUT)/cache -q
	@echo "demo: done: frames in $(OUT)/ (sphere_grid.png, sphere_grid_importance.png, mesh.png)"

test: opencl assets
	$(BIN)/python -m pytest -q tests

bench: opencl assets
	$(BIN)/python benchmarks/bench_sh.py
	$(BIN)/python benchmarks/bench_mips.py
	$(BIN)/python benchmarks/bench_render.py

clean:
	rm -rf $(OUT) .pytest_cache
