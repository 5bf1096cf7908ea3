"""The Mitsuba 3 BSDF ``microsim`` and ``microsim render`` (the ``render`` extra):
the plugin's methods are the tabulated BRDF's, its sampling passes Mitsuba's own chi-square test,
a white table in a white environment renders 1 within noise, and the Lambertian plane's table
renders as Mitsuba's ``diffuse`` does."""

import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2 as chi2_distribution

from microsim import tables
from microsim.cli import main
from microsim.core.table_noise import normal_squares
from microsim.models.tabulated import TabulatedBRDF
from microsim.testing import write_table
from microsim.testing.refusals import assert_refused

mi = pytest.importorskip("mitsuba")
plugin = pytest.importorskip("microsim.interop.mitsuba")
render = pytest.importorskip("microsim.interop.render")

SIZE, SPP, RENDERS = 48, 16, 8


def traced(directory, name, scene, albedo, illumination=None):
    return write_table({"scene": scene, "material": {"kind": "lambert", "albedo": albedo},
                        "illumination": illumination or {"incidences": 13}, "sensor": {"cells": 400},
                        "run": {"paths": 20_000, "realizations": 4, "seed": 1}}, directory / f"{name}.h5")


@pytest.fixture(scope="module")
def spheres(tmp_path_factory):
    return traced(tmp_path_factory.mktemp("spheres"), "spheres", {"kind": "poisson_spheres", "volume_fraction": 0.3},
                  0.8)


@pytest.fixture(scope="module")
def plane(tmp_path_factory):
    return tables.load(traced(tmp_path_factory.mktemp("plane"), "plane", {"kind": "plane"}, 0.5))


def exact(table, f):
    """The table with every cell f: a plane's BRDF as a run estimates it in expectation."""
    return TabulatedBRDF(dataclasses.replace(table, brdf=np.full_like(table.brdf, f)))


def test_the_plugins_methods_are_the_tabulated_brdfs_on_a_wavefront(spheres):
    tabulated = TabulatedBRDF(spheres)
    bsdf = plugin.bsdf(tabulated)
    rng = np.random.default_rng(7)
    n = 1000
    wi = rng.normal(size=(n, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo = rng.normal(size=(n, 3))
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    u1, u2 = rng.random(n), rng.random((n, 2))
    wi, wo, u1, u2 = (x.astype(np.float32).astype(np.float64) for x in (wi, wo, u1, u2))  # as Mitsuba holds them
    if plugin.variant().startswith("scalar"):
        pytest.skip("a wavefront: for the JIT variants")
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*wi.T)
    ctx = mi.BSDFContext()
    expected_f = np.where(wo[:, 2] > 0, tabulated(wi, wo) * np.maximum(wo[:, 2], 0), 0.0)
    np.testing.assert_allclose(np.asarray(bsdf.eval(ctx, si, mi.Vector3f(*wo.T)))[0], expected_f, rtol=1e-6,
                               atol=1e-9)
    np.testing.assert_allclose(np.asarray(bsdf.pdf(ctx, si, mi.Vector3f(*wo.T))), tabulated.pdf(wi, wo), rtol=1e-6,
                               atol=1e-9)
    sampled, weight = bsdf.sample(ctx, si, mi.Float(u1), mi.Point2f(*u2.T))
    expected_wo, expected_pdf = tabulated.sample(wi, u1, u2)
    np.testing.assert_allclose(np.asarray(sampled.wo).T, expected_wo, rtol=0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(sampled.pdf), expected_pdf, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(weight)[0], tabulated(wi, expected_wo) * expected_wo[:, 2] / expected_pdf,
                               rtol=1e-5)


@pytest.mark.parametrize("theta_i", [0.0, 40.0, 80.0])
def test_the_plugins_sampling_passes_mitsubas_chi_square_test(spheres, theta_i):
    """Mitsuba's own test of a BSDF (src/python/python/chi2.py): samples against the pdf over the
    sphere, through the registered plugin ``microsim``."""
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    plugin.register()
    t = np.radians(theta_i)
    sample, pdf = BSDFAdapter("microsim", {"type": "microsim", "filename": str(spheres)},
                              wi=mi.Vector3f(float(np.sin(t)), 0.0, float(np.cos(t))))
    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf, sample_dim=3,
                         sample_count=400_000, res=60, ires=16)
    assert test.run(), test.messages


def furnace_z2(bsdf_a, bsdf_b=None, value=1.0):
    """Per pixel of the object, the mean over RENDERS seeds of (render - value) (or of the
    difference of two BSDFs' renders, same seed) over its standard error, as squares of standard
    normal numbers (Student's t of RENDERS - 1 degrees of freedom); and the mean |z|."""
    covered = render.coverage(SIZE, SPP) > 0.999
    runs = []
    for seed in range(RENDERS):
        a = render.render(bsdf_a, "environment", SIZE, SPP, seed)
        b = value if bsdf_b is None else render.render(bsdf_b, "environment", SIZE, SPP, seed)
        runs.append((a - b)[covered])
    runs = np.array(runs)
    z = runs.mean(axis=0) / (runs.std(axis=0, ddof=1) / np.sqrt(RENDERS))
    return normal_squares(z, RENDERS), float(np.mean(np.abs(z)))


