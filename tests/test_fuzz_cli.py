"""`microsim run` under fuzzing (reduced size): every drawn config and
command line either writes a valid table or exits 2 with one line, writing nothing; never a
traceback (microsim.testing.fuzzing; the full 500-case run is benchmarks/fuzz_cli.py)."""

import tempfile
from pathlib import Path

from hypothesis import HealthCheck, given, seed, settings

from microsim.testing.fuzzing import cases, check

#: examples in the suite (the benchmark draws 500 and more)
EXAMPLES = 200


@seed(20261130)
@settings(max_examples=EXAMPLES, deadline=None, derandomize=False, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(cases())
def test_every_config_and_command_line_runs_or_is_refused_in_one_line(case):
    with tempfile.TemporaryDirectory() as folder:
        check(Path(folder), *case)
