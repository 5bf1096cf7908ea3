"""Energy, reciprocity and bad input for the ``mesh`` and ``heightfield`` scenes (geometry/periodic_tile.py).

1. Energy: a white Lambertian or mirror tile is closed by its surface (no [base]; nothing can be
   absorbed or transmitted), so every path leaves or is truncated: albedo + truncated = 1 to
   1e-6 at theta_i = 0, 60, 85 and 89 deg, for a mesh with vertical walls (cells at several
   heights, one a ridge running through the seams) and an anisotropic heightfield, each white
   and mirror, flat and smooth (tests/test_smooth_shading.py: its reciprocity). With 40 000
   paths an incidence a single lost path would miss 1e-6 25-fold;
   tests/test_mesh.py and test_heightfield.py already hold a white bumpy tile (no walls, no
   mirror, no 85 deg) to 1e-12.
   Reciprocity: an anisotropic Lambertian heightfield (albedo 0.8, about a third of the energy
   in orders 2+) at the ring-centre incidences of microsim.testing.reciprocity (phi_i 0 and 90 deg):
   f(a -> b) = f(b -> a) within 4.5 combined standard errors for every pair of matching cells
   (the quantity of every reciprocity test of the suite, ``reciprocity_z``). The same comparison
   rejects f cos(theta_o), which is not reciprocal, and the pairing with the incidences'
   azimuths swapped (what a tracer that ignored phi_i, or turned the scene, would give).
2. Bad input not covered by tests/test_mesh.py and test_heightfield.py: unreadable (corrupt)
   files, a directory, a mesh with no triangles, extents that are not one square period, a
   period (or scale, pixel, height scale) of 0, negative, NaN or infinite, heights that are
   infinite, of one sample, boolean or three-dimensional, and a tile too large for the memory
   (refused by the memory estimate before anything is traced): one line naming the key or the
   file, exit 2, nothing written; a mesh with a slit in a vertical wall (a hole with no projected
   area, through which about 1 % of the light would be transmitted: open edges off the seams are
   refused).
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from microsim import config, tables
from microsim.run import memory, runner
from microsim.run.memory import PROCESS_BYTES
from microsim.testing import trace_table
from microsim.testing.reciprocity import RECIPROCITY_CELLS, reciprocity_z, ring_incidences
from microsim.testing.refusals import SMALL_RUN, assert_run_refused
from microsim.testing.surfaces import RIDGE_SAMPLES, ridges, write_mesh

WHITE = {"kind": "lambert", "albedo": 1.0}
MIRROR = {"kind": "mirror"}
#: (theta_i, phi_i) of the energy checks: up to 89 deg along and across the tiles' features
ENERGY_INCIDENCES = [(0.0, 0.0), (60.0, 0.0), (85.0, 0.0), (89.0, 0.0), (60.0, 90.0), (85.0, 90.0), (89.0, 90.0)]
#: cell levels of the walled tile: a ridge along y through the seams (x in [1/4, 1/2]), a
#: raised cell next to it, a step down; first and last rows and columns equal (no wall on a seam)
LEVELS = np.array([[0, 0, 0, 0],
                   [2, 2, 2, 2],
                   [0, 3, 1, 0],
                   [0, 0, 0, 0]])


def walled(levels=LEVELS, cell: float = 0.25, step: float = 0.25, slit: int | None = None):
    """(vertices, faces) of a periodic tile of flat square cells, cell (i, j) at height
    ``step`` levels[i, j], joined by vertical walls, each cut at every level so that all edges
    are shared; the tile is closed (its solid lies below it). ``slit`` = z leaves out the quad
    between levels z and z + 1 of the +x wall of cell (2, 1) (level 3, beside level 0): a slit
    into the solid under the raised cell, open to the bottom (no floor lies under a raised cell)."""
    k = len(levels)
    index: dict = {}

    def vertex(i, j, level):
        return index.setdefault((i, j, level), len(index))

    faces = []

    def quad(corners, outward):
        """Two triangles of the quad of lattice corners, wound so that the normal is along ``outward``."""
        a, b, c, d = corners
        p = np.array(corners, float)
        if np.dot(np.cross(p[1] - p[0], p[2] - p[0]), outward) < 0:
            a, b, c, d = d, c, b, a
        faces.extend([[vertex(*a), vertex(*b), vertex(*c)], [vertex(*a), vertex(*c), vertex(*d)]])

    for i in range(k):
        for j in range(k):
            level = levels[i, j]
            quad([(i, j, level), (i + 1, j, level), (i + 1, j + 1, level), (i, j + 1, level)], (0, 0, 1))
            for axis, (ni, nj) in ((0, (i + 1, j)), (1, (i, j + 1))):
                if ni == k or nj == k or levels[ni, nj] == level:
                    continue
                outward = np.eye(3)[axis] * np.sign(level - levels[ni, nj])
                for z in range(min(level, levels[ni, nj]), max(level, levels[ni, nj])):
                    if axis == 0:
                        quad([(i + 1, j, z), (i + 1, j + 1, z), (i + 1, j + 1, z + 1), (i + 1, j, z + 1)], outward)
                    else:
                        quad([(i, j + 1, z), (i + 1, j + 1, z), (i + 1, j + 1, z + 1), (i, j + 1, z + 1)], outward)
    lattice = np.array(sorted(index, key=index.get), float)
    vertices = lattice * np.array([cell, cell, step])
    faces = np.array(faces)
    if slit is not None:
        corners = lattice[faces]
        wall = (np.all(corners[:, :, 0] == 3, axis=1) & np.all(np.isin(corners[:, :, 1], (1, 2)), axis=1)
                & np.all(np.isin(corners[:, :, 2], (slit, slit + 1)), axis=1))
        assert wall.sum() == 2
        faces = faces[~wall]
    return vertices, faces


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The walled mesh (PLY) and the ridges height array (.npy), beside the runs' directories."""
    directory = tmp_path_factory.mktemp("tiles")
    np.save(directory / "ridges.npy", ridges())
    return {"mesh": write_mesh(directory / "walled.ply", *walled()), "heightfield": str(directory / "ridges.npy")}


