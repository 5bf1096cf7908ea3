"""Hapke's model against the exact radiative transfer it approximates, form by form.

Without porosity (K = 1) and opposition effect, Hapke's model describes the half space of
independent Lambertian-sphere grains, whose exact BRDF ``lambert_sphere`` (method exact) gives
(the three-term Horak-Chandrasekhar solution with the exact single scattering; its albedo at
c = 1 is 1 to 1e-4). Printed, for albedos 0.3, 0.8, 0.95, 1 and theta_i = 0, 30, 60, 80 deg:

* the directional albedo of each form of the multiple scattering (isotropic, IMSA; anisotropic,
  AMSA, with Pbar = 1 + sum A_n^2 b_n as coded and with the sign 1 - sum found in some codes)
  beside the exact one;
* each form's median and largest |rel| against the exact BRDF over 4000 random pairs below 87 deg;
* the albedo the porosity factor gives white isotropic grains at phi = 0.1-0.6;
* the largest relative change of f when P takes mu / K in place of mu (the reading the papers leave
  open) at phi = 0.2, 0.4, 0.6;
* the largest relative error of Hapke's approximate H over w, x in [0, 1].

A few seconds; JSON in benchmarks/out/hapke_forms.json (--json prints it too).
"""

from __future__ import annotations

import argparse

import numpy as np
from report import save_figures

from microsim import models
from microsim.core.frames import direction
from microsim.models.hapke import approximate_h
from microsim.models.hfunctions import ISOTROPIC_MODE, HFunction
from microsim.models.quadrature import directional_albedo
from microsim.testing.models import random_pairs

ALBEDOS = [0.3, 0.8, 0.95, 1.0]
THETA_I = [0.0, 30.0, 60.0, 80.0]
FORMS = {"IMSA": {}, "AMSA": {"multiple_scattering": "anisotropic"}, "AMSA, Pbar = 1 - sum": None}


def form(name, albedo, **extra):
    """The Hapke model of form ``name`` (FORMS)."""
    if FORMS[name] is None:
        model = models.create("hapke", albedo=albedo, multiple_scattering="anisotropic", **extra)
        model.p_bar = 2.0 - model.p_bar  # 1 - sum A_n^2 b_n
        return model
    return models.create("hapke", albedo=albedo, **FORMS[name], **extra)


def against_exact(wi, wo, incidences) -> dict:
    out = {}
    for albedo in ALBEDOS:
        exact = models.create("lambert_sphere", albedo=albedo, method="exact")
        truth = exact(wi, wo)
        row = {"exact albedo": directional_albedo(exact, incidences).round(4).tolist()}
        for name in FORMS:
            model = form(name, albedo)
            rel = np.abs(model(wi, wo) / truth - 1.0)
            row[name] = {"albedo": directional_albedo(model, incidences).round(4).tolist(),
                         "median |rel|": round(float(np.median(rel)), 4), "max |rel|": round(float(rel.max()), 4)}
        out[str(albedo)] = row
    return out


def porosity_energy(incidences) -> dict:
    return {str(phi): directional_albedo(models.create("hapke", albedo=1.0, phase="isotropic", volume_fraction=phi),
                                         incidences).round(4).tolist() for phi in (0.1, 0.2, 0.3, 0.4, 0.5, 0.6)}


def p_argument(wi, wo) -> dict:
    out = {}
    for phi in (0.2, 0.4, 0.6):
        model = models.create("hapke", albedo=0.8, volume_fraction=phi, multiple_scattering="anisotropic")
        as_coded = model(wi, wo)
        coefficients = model.p_coefficients
        model.hemispherical_phase = lambda mu, k=model.k: np.polynomial.legendre.legval(mu / k, coefficients)
        out[str(phi)] = round(float(np.max(np.abs(model(wi, wo) / as_coded - 1.0))), 4)
    return out


def approximate_h_error() -> float:
    x = np.concatenate([np.geomspace(1e-9, 1e-3, 40), np.linspace(0.0, 1.0, 1001)])
    return float(max(np.max(np.abs(approximate_h(x, w) / HFunction(ISOTROPIC_MODE, w)(x) - 1.0))
                     for w in np.linspace(0.0, 1.0, 101)))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", action="store_true", help="print the figures as JSON on the last line")
    args = parser.parse_args()
    wi, wo = random_pairs(4000, 2, top=87.0)
    incidences = direction(np.radians(THETA_I), 0.0)
    figures = {"theta_i_deg": THETA_I, "against exact": against_exact(wi, wo, incidences),
               "white isotropic grains with K(phi): albedo": porosity_energy(incidences),
               "max |change| of f with P(mu / K)": p_argument(wi, wo),
               "approximate H: max |rel|": round(approximate_h_error(), 5)}
    for albedo, row in figures["against exact"].items():
        print(f"c = {albedo}: exact albedo {row['exact albedo']}")
        for name in FORMS:
            r = row[name]
            print(f"  {name:22s} albedo {r['albedo']}  median |rel| {r['median |rel|']:.4f}  max {r['max |rel|']:.4f}")
    for phi, albedo in figures["white isotropic grains with K(phi): albedo"].items():
        print(f"white isotropic grains, phi = {phi}: albedo {albedo}")
    print(f"P(mu / K) in place of P(mu): largest |change| of f {figures['max |change| of f with P(mu / K)']}")
    print(f"Hapke's approximate H: largest |rel| {figures['approximate H: max |rel|']}")
    save_figures(figures, "hapke_forms", args.json)


if __name__ == "__main__":
    main()
