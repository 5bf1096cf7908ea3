"""Every scene kind conforms: each kind of ``microsim.geometry.SCENES``, from the example config
its generator module declares (``EXAMPLE``, through :func:`microsim.testing.scenes.example`),
passes the same four checks, so that a new kind is held to them with no change here.

- The white furnace: a white Lambertian ``[material]`` (and ``[base]``, where the example has
  one) absorbs nothing, and every path's unit weight is reflected, transmitted through the
  scene's bottom or cut by the order limit: albedo + transmitted + truncated = 1 in every
  realization to float rounding (1e-12: a sum of at most a few thousand weights of 1), none
  absorbed, no roulette.
- Reciprocity: incidences at the centres of three rings of a 100-cell sensor whose cells meet
  azimuths 0 and 90 deg (41.8, 55.7 and 83.1 deg, phi_i 0 and 90: 15 pairs), 16 realizations;
  f(a -> b) = f(b -> a) within the errors: the mean z^2 of the pairs under
  ``microsim.testing.bounds.chi2_bound`` (each z a difference of two Student-t estimates; the
  bound is one-sided, as cells seen through one realization's geometry are correlated and make
  the differences' z smaller, never larger). Its power, in the same test: f cos(theta_o), which
  is not reciprocal, exceeds the bound (its z reach 10 and more: the cosines of the rings differ
  by a factor of 6).
- Thread identity: the table is the same byte for byte on one thread and on two, with
  realizations of two chunks of paths and part of a third (``microsim.testing.threads``).
- Bad input: an unknown key under ``[scene]`` is refused by ``microsim run`` in one line naming
  it, exit 2, nothing written (the command line in this process: ``microsim.cli.main``, what
  ``python -m microsim`` runs once imported; tests/test_cli_run.py checks that process's exit
  status).

Each check was broken on purpose once and failed (docs/developer/testing.md): a white albedo
one ulp below 1 (absorbed > 0: every kind), the balance summed without the transmitted energy
(the spheres' slab, whose light gets through), the power check on f itself (no kind's mean z^2
exceeds the bound: every kind; the traced tables' mean z^2 are 0.1 to 2.4 over seeds 1-5, the
bound 3.5, and f cos(theta_o)'s 40 to 620), the run on two threads with one path more a
realization, or a table with one ulp more in one cell (every kind), and a key of the scene's
own schema in place of the unknown one (exit 0: every kind).
"""

import numpy as np
import pytest

from microsim import config
from microsim.geometry import SCENES
from microsim.tables import dict_to_toml
from microsim.testing import example, trace_table
from microsim.testing.bounds import chi2_bound
from microsim.testing.reciprocity import non_reciprocal_z, reciprocity_z, ring_illumination, ring_incidences
from microsim.testing.refusals import assert_run_refused
from microsim.testing.threads import assert_same_table_for_threads, spanning_chunks

KINDS = list(SCENES)
WHITE = {"kind": "lambert", "albedo": 1.0}
#: the reciprocity sensor and its rings (cell counts 16, 20 and 24: cells centred at 0 and 90 deg)
CELLS, RINGS = 100, (3, 4, 6)
INCIDENCES = ring_incidences(CELLS, RINGS)
REALIZATIONS = 16
#: paths an incidence: about 6 paths a realization reach a cell of the 83 deg ring at albedo 0.4
PATHS = REALIZATIONS * 6000


@pytest.mark.parametrize("kind", KINDS)
def test_a_white_scene_returns_every_path(kind, tmp_path):
    data = example(kind)
    data["material"] = dict(WHITE)
    if "base" in data:
        data["base"] = dict(WHITE)
    try:
        config.validate(data)
    except config.ConfigError as err:
        pytest.skip(f"scene kind {kind!r} takes no white Lambertian material: {err}")
    table = trace_table(data, tmp_path / "white.h5")
    a = table.arrays
    assert np.all(a["energy/absorbed"] == 0.0) and np.all(a["diagnostics/roulette_kills"] == 0)
    assert np.all(np.abs(table.albedo + table.transmitted + table.truncated - 1.0) <= 1e-12)
    assert np.all(np.abs(a["energy/balance"] - 1.0) <= 1e-12) and np.all(a["energy/balance_stderr"] <= 1e-12)


@pytest.mark.parametrize("kind", KINDS)
def test_the_table_is_reciprocal_and_the_check_sees_what_is_not(kind, tmp_path):
    data = example(kind)
    data.update(illumination=ring_illumination(INCIDENCES), sensor={"cells": CELLS})
    data["run"].update(paths=PATHS, realizations=REALIZATIONS)
    table = trace_table(data, tmp_path / "reciprocity.h5")
    assert np.all(table.brdf_stderr > 0)
    z = reciprocity_z(table, INCIDENCES, table.brdf, table.brdf_stderr)
    bound = chi2_bound(len(z), REALIZATIONS)
    assert len(z) == 15 and np.mean(z**2) <= bound, (np.mean(z**2), bound, z.max())
    power = non_reciprocal_z(table, INCIDENCES)
    assert np.mean(power**2) > bound, (np.mean(power**2), bound)


@pytest.mark.parametrize("kind", KINDS)
def test_the_table_is_the_same_on_one_thread_and_on_two(kind, tmp_path):
    data = example(kind)
    data["run"].update(paths=spanning_chunks(2), realizations=2)
    assert_same_table_for_threads(data, tmp_path)


@pytest.mark.parametrize("kind", KINDS)
def test_an_unknown_scene_key_is_refused_in_one_line(kind, tmp_path, capsys):
    data = example(kind)
    data["scene"]["no_such_key"] = 1.0
    assert_run_refused(dict_to_toml(data), "scene.no_such_key", tmp_path, capsys, "unknown key")