def scene(kind: str, files, shading: str = "flat") -> dict:
    if kind == "mesh":
        return {"kind": "mesh", "path": files["mesh"], "shading": shading}
    return {"kind": "heightfield", "path": files["heightfield"], "pixel": 1.0 / RIDGE_SAMPLES, "shading": shading}


def run_table(data: dict, directory) -> tables.Table:
    cfg = config.validate(data)
    return trace_table(cfg, directory / "table.h5")


# ---------------------------------------------------------------- c: energy

def test_the_walled_tile_is_a_closed_periodic_surface():
    """The test's mesh is what the energy test needs: walls that are vertical, seams that match,
    the tile covered once, every edge off the sides shared."""
    from microsim.geometry.periodic_tile import checked

    vertices, faces = walled()
    tile = checked("walled", vertices, faces, None, closed_by_base=False)
    assert tile.period == 1.0 and np.count_nonzero(tile.normals[:, 2] == 0.0) == 2 * 24  # 24 wall quads, one a level
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    ends = vertices[unique[counts == 1]][:, :, :2]
    assert np.all(np.any((np.abs(ends) < 1e-12) | (np.abs(ends - 1.0) < 1e-12), axis=2).all(axis=1))


@pytest.mark.parametrize("shading", ["flat", "smooth"])
@pytest.mark.parametrize("kind", ["mesh", "heightfield"])
@pytest.mark.parametrize("material", [WHITE, MIRROR], ids=["white", "mirror"])
def test_a_white_or_mirror_closed_tile_returns_every_path(kind, material, shading, files, tmp_path):
    """Smooth shading too: the weight is the material's whatever the normal, and a direction
    sampled under its facet meets the surface again (microsim/tracer/shapes.py)."""
    table = run_table({
        "scene": scene(kind, files, shading), "material": material,
        "illumination": {"theta_i_deg": [t for t, _ in ENERGY_INCIDENCES], "phi_i_deg": [p for _, p in ENERGY_INCIDENCES]},
        "sensor": {"cells": 100}, "run": {"paths": 40_000, "realizations": 4, "seed": 5},
    }, tmp_path)
    energy = table.arrays
    np.testing.assert_allclose(table.albedo + table.truncated, 1.0, rtol=0, atol=1e-6)
    assert np.all(energy["energy/absorbed"] == 0.0) and np.all(table.transmitted == 0.0)
    # the walls and slopes do their work: paths meet the tile more than once at every oblique
    # incidence (a mirror mesh at 0 deg: never, its tops are flat and its walls vertical)
    multiple = (table.brdf_order[:, 1:] * table.sensor.projected_solid_angle()).sum(axis=(1, 2))
    assert np.all(multiple[1:] > 1e-4) and multiple.max() > 0.1, multiple


# ---------------------------------------------------------------- c: reciprocity

@pytest.fixture(scope="module")
def reciprocity_table(files, tmp_path_factory):
    """All orders on the ridges (Lambertian, albedo 0.8), incidences at ring centres x phi_i {0, 90} deg:
    960 000 paths, under the slow mark's 1 M."""
    incidences = ring_incidences()
    table = run_table({
        "scene": scene("heightfield", files), "material": {"kind": "lambert", "albedo": 0.8},
        "illumination": {"theta_i_deg": [t for _, t, _ in incidences], "phi_i_deg": [p for _, _, p in incidences]},
        "sensor": {"cells": RECIPROCITY_CELLS}, "run": {"paths": 96_000, "realizations": 16, "seed": 5},
    }, tmp_path_factory.mktemp("reciprocity"))
    return table, incidences


