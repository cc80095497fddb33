"""Fuzzing the Python API (issue 60): tests/fuzz_api.py calls every public function and method with
random arguments, of the documented types and of wrong ones, in a child process under a 3 GiB
address-space limit (a small container's). Every call succeeds or raises an iblbake.Error of one
line: a raw exception, a MemoryError (more than the memory it could have), a Python warning or a
child killed is a finding. `make test` runs a fixed draw of 300 calls; `make stress`
(IBLBAKE_STRESS=1) 5,000 new ones each run (the seed is in the failure's message)."""

import json
import random
import resource
import subprocess
import sys
from pathlib import Path

from tests.helpers import STRESS, stress_scale

WORKER = Path(__file__).resolve().with_name("fuzz_api.py")
LIMIT = 3 << 30


def run_fuzz(folder: Path, seed: int, cases: int) -> list:
    """Each case's outcome; a child that dies is the finding of the case it had started."""
    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (LIMIT, LIMIT))

    p = subprocess.run([sys.executable, str(WORKER), str(folder), str(seed), str(cases)], capture_output=True,
                       text=True, timeout=3000, preexec_fn=limit, cwd=folder)     # relative paths land there
    results, started = [], None
    for line in p.stdout.splitlines():
        rec = json.loads(line)
        if "start" in rec:
            started = rec
        else:
            results.append(rec)
    if p.returncode != 0:
        results.append({"case": started and started["start"], "call": started and started["call"], "outcome": "raw",
                        "message": f"the child exited {p.returncode} in {started}: {p.stderr[-1500:]}"})
    elif p.stderr.strip():            # nothing of a call may reach stderr (a warning, a native library's log)
        results.append({"case": None, "call": "-", "outcome": "raw", "message": f"stderr: {p.stderr[-1500:]}"})
    return results


def test_the_api_under_random_arguments(tmp_path, stress):
    cases = stress_scale(300, 5000)
    seed = random.randrange(1 << 30) if STRESS else 60
    results = run_fuzz(tmp_path, seed, cases)
    raw = [r for r in results if r["outcome"] == "raw"]
    stress.count("inputs fuzzed", len(results))
    stress.count("crashes", len(raw))
    calls = {r["call"] for r in results}
    assert len(calls) == 11, calls                       # every public function and class was called
    assert sum(r["outcome"] == "ok" for r in results) > cases / 5, "too few valid calls to fuzz the work itself"
    assert not raw, (f"seed {seed}: {len(raw)} raw outcomes of {len(results)}, first: case {raw[0]['case']} "
                     f"{raw[0]['call']}: {raw[0]['message']}")
    stress.check(f"API fuzz, {cases} calls: raw exceptions", len(raw), 0, "outcomes")
    peak = max(r["peak_rss"] for r in results)
    stress.check(f"API fuzz, {cases} calls: the process's peak resident size", peak / 2 ** 30, LIMIT / 2 ** 30, "GiB")
    slowest = max(results, key=lambda r: r["seconds"])
    stress.check(f"API fuzz: slowest call ({slowest['call']})", slowest["seconds"], 120.0, "seconds")
