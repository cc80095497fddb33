"""`make check-locals` (tests/poison_locals.py) must see what it exists to see: a float3 out-parameter
left unwritten on an early return, the shape of kernels/probes.h's old probe_contribution."""

import os

import numpy as np
import pytest

from tests import poison_locals

SOURCE = """
inline float3 part(int off, float3 *value)
{
    if (off) return (float3)(0.0f);          /* *value left unwritten */
    *value = (float3)(1.0f);
    return (float3)(2.0f);
}

__kernel void blend(__global float *out, const int first_off)
{
    float3 value, sum = (float3)(0.0f);
    for (int i = 0; i < 2; ++i) sum += part(i == 0 ? first_off : 0, &value) * value;
    out[get_global_id(0)] = sum.x;
}
"""


@pytest.mark.skipif(not os.path.exists(poison_locals.CLANG), reason="needs Debian's clang-15 (PoCL's compiler)")
def test_an_unwritten_out_parameter_reads_as_nan(tmp_path, monkeypatch):
    from iblbake.device.runtime import Runtime

    monkeypatch.setenv("IBLBAKE_KERNEL_CACHE", str(tmp_path))
    rt = Runtime("pocl")
    prg = poison_locals._PoisonedSource(rt.cl, rt.ctx, SOURCE).build(["-cl-std=CL1.2"])
    kernel = rt.cl.Kernel(prg, "blend")
    out = np.zeros(4, np.float32)
    buf = rt.cl.Buffer(rt.ctx, rt.cl.mem_flags.WRITE_ONLY, out.nbytes)
    got = {}
    for first_off in (0, 1):
        kernel(rt.queue, (4,), None, buf, np.int32(first_off))
        rt.cl.enqueue_copy(rt.queue, out, buf)
        got[first_off] = out.copy()
    assert np.all(got[0] == 4.0)               # every value written: 2 x 1 + 2 x 1
    assert np.all(np.isnan(got[1]))            # the first call's value unwritten: 0 x NaN