def test_the_anisotropic_heightfield_table_is_reciprocal(reciprocity_table):
    table, incidences = reciprocity_table
    pa = table.sensor.projected_solid_angle()
    orders = (table.brdf_order * pa).sum(axis=2)
    assert np.all(orders[:, 1:].sum(axis=1) > 0.2 * table.albedo)  # rough enough: multiple scattering matters
    # anisotropic: at the 71 deg ring, phi_i = 0 and 90 deg differ by many standard errors
    assert abs(table.albedo[-2] - table.albedo[-1]) > 10 * np.hypot(*table.albedo_stderr[-2:])
    assert np.all(table.brdf_stderr > 0)
    z = reciprocity_z(table, incidences, table.brdf, table.brdf_stderr)
    assert len(z) == 45
    assert z.max() <= 4.5


def test_a_non_reciprocal_quantity_is_detected(reciprocity_table):
    """Power of the check: f cos(theta_o) is not reciprocal, and the same comparison rejects it."""
    table, incidences = reciprocity_table
    t_lo, t_hi = table.sensor.cell_bounds()[:2]
    mu = np.cos(0.5 * (t_lo + t_hi))
    assert reciprocity_z(table, incidences, table.brdf * mu, table.brdf_stderr * mu).max() > 4.5


def test_the_incidences_azimuths_swapped_are_detected(reciprocity_table):
    """Power for the azimuth: pairing the cells as if phi_i = 0 and 90 deg were exchanged (a tracer
    that ignored phi_i, or turned the scene) is rejected."""
    table, incidences = reciprocity_table
    swapped = [(ring, theta, 90.0 - phi) for ring, theta, phi in incidences]
    assert reciprocity_z(table, swapped, table.brdf, table.brdf_stderr).max() > 4.5


# ---------------------------------------------------------------- e: bad input

def _cut(kind: str, fraction: float):
    """The walled tile written as ``kind`` (binary PLY, STL) and cut short: a corrupt file."""
    def content():
        data = trimesh.Trimesh(*walled(), process=False).export(file_type=kind)
        return data[: int(len(data) * fraction)]
    return content


def _file(name: str, content):
    """make(directory) -> the path of a file ``name`` there holding ``content``: text, bytes, an
    array (numpy's .npy), or a function returning one of them."""
    def make(directory):
        path, value = directory / name, content() if callable(content) else content
        if isinstance(value, np.ndarray):
            np.save(path, value)
        elif isinstance(value, bytes):
            path.write_bytes(value)
        else:
            path.write_text(value)
        return str(path)
    return make


#: (make a file in a directory, extra [scene] lines, what the line says after "scene.path = '...': ")
BAD_MESHES = [
    (_file("half.ply", _cut("ply", 0.5)), "", "trimesh cannot read it as a PLY file (damaged, or not of that "
                                              "format: its reader raised ValueError: PLY is unexpected length"),
    (_file("noy.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n2\n3\n"), "",
     "trimesh cannot read it as a PLY file (damaged, or not of that format: its reader raised KeyError: no 'y' in "
     "the file's declarations)"),
    (_file("junk.glb", b"glTF" + bytes(range(256)) * 4), "", "trimesh cannot read it as a GLB file"),
    (_file("index.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 9\n"), "", "trimesh cannot read it as a OBJ file"),
    (_file("index.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 5\n"), "", "trimesh cannot read it as a OFF file"),
    (_file("third.stl", _cut("stl", 1 / 3)), "", "holds no triangles"),
    (_file("empty.obj", ""), "", "holds no triangles"),
    (_file("points.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\n"), "", "holds no triangles"),
    (lambda directory: str(directory), "", "is a directory, not a file"),
    (_file("walled.ply", lambda: trimesh.Trimesh(*walled(), process=False).export(file_type="ply")),
     "period = 0.5", ""),  # two periods wide: its copies a period apart do not join
]


@pytest.mark.parametrize("make, extra, what", BAD_MESHES,
                         ids=["corrupt-ply", "ply-without-y", "junk-glb", "obj-index", "off-index", "cut-stl",
                              "empty-obj",
                              "no-faces-obj", "directory", "period-too-small"])
def test_an_unreadable_empty_or_non_periodic_mesh_is_refused_in_one_line(make, extra, what, tmp_path,
                                                                         tmp_path_factory, capsys):
    path = make(tmp_path_factory.mktemp("meshes"))  # beside the run's directory, which must stay empty
    text = f'[scene]\nkind = "mesh"\npath = "{path}"\n{extra}\n' + SMALL_RUN
    assert_run_refused(text, f"scene.path = {path!r}: {what}", tmp_path, capsys)


