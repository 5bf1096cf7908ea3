"""The layout of a table, declared once: every attribute and dataset with its axes, unit and
meaning (conventions §6).

The core datasets (incidences, sensor, energy, paths, diagnostics) are declared here, and each
estimator declares its own (``Estimator.DATASETS``, :mod:`microsim.tracer.estimators`): the loader's
shape checks and the reference page of the documentation derive from the two together
(:data:`microsim.tables.DATASETS`). A leaf module: it imports only the tally's names. ``FORMAT_VERSION`` is
written into every table; its major number changes when a dataset changes meaning or shape, its
minor number when datasets or attributes are added. A dataset's ``since`` is the first version
whose tables hold it wherever its ``when`` holds: a table of an earlier version may lack it
(:func:`may_lack`), and a reader keys what it does without the dataset on that, not on its
absence alone (a table of a later version that lacks it is damaged).
"""

from __future__ import annotations

from dataclasses import dataclass

from microsim.core.tally import COUNT_NAMES, ENERGY_NAMES

#: the version of the layout, written as the ``format_version`` attribute of every table; a
#: table of another major version is refused by the loader (a table without one is 1.0)
FORMAT_VERSION = "1.1"


@dataclass(frozen=True)
class Dataset:
    """One dataset: its HDF5 path, the names of its axes (None where its shape is free), its
    unit ("" for a number), what it holds, and when a table has it (``when``: "always", or the
    condition; ``required``: the loader refuses a table without it)."""

    name: str
    axes: tuple[str, ...] | None
    unit: str
    doc: str
    when: str = "always"
    required: bool = False
    since: str = "1.0"


def version_numbers(version: str) -> tuple[int, ...]:
    """A format version as numbers: "1.1" -> (1, 1)."""
    return tuple(int(part) for part in str(version).split("."))


def may_lack(table_version: str, dataset: Dataset) -> bool:
    """Whether a table of ``table_version`` may lack ``dataset`` where its ``when`` holds: it was
    written before the dataset's ``since``."""
    return version_numbers(table_version) < version_numbers(dataset.since)


@dataclass(frozen=True)
class Attribute:
    """One attribute: of the file's root group unless ``group`` says where."""

    name: str
    doc: str
    when: str = "always"
    group: str = "/"


#: the lengths the axes name
AXIS_LENGTHS = {
    "incidences": "n_i, the incidences of [illumination]",
    "cells": "n_c, the sensor's cells (about sensor.cells)",
    "orders": "4: scattering orders 1, 2, 3 and 4 or more",
    "retro_rings": "n_r = sensor.retro_rings",
    "points": "n_d, the points of sensor.directions_deg then sensor.retro_points_deg",
    "other_points": "n_d again: the second axis of a covariance between the points",
    "xyz": "3: the components of a unit vector",
    "rings": "the sensor's rings, from the pole",
    "bounds": "2: a cell's lower and upper bound",
    "realizations": "the realizations (the attribute realizations)",
    "masking_directions": "the directions of the scene's attribute statistics_directions_deg",
    "pair_bins": "the bins of g(r) between the scene's attribute pair_edges",
    "chord_bins": "the bins between the scene's attribute chord_edges, and one beyond the last",
}

#: axes whose length is another's: a covariance's second axis (the loader checks it)
SAME_LENGTH = {"other_points": "points"}

#: what the dimension scale of each axis holds (its netCDF coordinate variable, format 1.1):
#: the index along it, but for the orders
SCALES = {axis: "0, 1, ...: the index along it" for axis in AXIS_LENGTHS} | {
    "orders": "1, 2, 3, 4: the scattering order (4: four or more)", "xyz": "0, 1, 2: x, y, z",
    "bounds": "0, 1: lower, upper"}

