"""What every benchmark does with its figures: one JSON file in benchmarks/out, and with --json
the same object printed as the last line."""

import json
from pathlib import Path

OUT = Path(__file__).resolve().parent / "out"


def save_figures(figures: dict, name: str, print_json: bool) -> Path:
    """Write benchmarks/out/<name>.json; also print it on one line if ``print_json``."""
    OUT.mkdir(exist_ok=True)
    path = OUT / f"{name}.json"
    path.write_text(json.dumps(figures, indent=1))
    if print_json:
        print(json.dumps(figures))
    return path
