"""Bit identity: small tables traced now equal the golden ones checked in, on every host.

``tests/data/golden_<name>.npz`` holds every dataset of the table that ``GOLDEN[name]`` gave
when it was last regenerated, and the platform it was made on: machine, the widest SIMD
instruction set (Embree picks its kernels by it) and the CPU vendor (Embree refines the
hardware's approximate reciprocals, whose bits the instruction sets leave to each vendor). Two checks, one of them on every host:

- **Same platform: byte for byte.** Any change that moves a single bit of a table fails, with
  the size of the largest move.
- **Another platform: within what a change of CPU can do** (:func:`host_moves`). Embree returns
  float32 hit distances and normals, and its SSE, AVX, AVX2 and AVX-512 kernels round them
  differently; numpy's SIMD sines and arccosines round the sensor's layout differently. Measured
  by tracing the goldens on this AVX-512 host with Embree, numba and numpy restricted to AVX2,
  AVX and SSE4.2 (``python benchmarks/cross_isa.py measure``, on 2026-12-01), as a fraction of
  the largest value of each dataset (or, for a ``_stderr``, of its estimate):

  | golden | largest move (AVX2 / AVX / SSE4.2) | why | bound (``HOST_TOLERANCE``) |
  |---|---|---|---|
  | vcavities, vcavities_lambert, medium | 0 / 0 / 0: identical | no Embree; numba's float64 arithmetic is IEEE without fast-math | 0 |
  | conductor | 8.9e-8 / 1.7e-7 / 1.7e-7 | float32 hits move the Fresnel weights by float32 rounding (2^-23 = 1.2e-7); no path changes course | 1e-6 |
  | exact | 3.3e-3 / 4.4e-3 / 4.4e-3 | a last-bit change of a hit is amplified bounce after bounce on Lambertian spheres: 0.1-0.4 % of the ~48 000 segments are traced otherwise | 2e-2 |
  | spheres | 4.1e-3 / 2.8e-3 / 2.8e-3 | the same | 2e-2 |
  | every ``sensor/``, ``incidence/`` dataset | 2 ulps | numpy's SIMD transcendental functions | 8 ulps |

  On an AMD EPYC with AVX-512 (Zen 4, 2026-12-02) every dataset of the goldens made on the Intel
  Xeon came out identical (``measure --isa native``: moves 0), and emulated AVX2 moved them as on
  the Xeon: spheres 2.2e-3, conductor 1.2e-7, exact 3.3e-3, layout 2 ulps.

  Integer datasets are exact but for the diagnostics (event counts) of the goldens whose paths
  diverge: counts over the diverged paths, which moved by at most 0.65 square roots of the
  largest count (2 of 25 inside hits of an incidence, 7 of a few hundred roulette kills, 101 of ~24 000
  segments): bound 5 square roots.

So a change of one ulp in the albedo of the facets' or the medium's material, or one path
more, fails on every host: byte for byte on the golden's own platform, and on any other through
the goldens traced without Embree, which must stay identical (a base plane's albedo or a
conductor's eta is seen there within the Embree goldens' bounds only;
``test_the_host_check_sees_one_ulp_of_albedo_and_one_path_more``
shows it on every run). The Embree goldens, on another platform, see any change that draws the
paths anew: with the seed one more, 19 datasets of ``exact`` and 21 of ``spheres`` move beyond
the bound, the largest by 56 % and 87 % of the dataset's largest value.

``exact`` runs native spheres on the direct backend; ``spheres`` and ``conductor`` tessellated
spheres on the embreex backend (their tables are those of c8660dd);
``vcavities`` and ``vcavities_lambert`` the analytic V-cavity tracer; ``medium`` the
radiative-transfer half space. Between them they reach every tracer event: Lambertian,
interfaced-Lambertian and conductor interactions, point scattering, Russian roulette,
pass-through of overlapping spheres, side wraps, a base plane, transmission through the slab and
truncation by ``max_order``. A change meant to move results (new physics, another sampling
order) regenerates them on its host, and its commit message says why:

    python tests/test_golden.py --regenerate [NAME ...]
"""

from __future__ import annotations

import sys

import numpy as np
import pytest

from microsim.testing.golden import GOLDEN, byte_moves, host_moves, load_golden, platform_key, regenerate, trace


@pytest.mark.parametrize("name", sorted(GOLDEN))
def test_table_equals_the_golden_one(name, tmp_path):
    golden, made_on = load_golden(name)
    now = trace(name, tmp_path)
    assert now.keys() == golden.keys()
    assert [key for key in golden if now[key].shape != golden[key].shape or now[key].dtype != golden[key].dtype] == []
    if made_on == platform_key():
        moved = byte_moves(now, golden)
        assert not moved, "moved: " + ", ".join(moved)
        assert not host_moves(name, now, golden)  # the other platforms' check passes an unmoved table
    else:
        moved = host_moves(name, now, golden)
        assert not moved, f"golden made on {made_on}, this is {platform_key()}; moved beyond what a change " \
                          f"of CPU does: " + ", ".join(moved)


@pytest.mark.parametrize("name", ["vcavities", "vcavities_lambert", "medium"])
@pytest.mark.parametrize("change", ["albedo", "paths"])
def test_the_host_check_sees_one_ulp_of_albedo_and_one_path_more(name, change, tmp_path):
    """The host check sees one ulp more of albedo, and one path more, even against the bounds of
    another platform (the byte check sees them a fortiori)."""
    golden, _ = load_golden(name)
    albedo, paths = GOLDEN[name]["material"]["albedo"], GOLDEN[name]["run"]["paths"]
    changes = {"material": {"albedo": float(np.nextafter(albedo, 1.0))}} if change == "albedo" else \
        {"run": {"paths": paths + 1}}
    assert host_moves(name, trace(name, tmp_path, **changes), golden)


def test_the_golden_tables_reach_every_tracer_event():
    spheres, conductor, exact, medium = (load_golden(name)[0] for name in ("spheres", "conductor", "exact", "medium"))
    assert np.all(spheres["diagnostics/roulette_kills"] > 0) and np.all(spheres["diagnostics/inside_hits"] > 0)
    assert np.all(exact["diagnostics/roulette_kills"] > 0) and np.all(medium["diagnostics/roulette_kills"] > 0)
    assert np.all(conductor["energy/transmitted"] > 0) and np.all(conductor["energy/truncated"] > 0)
    assert np.all(spheres["albedo_order"][:, 3] > 0)  # paths reach order 4+


if __name__ == "__main__":
    if sys.argv[1:2] != ["--regenerate"] or not set(sys.argv[2:]) <= set(GOLDEN):
        sys.exit(f"usage: python tests/test_golden.py --regenerate [NAME ...] (names: {', '.join(GOLDEN)})")
    regenerate(sys.argv[2:] or list(GOLDEN))
