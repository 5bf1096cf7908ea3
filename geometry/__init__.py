"""Generators of random microgeometry, one module per scene kind (CONVENTIONS 5).

A generator module provides ``KIND``; ``Config``, the pydantic model of its ``[scene]`` table;
``check(config)``, cross-section rules (raises ValueError with a one-line message);
``resolve(config) -> dict``, every scene parameter with its defaults filled in (stored in the
table's ``scene/`` attrs); and ``generate(resolved, config, rng) -> microsim.scene.Scene``, one
random realization.
"""

from . import plane, poisson_spheres

SCENES = {module.KIND: module for module in (plane, poisson_spheres)}