ATTRIBUTES = (
    Attribute("format_version", f"the version of this layout ({FORMAT_VERSION})", "tables written by microsim 0.1.0 "
              "after the layout was declared; older tables have the same layout without it"),
    Attribute("units", "each dataset's unit, as CF spells it (1: a number)", "format 1.1", group="every dataset"),
    Attribute("long_name", "what each dataset holds (its meaning below)", "format 1.1", group="every dataset"),
    Attribute("ancillary_variables", "the dataset's standard error (and covariance): X_stderr", "format 1.1, "
              "datasets that have one", group="every dataset"),
    Attribute("coordinates", "the coordinates along its axes: theta_i phi_i, theta_o phi_o", "format 1.1, "
              "datasets of the root with incidence or cell axes", group="every dataset"),
    Attribute("microsim_version", "the version of microsim that wrote the table"),
    Attribute("config_toml", "the run config, validated and complete (every default written out), as TOML"),
    Attribute("created_utc", "when the table was written (ISO 8601, UTC)"),
    Attribute("seed", "run.seed"),
    Attribute("wall_time_s", "seconds of tracing, without compiling"),
    Attribute("name", "the config's name (a label, \"\" if none)"),
    Attribute("realizations", "independent geometry samples: the batches of the standard errors"),
    Attribute("paths_per_realization", "paths traced per realization and incidence"),
    Attribute("max_order", "run.max_order (0: unlimited)"),
    Attribute("backend", "how Embree was called: direct or embreex"),
    Attribute("backend_fallback", "what the backend substituted, and why (\"\" if nothing)"),
    Attribute("albedos_traced_together", "the material albedos traced in one run", "a table of an albedo list"),
    Attribute("albedo_traced", "the albedo the paths were traced at (the largest)", "a table of an albedo list"),
    Attribute("cells_requested", "sensor.cells as the config asked (the sensor's actual cells: the datasets' "
              "length)", group="sensor"),
    Attribute("sha256", "the SHA-256 of the dataset's bytes, checked by microsim.tables.load", group="every dataset"),
)

_ENERGY_DOCS = {
    "transmitted": "energy that left through the bottom of the scene",
    "truncated": "energy cut by run.max_order or the tracer's limit of interactions",
    "absorbed": "energy absorbed by the materials",
    "balance": "albedo + transmitted + truncated + absorbed: 1 in expectation",
}
_COUNT_DOCS = {
    "segments": "ray segments traced",
    "inside_hits": "hits on a back face, passed through (a ray inside overlapping spheres)",
    "roulette_kills": "paths ended by Russian roulette",
}

