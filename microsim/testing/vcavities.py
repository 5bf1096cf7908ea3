"""The V-cavity cases of single scattering, shared by tests/test_vcavities.py and
benchmarks/vcavities_single.py (which prints the figures behind the tests).

Contract: :func:`vcavity_config` is the validated config of a V-cavity case (order 1 alone by
default, fixed seed); :func:`order1_agreement` judges order 1 of a traced Result against a model
averaged over each cell with signal (table > ``SIGNAL`` standard errors): the cells, the mean
z^2 over them and the median relative difference; :func:`assert_order1_matches` requires the
mean z^2 of every incidence within the two-sided bounds of :mod:`microsim.testing.bounds`.
"""

from __future__ import annotations

import numpy as np

from microsim import config
from microsim.analysis.averages import cell_averages
from microsim.testing.bounds import chi2_bound, chi2_lower_bound

CONDUCTOR = {"kind": "conductor", "eta": 0.2, "k": 3.9}
#: dielectric-reflection facets: an interface of index 1.5 over a black body reflects F(i.h) alone
DIELECTRIC = {"kind": "interfaced_lambert", "albedo": 0.0, "eta": 1.5}
THETA_I = [0.0, 45.0, 70.0, 85.0]
CELLS = 400
REALIZATIONS = 32
SIGNAL = 3.0


#: the ``[run]`` of a case, but for the keys a call gives
RUN = {"paths": 2_000_000, "realizations": REALIZATIONS, "seed": 3, "max_order": 1}


def vcavity_config(material, distribution="beckmann", roughness=(0.3, 0.3), theta=THETA_I, phi=None, **keys):
    """The validated config of grooves of ``distribution`` and ``roughness`` (x, y) faceted with
    ``material``, lit from ``theta`` (and ``phi``, default 0) degrees; ``keys``: those of RUN
    (``paths``, ``realizations``, ``seed``, ``max_order``), ``cells`` (default CELLS), and any
    other is a ``[scene]`` key."""
    run = {key: keys.pop(key, value) for key, value in RUN.items()}
    cells = keys.pop("cells", CELLS)
    return config.validate({
        "scene": {"kind": "vcavities", "distribution": distribution, "roughness_x": roughness[0],
                  "roughness_y": roughness[1], **keys},
        "material": material,
        "illumination": {"theta_i_deg": list(theta), "phi_i_deg": list(phi) if phi is not None else [0.0] * len(theta)},
        "sensor": {"cells": cells},
        "run": run,
    })


def order1_agreement(result, model, i):
    """(cells with signal, mean z^2 over them, median |sim / model - 1| over them) of order 1
    against the cell-averaged model, incidence i."""
    sim, stderr = result.brdf[i].mean[0], result.brdf[i].stderr[0]
    modelled, _ = cell_averages(model, result.sensor, result.plan.incidence_direction(i), stderr)
    signal = (stderr > 0) & (sim > SIGNAL * stderr)
    sim, stderr, modelled = sim[signal], stderr[signal], modelled[signal]
    return int(signal.sum()), float(np.mean(((sim - modelled) / stderr) ** 2)), float(np.median(np.abs(sim / modelled - 1)))


def assert_order1_matches(result, model, realizations=REALIZATIONS):
    """Mean z^2 of order 1 against the cell-averaged model within the two-sided bounds, per incidence."""
    for i in range(result.plan.n_incidences):
        n, z2, _ = order1_agreement(result, model, i)
        assert n >= 10
        assert chi2_lower_bound(n, realizations) <= z2 <= chi2_bound(n, realizations), \
            (np.degrees(result.plan.theta_i[i]), n, z2)


#: (facet material, the model's eta, distribution, roughness) of the diffuse facets, their incidences and paths
DIFFUSE_FACETS = [
    ({"kind": "lambert", "albedo": 0.7}, 1.0, "beckmann", (0.5, 0.5)),
    ({"kind": "lambert", "albedo": 0.7}, 1.0, "ggx", (0.3, 0.8)),
    ({"kind": "interfaced_lambert", "albedo": 0.7, "eta": 1.5}, 1.5, "beckmann", (0.5, 0.5)),
]
DIFFUSE_THETA, DIFFUSE_PHI, DIFFUSE_PATHS = [0.0, 60.0, 85.0, 85.0], [0.0, 0.0, 0.0, 90.0], 400_000
