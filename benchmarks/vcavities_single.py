"""The figures behind tests/test_vcavities.py items a and b: V-cavity single scattering against
the microfacet models with the Torrance-Sparrow G, case by case.

The cases and configs are the tests' own (microsim.testing.vcavities, which tests/test_vcavities.py imports): conductor
facets (0.2 + 3.9i), Beckmann and GGX at roughness 0.1, 0.3, 0.7, one anisotropic Beckmann field
at phi_i = 0 and 90 deg, dielectric-reflection facets (an index-1.5 interface over a black body),
Lambertian and interfaced Lambertian facets; and, for contrast, the Smith G at 85 deg. For each
incidence: the cells with signal (table > 3 standard errors), the mean z^2 per cell with its
two-sided bounds (microsim.testing.bounds; the lower one is vacuous below about 40 cells), and the
median |sim / model - 1|. About a minute on one core.
"""

import numpy as np

from microsim import models
from microsim.testing import trace
from microsim.testing import vcavities as cases
from microsim.testing.bounds import chi2_bound, chi2_lower_bound


def report(label, result, model):
    rows = []
    for i in range(result.plan.n_incidences):
        n, z2, rel = cases.order1_agreement(result, model, i)
        bounds = chi2_lower_bound(n, cases.REALIZATIONS), chi2_bound(n, cases.REALIZATIONS)
        rows.append(f"{np.degrees(result.plan.theta_i[i]):.0f}/{np.degrees(result.plan.phi_i[i]):.0f} deg: "
                    f"{n} cells, z^2 {z2:.2f} in [{max(bounds[0], 0):.2f}, {bounds[1]:.2f}], |rel| {rel:.3f}")
    print(f"{label}: " + "; ".join(rows), flush=True)


def main():
    for distribution in ("beckmann", "ggx"):
        for a in (0.1, 0.3, 0.7):
            result = trace(cases.vcavity_config(cases.CONDUCTOR, distribution, (a, a)))
            report(f"conductor {distribution} {a}", result, models.create(
                "microfacet", distribution=distribution, roughness=a, gaf="torrance_sparrow", eta=0.2, k=3.9))
    result = trace(cases.vcavity_config(cases.CONDUCTOR, "beckmann", (0.2, 0.6), theta=[45.0, 45.0, 85.0, 85.0],
                                             phi=[0.0, 90.0, 0.0, 90.0]))
    report("conductor beckmann 0.2 x 0.6", result, models.create(
        "microfacet", distribution="beckmann", roughness_x=0.2, roughness_y=0.6, gaf="torrance_sparrow", eta=0.2, k=3.9))
    for distribution in ("beckmann", "ggx"):
        result = trace(cases.vcavity_config(cases.DIELECTRIC, distribution, (0.3, 0.3)))
        report(f"dielectric {distribution} 0.3", result, models.create(
            "microfacet", distribution=distribution, roughness=0.3, gaf="torrance_sparrow", eta=1.5))
    for material, eta, distribution, roughness in cases.DIFFUSE_FACETS:
        result = trace(cases.vcavity_config(material, distribution, roughness, theta=cases.DIFFUSE_THETA,
                                                 phi=cases.DIFFUSE_PHI, paths=cases.DIFFUSE_PATHS))
        report(f"{material['kind']} {distribution} {roughness}", result, models.create(
            "interfaced_lambert", albedo=0.7, eta=eta, distribution=distribution, roughness_x=roughness[0],
            roughness_y=roughness[1], gaf="torrance_sparrow"))
    result = trace(cases.vcavity_config(cases.CONDUCTOR, "beckmann", (0.7, 0.7), theta=[85.0]))
    report("for contrast, the Smith G: conductor beckmann 0.7", result, models.create(
        "microfacet", distribution="beckmann", roughness=0.7, gaf="smith", eta=0.2, k=3.9))


if __name__ == "__main__":
    main()
