"""Shared helpers of the physics tests: run a config dictionary end to end, read the table back."""

import pytest

from microsim import config, runner, tables


@pytest.fixture
def simulate(tmp_path):
    """``simulate(dict, workers=1) -> Table``: validate, trace, write the HDF5 table, load it."""
    counter = iter(range(1000))

    def run(data: dict, workers: int = 1) -> tables.Table:
        cfg = config.validate(data)
        result = runner.run(cfg, workers=workers)
        path = tmp_path / f"table{next(counter)}.h5"
        tables.write(path, result, cfg)
        return tables.load(path)

    return run