def test_a_white_table_in_a_white_environment_renders_one_within_noise(plane):
    """The furnace: albedo 1 at every incidence (the white plane's table in expectation) under a
    constant environment of radiance 1: every pixel of the sphere is 1. Emitter sampling and MIS
    make it noisy unless eval, pdf and sample agree."""
    squares, mean_abs_z = furnace_z2(plugin.bsdf(exact(plane, 1.0 / np.pi)))
    n = squares.size
    assert chi2_distribution.ppf(0.005, n) / n <= squares.mean() <= chi2_distribution.ppf(0.995, n) / n, squares.mean()
    assert mean_abs_z < 3.0


def test_the_lambertian_plane_table_renders_as_mitsubas_diffuse(plane):
    """The same scene and seeds with Mitsuba's ``diffuse`` of albedo 0.5: under the directional
    light the pixels are the same to float32 rounding (one emitter sample, f cos the same); under
    the environment their difference has mean 0 within its noise (the two sample differently)."""
    table = plugin.bsdf(exact(plane, 0.5 / np.pi))
    diffuse = mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}})
    a, b = render.render(table, "directional", SIZE, SPP, 1), render.render(diffuse, "directional", SIZE, SPP, 1)
    lit = (render.coverage(SIZE, SPP) > 0.999) & (b > 1e-3)
    assert np.sqrt(np.mean(((a - b)[lit] / b[lit]) ** 2)) < 1e-5
    squares, _ = furnace_z2(table, diffuse)
    n = squares.size
    assert chi2_distribution.ppf(0.005, n) / n <= squares.mean() <= chi2_distribution.ppf(0.995, n) / n, squares.mean()


def test_render_writes_the_comparison_png(spheres, tmp_path, capsys):
    out = tmp_path / "compare.png"
    assert main(["render", str(spheres), "--model", "lambert_sphere", "--param", "albedo=0.8", "--out", str(out),
                 "--size", "32", "--spp", "4"]) == 0
    import matplotlib.image

    image = matplotlib.image.imread(out)  # two rows (the lights) of three panels (table, model, difference)
    assert image.ndim == 3 and image.shape[1] > 2 * image.shape[0] * 0.8
    assert "render written to" in capsys.readouterr().out


def test_a_mesh_is_centred_and_scaled_into_the_unit_sphere(spheres, tmp_path):
    """--mesh: an icosphere of radius 2 at (3, 1, 0) covers what the unit sphere covers (the share
    of the frame within the faceting's difference)."""
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=4, radius=2.0)
    mesh.apply_translation([3.0, 1.0, 0.0])
    mesh.export(tmp_path / "ball.ply")
    covered = render.coverage(SIZE, SPP, tmp_path / "ball.ply")
    sphere = render.coverage(SIZE, SPP)
    assert abs(covered.sum() - sphere.sum()) < 0.01 * sphere.sum()
    assert main(["render", str(spheres), "--mesh", str(tmp_path / "ball.ply"), "--out", str(tmp_path / "b.png"),
                 "--size", "32", "--spp", "4"]) == 0


def test_the_plugin_takes_a_registered_model_by_name():
    """{"type": "microsim", "model": "lambert", "albedo": 0.5}: f cos theta_o = 0.5 cos / pi."""
    plugin.register()
    bsdf = mi.load_dict({"type": "microsim", "model": "lambert", "albedo": 0.5})
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(0.0, 0.6, 0.8)
    value = np.asarray(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(0.0, -0.8, 0.6))).ravel()[0]
    np.testing.assert_allclose(value, 0.5 * 0.6 / np.pi, rtol=1e-6)


def test_bad_renders_are_refused_in_one_line_and_write_nothing(spheres, tmp_path, capsys):
    taken = tmp_path / "taken.png"
    taken.write_bytes(b"keep me")
    few = traced(tmp_path, "few", {"kind": "plane"}, 0.5, {"theta_i_deg": [0.0, 30.0, 60.0, 85.0]})
    broken = tmp_path / "broken.ply"
    broken.write_text("ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n")
    cases = (
        (["render", str(spheres), "--out", str(taken)], ("--out", "exists", "--force")),
        (["render", str(tmp_path / "missing.h5"), "--out", str(tmp_path / "a.png")], ("missing.h5", "not found")),
        (["render", str(spheres), "--param", "albedo=0.8", "--out", str(tmp_path / "a.png")], ("--param", "--model")),
        (["render", str(spheres), "--mesh", str(tmp_path / "none.ply"), "--out", str(tmp_path / "a.png")],
         ("--mesh", "not found")),
        (["render", str(few), "--out", str(tmp_path / "a.png")], ("not a full BRDF",)),
        (["render", str(spheres), "--mesh", str(broken), "--out", str(tmp_path / "a.png")],
         ("--mesh", "cannot read")),
    )
    before = sorted(tmp_path.iterdir())
    for argv, words in cases:
        assert_refused(argv, capsys, *words)
    assert sorted(tmp_path.iterdir()) == before and taken.read_bytes() == b"keep me"


