# iblbake: `make demo` sets everything up and bakes the examples; `make test` runs the tests.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.iblbake-installed
PANOS  := examples/panoramas
OUT    := examples/out

.PHONY: demo test check check-locals test-corpus stress install opencl intel-cpu test-intel check-intel meshes assets testmodels readers peers bench docs clean

install: $(STAMP)
# editable_mode=compat: the editable install is a plain path in a .pth file. setuptools' default
# installs an import-hook finder that site imports (pathlib, re...) for 10-25 ms before any line of
# iblbake runs, and a Ctrl-C landing there printed a traceback (exit 1) instead of exiting 130.
$(STAMP): pyproject.toml Makefile
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q -e '.[test]' --config-settings editable_mode=compat
	touch $@

opencl: $(STAMP)
	sh scripts/ensure_opencl.sh $(BIN)/iblbake

# the example meshes and textures, made here (no network)
meshes: $(STAMP)
	test -f examples/meshes/knot.ply || $(BIN)/python examples/make_mesh.py examples/meshes/knot.ply
	test -f examples/meshes/tiles.glb -a -f examples/textures/roughness_stripes.png || $(BIN)/python examples/make_textured.py examples
	test -f examples/corpus/meshes/garden.glb -a -f examples/corpus/meshes/skylight_room.obj || $(BIN)/python examples/make_corpus.py examples/corpus

assets: meshes
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
	$(BIN)/iblbake render examples/scenes/sphere_grid.yaml -o $(OUT)/sphere_grid.png --cache $(OUT)/cache --report
	$(BIN)/iblbake render examples/scenes/sphere_grid.yaml -o $(OUT)/sphere_grid_importance.png --cache $(OUT)/cache \
	    --set effects.specular=importance --set effects.samples=40 -q
	$(BIN)/iblbake render examples/scenes/mesh.yaml -o $(OUT)/mesh.png --cache $(OUT)/cache -q
	@echo "demo: done: frames in $(OUT)/ (sphere_grid.png, sphere_grid_importance.png, mesh.png)"

testmodels:
	sh examples/fetch_testmodels.sh tests/data/assimp

# the real readers of the files iblbake writes (KTX2, glTF: Node and tests/node/package.json; GLSL: glslang)
readers:
	sh scripts/ensure_readers.sh tests/node

# the peer renderer the path tracer is tested against: Mitsuba 3 (PyPI) on Debian's LLVM 19
peers: $(STAMP)
	sh scripts/ensure_peers.sh $(BIN)/python

# the whole suite but the corpus' other scenes (pytest marker `corpus`), on every core up to four
test: opencl assets testmodels readers peers
	$(BIN)/python -m pytest -q -n $(CORES) -m "not corpus" tests
	$(MAKE) --no-print-directory check-locals

# every scene of the corpus tests (each case minutes; docs/benchmarks.md has their figures)
test-corpus: opencl assets testmodels readers peers
	$(BIN)/python -m pytest -q -n $(CORES) -m corpus tests

# the developer loop (at most 3 minutes on a 2-core CPU): no network, synthetic panoramas, no
# readers, browser, Dask or kill loops, nothing over about 5 s (pytest markers: pyproject.toml), on
# every core up to four (pytest-xdist; a worker builds its own kernels, about 0.4 GiB each)
FAST   := -m "not (slow or external or kill)"
CORES  := $(shell n=$$(nproc 2>/dev/null || echo 1); [ $$n -gt 4 ] && n=4; echo $$n)
check: opencl meshes
	$(BIN)/python -m pytest -q -n $(CORES) $(FAST) tests

# the developer loop's tests with every kernel's uninitialised locals poisoned (NaN: tests/poison_locals.py),
# so a kernel that reads a value it never wrote fails every time instead of now and then
check-locals: opencl meshes
	IBLBAKE_POISON_LOCALS=1 $(BIN)/python -m pytest -q -n $(CORES) $(FAST) tests

# Intel's OpenCL CPU runtime (the optional extra iblbake[intel-cpu], Intel's EULA: docs/libraries.md),
# registered by iblbake itself; PoCL stays the default device, IBLBAKE_DEVICE=intel-cpu picks Intel's
INTEL  := $(VENV)/.iblbake-intel-installed
$(INTEL): $(STAMP)
	$(BIN)/python -m pip install -q -e '.[test,intel-cpu]' --config-settings editable_mode=compat
	IBLBAKE_DEVICE=intel-cpu $(BIN)/iblbake devices
	touch $@

intel-cpu: $(INTEL)

# the suites on Intel's runtime: every test as `make test` and `make check` run them, each device the
# tests ask for being Intel's CPU (tests that pick a device themselves: docs/testing.md)
test-intel: $(INTEL) assets testmodels readers peers
	IBLBAKE_DEVICE=intel-cpu $(BIN)/python -m pytest -q tests

check-intel: $(INTEL) meshes
	IBLBAKE_DEVICE=intel-cpu $(BIN)/python -m pytest -q $(FAST) tests

# the stress and fuzz suite at full size (10x the fuzz inputs, 24 kill runs per command, every
# writer of every command onto a full disk, every reader given special files); prints and saves
# the table of case, bound, measured, result
stress: opencl assets testmodels
	IBLBAKE_STRESS=1 IBLBAKE_STRESS_REPORT=docs/stress-table.md $(BIN)/python -m pytest -q -rs \
	    tests/test_stress.py tests/test_stress_render.py tests/test_fuzz.py tests/test_fuzz_api.py tests/test_nothing_lost.py \
	    tests/test_outputs_guarded.py tests/test_full_disk.py tests/test_bounded_reads.py tests/test_trust.py

bench: opencl assets
	$(BIN)/python benchmarks/bench_sh.py
	$(BIN)/python benchmarks/bench_mips.py
	$(BIN)/python benchmarks/bench_render.py
	$(BIN)/python benchmarks/bench_accuracy.py
	$(BIN)/python benchmarks/bench_study.py
	$(BIN)/python benchmarks/bench_scale.py

# the generated files: kernels/layout.h and basis_headers.h from scene/layout.py, docs/scene.md from scene/schema.py
# (tests fail while either is stale)
docs: $(STAMP)
	$(BIN)/python -m iblbake.scene.layout > kernels/layout.h.tmp && mv kernels/layout.h.tmp kernels/layout.h
	$(BIN)/python -m iblbake.scene.layout basis_headers > kernels/basis_headers.h.tmp \
		&& mv kernels/basis_headers.h.tmp kernels/basis_headers.h
	$(BIN)/python -m iblbake.scene.schema > docs/scene.md.tmp && mv docs/scene.md.tmp docs/scene.md

clean:
	rm -rf $(OUT) .pytest_cache
