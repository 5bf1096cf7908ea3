"""How far the tabulated BRDF (microsim.models.tabulated) lies from the BRDF it tabulates: the
interpolation alone, without noise.

An analytic model's exact cell averages at the incidences of a full-BRDF run
(``illumination.incidences = N``, microsim.config.full_brdf) are tabulated as a table's would be; the
tabulated BRDF's own cell averages (a fixed 16 x 16 Gauss rule a cell) are then compared with the
model's at the table's incidences and halfway between them (in theta_i), where it interpolates.
Reported per model, sensor and N: the relative error of the cells, RMS weighted by each cell's
share of the albedo (f_C P_C), and its largest, over the cells above 1 % of the incidence's
largest value; and the albedo's relative error, the largest over the incidences. Lab notes: docs/guide/tabulated.md.

    python benchmarks/tabulated_accuracy.py [--cells 1600 3240] [--incidences 7 13 25]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from microsim import models
from microsim.analysis.averages import CellRule, cell_averages
from microsim.config import full_brdf
from microsim.core.frames import direction
from microsim.models.tabulated import CellValues, TabulatedBRDF
from microsim.tracer.sensor import Sensor

MODELS = {
    "lambert_sphere c=0.8": ("lambert_sphere", {"albedo": 0.8}),
    "oren_nayar sigma=0.5": ("oren_nayar", {"albedo": 0.8, "roughness": 0.5}),
    "microfacet alpha=0.5": ("microfacet", {"roughness": 0.5, "eta": 1.5}),
    "microfacet alpha=0.2": ("microfacet", {"roughness": 0.2, "eta": 1.5}),
}


def exact_averages(model, sensor, theta):
    zeros = np.zeros(sensor.n_cells)
    return np.array([cell_averages(model, sensor, direction(t, 0.0), zeros)[0] for t in theta])


def errors(reference, tabulated, projected):
    """(weighted relative RMS and largest relative error over the cells above 1 % of their
    incidence's largest value, the albedo's largest relative error)."""
    lit = reference > 0.01 * reference.max(axis=1, keepdims=True)
    rel = np.divide(tabulated - reference, reference, out=np.zeros_like(reference), where=lit)
    share = np.where(lit, reference * projected, 0.0)
    rms = np.sqrt(np.sum(share * rel**2) / np.sum(share))
    albedo = (tabulated @ projected - reference @ projected) / (reference @ projected)
    return rms, np.abs(rel[lit]).max(), np.abs(albedo).max()


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[1600, 3240])
    parser.add_argument("--incidences", type=int, nargs="+", default=[7, 13, 25])
    args = parser.parse_args()
    print("| model | cells | N | at the incidences: RMS / max / albedo | halfway: RMS / max / albedo |")
    print("|---|---|---|---|---|")
    for label, (name, params) in MODELS.items():
        model = models.create(name, **params)
        for cells in args.cells:
            sensor = Sensor.build(cells)
            projected = sensor.projected_solid_angle()
            for n in args.incidences:
                if n > sensor.n_rings:
                    continue
                nodes = np.radians(full_brdf.polar_angles_deg(n, cells))
                halfway = 0.5 * (nodes[1:] + nodes[:-1])
                start = time.perf_counter()
                table = CellValues(sensor, nodes, np.zeros(n), exact_averages(model, sensor, nodes))
                try:
                    tabulated = TabulatedBRDF(table)
                except ValueError as err:  # too few incidences for this sensor's rings: not a full BRDF
                    print(f"| {label} | {sensor.n_cells} | {n} | refused: {str(err).split(': ', 1)[1]} | |")
                    continue
                row = []
                for theta, reference in ((nodes, table.brdf), (halfway, exact_averages(model, sensor, halfway))):
                    averaged = np.array([CellRule(sensor, direction(t, 0.0), np.full(sensor.n_cells, 16))
                                         .averages(tabulated) for t in theta])
                    row.append(" / ".join(f"{100 * e:.2f} %" for e in errors(reference, averaged, projected)))
                print(f"| {label} | {sensor.n_cells} | {n} | {row[0]} | {row[1]} |  ({time.perf_counter() - start:.0f} s)",
                      flush=True)


if __name__ == "__main__":
    main()
