set -e
test -d /tmp/site/matplotlib || pip install -q --no-deps --target /tmp/site .whl/*.whl
export PYTHONPATH=/tmp/site
mkdir -p /etc/OpenCL/vendors; echo libnvidia-opencl.so.1 > /etc/OpenCL/vendors/nvidia.icd
rm -rf /tmp/site/iblbake /tmp/site/iblbake-* /tmp/site/kernels
pip install -q --no-deps --no-build-isolation --no-index --target /tmp/site . 2>&1 | tail -2
export IBLBAKE_CACHE=/tmp/ibc
python3 benchmarks/bench_render.py --device gpu --only mesh 2>&1 | tail -14
python3 benchmarks/bench_render.py --device gpu --only prefiltered 2>&1 | tail -4
python3 benchmarks/tune_gtao.py --device gpu --side 1280 --ref-rays 1024 2>&1 | tail -14