def test_no_render_writes_over_its_inputs_or_into_an_unwritable_folder(spheres, tmp_path, capsys):
    """--out the table, or the mesh rendered, is refused with --force or not (each the only copy of
    what the render reads); a folder nothing can write in (/sys, even for root), a suffix of no
    picture format: one line before anything is rendered."""
    table = tmp_path / "own.h5"
    table.write_bytes(spheres.read_bytes())
    mesh = tmp_path / "bunny.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    before = {path: path.read_bytes() for path in (table, mesh)}
    cases = [(["--out", str(table), "--force"], ("--out", "the table", "another name")),
             (["--out", str(mesh), "--mesh", str(mesh), "--force"], ("--out", "the mesh", "another name")),
             (["--out", "/sys/render.png"], ("--out", "/sys", "not writable")),
             (["--out", str(tmp_path / "r.bmp")], ("--out", "suffix", ".png", ".jpg"))]
    for flags, words in cases:
        assert_refused(["render", table, *flags], capsys, *words)
    assert {path: path.read_bytes() for path in (table, mesh)} == before and len(list(tmp_path.iterdir())) == 2


def test_a_model_that_raises_while_rendered_is_named_with_its_error(spheres, tmp_path, capsys):
    """Mitsuba reports an exception of a Python BSDF only as "(see above)": the render says the
    model's own, in one line, and writes nothing."""
    (tmp_path / "boom.py").write_text("def Boom(wi, wo):\n    raise ValueError('no value at these directions')\n")
    out = tmp_path / "r.png"
    assert main(["render", str(spheres), "--model", f"{tmp_path / 'boom.py'}:Boom", "--out", str(out), "--size", "16",
                 "--spp", "1"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [f"microsim: error: --model {tmp_path / 'boom.py'}:Boom: evaluating it raised ValueError: no value "
                     "at these directions"], lines
    assert not out.exists()


@pytest.mark.parametrize("suffix, magic", [(".png", b"\x89PNG"), (".jpg", b"\xff\xd8\xff"), (".jpeg", b"\xff\xd8\xff"),
                                           (".pdf", b"%PDF"), (".svg", b"<?xml")])
def test_a_render_is_written_in_the_format_of_its_suffix(suffix, magic, tmp_path):
    images = {light: {"table": np.ones((8, 8))} for light in render.LIGHTS}
    out = render.figure(images, tmp_path / f"r{suffix}", ("table", "model"))
    assert out.read_bytes().startswith(magic) and [p.name for p in tmp_path.iterdir()] == [f"r{suffix}"]


SCALAR_CHECK = """
import sys, numpy as np, mitsuba as mi
mi.set_variant("scalar_rgb")
from microsim import tables; from microsim.interop import mitsuba as plugin
from microsim.models.tabulated import TabulatedBRDF
tabulated = TabulatedBRDF(tables.load(sys.argv[1]))
bsdf, ctx = plugin.bsdf(tabulated), mi.BSDFContext()
rng = np.random.default_rng(8)
worst = 0.0
for _ in range(200):
    wi, wo = rng.normal(size=3), rng.normal(size=3)
    wi[2] = abs(wi[2])
    wi, wo = (np.array(w / np.linalg.norm(w), np.float32).astype(float) for w in (wi, wo))
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*wi)
    f = float(bsdf.eval(ctx, si, mi.Vector3f(*wo))[0])
    expected = float(tabulated(wi, wo)) * max(wo[2], 0.0) if wo[2] > 0 else 0.0
    u1, u2 = np.float32(rng.random()), np.array(rng.random(2), np.float32)
    sampled, weight = bsdf.sample(ctx, si, float(u1), mi.Point2f(*u2.astype(float)))
    wo_s, pdf_s = tabulated.sample(wi.reshape(1, 3), [float(u1)], u2.astype(float).reshape(1, 2))
    pdf = float(bsdf.pdf(ctx, si, mi.Vector3f(*wo)))
    worst = max(worst, abs(f - expected) / max(expected, 1e-12) if expected else abs(f),
                float(np.max(np.abs(np.array(sampled.wo) - wo_s[0]))), abs(sampled.pdf - pdf_s[0]) / pdf_s[0],
                abs(pdf - float(tabulated.pdf(wi, wo)[0])) / max(float(tabulated.pdf(wi, wo)[0]), 1e-12))
print(mi.variant(), worst)
"""


def test_the_plugin_is_correct_in_a_scalar_variant(spheres):
    """One ray at a time (a process of its own: the variant is the process's): eval, pdf and sample
    as the tabulated BRDF's, to float32 rounding."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", SCALAR_CHECK, str(spheres)], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    variant, worst = done.stdout.split()
    assert variant == "scalar_rgb" and float(worst) < 2e-5, done.stdout