CORE = (
    Dataset("incidence/theta", ("incidences",), "rad", "polar angle of each incidence wi", required=True),
    Dataset("incidence/phi", ("incidences",), "rad", "azimuth of each incidence wi", required=True),
    *(Dataset(f"sensor/{name}", ("cells",), "rad", doc, required=True) for name, doc in (
        ("theta_lo", "lower polar bound of each cell"), ("theta_hi", "upper polar bound of each cell"),
        ("phi_lo", "lower azimuth bound of each cell, in the scene's frame (the relative azimuth of an "
                   "incidence at phi_i = 0; cells of a ring are centred on phi = 2 pi j / n)"),
        ("phi_hi", "upper azimuth bound of each cell"))),
    Dataset("sensor/direction", ("cells", "xyz"), "", "unit vector of each cell's centre", required=True),
    Dataset("sensor/solid_angle", ("cells",), "sr", "solid angle of each cell", required=True),
    Dataset("sensor/projected_solid_angle", ("cells",), "sr", "projected solid angle P_C of each cell "
            "(the integral of cos theta over it)", required=True),
    Dataset("sensor/ring_counts", ("rings",), "", "cells in each ring, from the pole (the sensor is rebuilt from it)",
            required=True),
    *(Dataset(f"energy/{name}{suffix}", ("incidences",), "",
              doc if not suffix else f"standard error of energy/{name}",
              required=name in ("transmitted", "truncated") and not suffix)
      for name, doc in ((n, _ENERGY_DOCS[n]) for n in (*ENERGY_NAMES, "balance")) for suffix in ("", "_stderr")),
    Dataset("paths", ("incidences",), "", "paths traced per incidence", required=True),
    *(Dataset(f"diagnostics/{name}", ("incidences",), "", _COUNT_DOCS[name]) for name in COUNT_NAMES),
    Dataset("scene/<count>", ("realizations",), "", "what each realization generated (spheres, images, triangles, ...); the "
            "group's attributes hold the resolved scene parameters and the largest triangle count"),
    *(Dataset(f"scene/{name}", ("realizations", *axes), unit, f"{doc} (geometry/surface_statistics.py; "
              "masking directions: the attribute scene/statistics_directions_deg)",
              "mesh and heightfield scenes with statistics = true")
      for name, axes, unit, doc in (
          ("ndf", ("cells",), "1/sr", "each realization's NDF D(m), averaged over each sensor cell of normals m"),
          ("vndf", ("masking_directions", "cells"), "1/sr", "its visible NDF D_wo(m) = G1(wo, m) <wo.m> D(m) / "
           "cos theta_o, averaged over each cell"),
          ("g1", ("masking_directions",), "", "the visible share of the facets' area projected towards wo"),
          ("facing_area", ("masking_directions",), "", "the facets' area projected towards wo, per tile area"),
          ("g1_rays", ("masking_directions", "cells"), "", "shadow rays started on facets of normals in each cell"),
          ("g1_free", ("masking_directions", "cells"), "", "those of them that left the surface: sum(g1_free) / "
           "sum(g1_rays) over the realizations is G1(wo, m)"))),
    *(Dataset(f"scene/{name}", ("realizations", *axes), unit, f"{doc} (geometry/sphere_statistics.py)",
              "poisson_spheres and packed_spheres scenes with statistics = true")
      for name, axes, unit, doc in (
          ("pair_correlation", ("pair_bins",), "", "each realization's pair correlation g(r) of the sphere centres "
           "(periodic in x, y and z)"),
          ("chords", ("chord_bins",), "", "counts of the void's chord lengths in the bulk (from the spheres' exposed "
           "surface, cosine-weighted), the last bin those beyond the last edge"),
          ("mean_chord", (), "", "the mean of those chords, in radii"),
          ("free_path_top", ("incidences", "chord_bins"), "", "counts of the first flight along each wi from the "
           "plane z = the largest radius to the first sphere, the last bin those beyond the last edge or through"))),
)

#: the root's coordinates (format 1.1): what xarray shows along the incidences and the cells,
#: and the dimension scales (one per axis a table uses; netCDF's coordinate variables)
COORDINATES = (
    Dataset("theta_i", ("incidences",), "rad", "polar angle of each incidence: incidence/theta under a second "
            "name (one dataset, hard-linked)", "format 1.1"),
    Dataset("phi_i", ("incidences",), "rad", "azimuth of each incidence: incidence/phi under a second name",
            "format 1.1"),
    Dataset("theta_o", ("cells",), "rad", "polar angle of each cell's centre (sensor/direction; 0 for the cap)",
            "format 1.1"),
    Dataset("phi_o", ("cells",), "rad", "azimuth of each cell's centre, in the scene's frame (the relative azimuth "
            "phi_o - phi_i where phi_i = 0)", "format 1.1"),
    Dataset("theta_o_bounds", ("cells", "bounds"), "rad", "each cell's polar bounds (sensor/theta_lo, theta_hi)",
            "format 1.1"),
    Dataset("phi_o_bounds", ("cells", "bounds"), "rad", "each cell's azimuth bounds (sensor/phi_lo, phi_hi)",
            "format 1.1"),
    *(Dataset(axis, (axis,), "", f"the dimension scale of axis {axis}: {SCALES[axis]}", "format 1.1, where a "
              "dataset has the axis") for axis in AXIS_LENGTHS),
)