#: (make a file, what the line says after "scene.path = '...': ")
BAD_HEIGHTS = [
    (_file("inf.npy", np.where(np.eye(8) > 0, np.inf, 0.0)), "8 of 64 heights are NaN or infinite"),
    (_file("one.npy", np.zeros((1, 1))), "an array of shape (1, 1)"),
    (_file("bool.npy", np.zeros((8, 8), bool)), "an array of shape (8, 8) and type bool"),
    (_file("cube.npy", np.zeros((4, 4, 4))), "an array of shape (4, 4, 4)"),
    (_file("objects.npy", np.array([[None, 1], [2, 3]], dtype=object)), "cannot be read as a height array"),
    (_file("empty.npz", lambda: b""), "not a NumPy file (a .npy starts with b'\\x93NUMPY'"),
    (_file("text.npy", "1 2\n3 4\n"), "not a NumPy file"),
    (lambda directory: str(directory), "is a directory, not a file"),
]


@pytest.mark.parametrize("make, what", BAD_HEIGHTS,
                         ids=["inf", "one-sample", "bool", "3-d", "objects", "empty-file", "text-file", "directory"])
def test_an_unreadable_or_unfit_height_array_is_refused_in_one_line(make, what, tmp_path, tmp_path_factory, capsys):
    path = make(tmp_path_factory.mktemp("heights"))
    assert_run_refused(f'[scene]\nkind = "heightfield"\npath = "{path}"\n' + SMALL_RUN,
                       f"scene.path = {path!r}: {what}", tmp_path, capsys)


@pytest.mark.parametrize("kind, line", [
    ("mesh", "period = 0.0"), ("mesh", "period = -1.0"), ("mesh", "period = nan"), ("mesh", "period = inf"),
    ("mesh", "scale = 0.0"), ("heightfield", "pixel = 0.0"), ("heightfield", "pixel = -0.5"),
    ("heightfield", "pixel = nan"), ("heightfield", "height_scale = 0.0"),
])
def test_a_period_of_zero_is_refused_in_one_line(kind, line, files, tmp_path, capsys):
    """A period (or what makes it: scale, pixel) of 0, below 0, NaN or infinite, named by its key."""
    key, value = (part.strip() for part in line.split("="))
    text = f'[scene]\nkind = "{kind}"\npath = "{files[kind]}"\n{line}\n' + SMALL_RUN
    assert_run_refused(text, f"scene.{key} = {float(value)}: out of range; accepted: a number in (0, 1e+09]",
                       tmp_path, capsys)


@pytest.mark.parametrize("kind, line, key", [("mesh", "scale = 1e-9", "scene.path"),
                                            ("heightfield", "pixel = 1e-14", "scene.pixel = 1e-14")])
def test_a_period_too_short_to_trace_is_refused_in_one_line(kind, line, key, files, tmp_path, capsys):
    """A white heightfield of period 3e-13 returned 8 % of its paths (float32 rays, the tracer's
    offsets): periods below periodic_tile.MIN_PERIOD are refused."""
    text = f'[scene]\nkind = "{kind}"\npath = "{files[kind]}"\n{line}\n' + SMALL_RUN
    assert_run_refused(text, key, tmp_path, capsys, "below 1e-06")


@pytest.mark.parametrize("kind", ["mesh", "heightfield"])
def test_a_tile_too_large_for_the_memory_is_refused_before_tracing(kind, files, tmp_path, capsys, monkeypatch):
    """The memory estimate (the tile's scene_bytes) refuses the run before any kernel is compiled
    or path traced: the free memory is made smaller than the scene, as a tile of many millions
    of triangles would be on this machine (a 4096 x 4096 height array: 34 M triangles, about
    56 GiB estimated), without writing or reading such a file."""
    def not_before_the_refusal(*args, **kwargs):
        raise AssertionError("traced a run that cannot fit")

    monkeypatch.setattr(memory, "available_memory", lambda: PROCESS_BYTES + 1024)
    monkeypatch.setattr(runner.Run, "compile", not_before_the_refusal)
    monkeypatch.setattr(runner.Run, "trace", not_before_the_refusal)
    lines = f'[scene]\nkind = "{kind}"\npath = "{files[kind]}"\n'
    if kind == "heightfield":
        lines += f"pixel = {1.0 / RIDGE_SAMPLES}\n"
    assert_run_refused(lines + SMALL_RUN, "microsim: error: this run needs about ", tmp_path, capsys)


def test_a_mesh_with_a_slit_in_a_wall_is_refused(tmp_path, tmp_path_factory, capsys):
    path = write_mesh(tmp_path_factory.mktemp("slit") / "slit.ply", *walled(slit=0))
    assert_run_refused(f'[scene]\nkind = "mesh"\npath = "{path}"\n' + SMALL_RUN, f"scene.path = {path!r}", tmp_path,
                       capsys, "open edges lie inside the tile")
