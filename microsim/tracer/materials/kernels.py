"""The three kernels of one interaction, compiled over every registered material kind and chosen
by its code, as pbrt's BxDFs and Mitsuba 3's BSDFs have them, with ``wi`` pointing away from the
surface towards where the light came from (``wi = -d``), ``wo`` away from it, ``n`` the outward
unit shading normal, all unit 3-tuples:

- :func:`scatter` samples the outgoing direction exactly and returns the factor by which the
  path weight is multiplied (0 ends the path: absorbed), and the fraction cut short;
- :func:`evaluate` is f(wi, wo) |n . wo|, of the lobes that are not a Dirac delta (zero for a
  mirror, a conductor, the smooth interface's reflection): what a point estimate at a direction
  (next-event estimation) adds;
- :func:`pdf` is the density per solid angle with which :func:`scatter` draws ``wo`` outside its
  delta lobes (it integrates to 1 less their probability). Where a kind's weight is a fixed
  function of the directions, it is evaluate / pdf; where it is random (the interfaced body's
  bounces), its mean is.

Each is a switch over the kinds (``if code == <kind's code>: return <kind's kernel>(...)``),
generated from the registry once every kind module is imported (:mod:`microsim.tracer.materials`
imports this module last); a code no kind holds raises rather than falls through.
"""

from __future__ import annotations

import numba

from microsim.tracer.materials.base import MATERIALS, SEALED


@numba.njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def scatter(code, prm, states, i, d, n):
    """One interaction: returns (new direction, weight factor, truncated weight fraction).

    ``d`` is the propagation direction of the arriving ray (pointing into the surface), ``n``
    the outward unit shading normal, ``prm`` the material's parameter row. A weight factor of 0
    means the path ends. The kind of code ``code`` samples (its ``sample``).
    """
    return sample_of_kind(code, prm, states, i, d, n)


@numba.njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def evaluate(code, prm, wi, wo, n):
    """f(wi, wo) |n . wo| of the material's lobes that are not a Dirac delta (module doc)."""
    return _continuous_lobes(code, prm, False, wi, wo, n)


@numba.njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def pdf(code, prm, wi, wo, n):
    """Density per solid angle with which :func:`scatter` draws wo outside its delta lobes: the
    sampler draws directions as the white material would send them (the albedo goes into the
    weight), so the pdf is :func:`evaluate` of the kind with albedo 1."""
    return _continuous_lobes(code, prm, True, wi, wo, n)


@numba.njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def _continuous_lobes(code, prm, white, wi, wo, n):
    """f |n . wo| of the lobes that are not a delta (of the white kind, with ``white``): 0 unless
    wi and wo are both above the surface, else the kind's ``lobes``."""
    cos_i = wi[0] * n[0] + wi[1] * n[1] + wi[2] * n[2]
    cos_o = wo[0] * n[0] + wo[1] * n[1] + wo[2] * n[2]
    if cos_i <= 0.0 or cos_o <= 0.0:
        return 0.0
    return lobes_of_kind(code, prm, white, wi, wo, n)


def _switch(method: str, arguments: str):
    """``method`` of every registered kind, chosen by ``code``: a numba function generated from
    the registry (``if code == <kind's code>: return <kind's method>(...)``, the kinds in order
    of registration), which kernels inline, each kind's function inlined in it. A code no kind
    holds raises. Built once every kind is registered (at the end of this module)."""
    namespace, lines = {}, [f"def {method}_of_kind(code, {arguments}):"]
    for j, kind in enumerate(MATERIALS.values()):
        namespace[f"{method}_{j}"] = numba.njit(inline="always", error_model="numpy")(getattr(kind, method))
        lines.append(f"    if code == {kind.code}:\n        return {method}_{j}({arguments})")
    lines.append(f"    raise ValueError('{method}: unknown material kind code')")
    exec("\n".join(lines), namespace)
    return numba.njit(inline="always", error_model="numpy")(namespace[f"{method}_of_kind"])


#: the kernels' switches over every kind (:func:`_switch`); a kind defined later is refused
sample_of_kind = _switch("sample", "prm, states, i, d, n")
lobes_of_kind = _switch("lobes", "prm, white, wi, wo, n")
SEALED[0] = True
