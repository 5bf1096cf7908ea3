"""A user's own model, compared and fitted from Python and from the command line: a plain
function, and a BRDFModel subclass in a file or a module."""

import json
import math

import numpy as np
import pytest

from microsim import models, tables
from microsim.analysis import compare, fit
from microsim.cli import main
from microsim.testing.tables import write_plane_table

MODEL_FILE = '''
import numpy as np
from microsim.models import BRDFModel, Param


class Diffuse(BRDFModel):
    """A Lambertian BRDF written by a user."""
    name = "my_diffuse"
    params = (Param("reflectance", "hemispherical reflectance", 0.3, 0.0, 1.0),)
    reference = "a user's model"

    def _eval(self, wi, wo):
        return np.full(len(wi), self.reflectance / np.pi)


def lambertian(wi, wo, albedo=0.3):
    return np.full(len(wi), albedo / np.pi)


def broken(wi, wo):
    return {}["no such key"]
'''


def lambertian(wi, wo, albedo=0.3):
    """A plain function: f in 1/sr for arrays (N, 3) of directions."""
    return np.full(len(wi), albedo / math.pi)


def same_fit(ours: dict, theirs: dict) -> bool:
    """Two fits of one parameter by models equal up to rounding: within the convergence of the
    fit (fit.CONVERGED of a standard error), with the same error."""
    (value, error), (their_value, their_error) = ours, theirs
    return abs(value - their_value) <= fit.CONVERGED * error and error == pytest.approx(their_error, rel=1e-6)


@pytest.fixture(scope="module")
def plane(tmp_path_factory):
    return write_plane_table(tmp_path_factory.mktemp("user"), 6400)


def test_a_plain_function_compares_and_fits_as_the_registered_model_does(plane):
    table = tables.load(plane)
    theirs = compare.compare(table, "lambert", albedo=0.5)
    for spec in (lambertian, lambda wi, wo: np.full(len(wi), 0.5 / np.pi)):
        ours = compare.compare(table, spec, **({"albedo": 0.5} if spec is lambertian else {}))
        np.testing.assert_array_equal(ours.model, theirs.model)
        assert ours.as_dict()["overall"] == theirs.as_dict()["overall"]
    assert compare.compare(table, lambertian).params == {"albedo": 0.3}  # its default
    fitted = fit.fit(table, lambertian, ["albedo"], {"albedo": 0.5})
    registered = fit.fit(table, "lambert", ["albedo"], {"albedo": 0.5})
    assert same_fit(fitted.free["albedo"], registered.free["albedo"]) and fitted.comparison.model_name == "lambertian"


def test_a_subclass_compares_and_fits_from_python(plane, tmp_path):
    namespace = {}
    exec(MODEL_FILE, namespace)
    table = tables.load(plane)
    result = fit.fit(table, namespace["Diffuse"], ["reflectance"], {"reflectance": 0.5})
    assert same_fit(result.free["reflectance"], fit.fit(table, "lambert", ["albedo"], {"albedo": 0.5}).free["albedo"])
    assert "my_diffuse" not in models.available()  # a user's class needs no registration


@pytest.mark.parametrize("where", ["file", "module"])
def test_a_user_model_from_the_command_line(plane, tmp_path, monkeypatch, capsys, where):
    (tmp_path / "user_brdfs.py").write_text(MODEL_FILE)
    monkeypatch.chdir(tmp_path)
    source = str(tmp_path / "user_brdfs.py") if where == "file" else "user_brdfs"
    outputs = {}
    for name, free, param in (("Diffuse", "reflectance", "reflectance=0.4"), ("lambertian", "albedo", "albedo=0.4")):
        assert main(["compare", str(plane), "--model", f"{source}:{name}", "--param", param, "--json"]) == 0
        compared = json.loads(capsys.readouterr().out)
        assert main(["fit", str(plane), "--model", f"{source}:{name}", "--free", free, "--param", param, "--json"]) == 0
        fitted = json.loads(capsys.readouterr().out)
        outputs[name] = compared["overall"], (fitted["fit"][free]["value"], fitted["fit"][free]["stderr"])
    assert main(["fit", str(plane), "--model", "lambert", "--free", "albedo", "--param", "albedo=0.4", "--json"]) == 0
    fitted = json.loads(capsys.readouterr().out)["fit"]["albedo"]
    assert outputs["Diffuse"][0] == outputs["lambertian"][0]
    for name in outputs:
        assert same_fit(outputs[name][1], (fitted["value"], fitted["stderr"]))


@pytest.mark.parametrize("spec, message", [
    ("missing.py:Diffuse", "--model missing.py:Diffuse: missing.py: no such file"),
    ("{dir}/user_brdfs.py:Nothing", "--model {dir}/user_brdfs.py:Nothing: {dir}/user_brdfs.py has no Nothing"),
    ("no_such_module:Diffuse", "--model no_such_module:Diffuse: importing no_such_module raised ModuleNotFoundError: "
                               "No module named 'no_such_module'"),
    ("{dir}/user_brdfs.py:np", "--model {dir}/user_brdfs.py:np: <module 'numpy'"),
    ("{dir}/user_brdfs.py:broken", "--model {dir}/user_brdfs.py:broken: evaluating it raised KeyError: 'no such key'"),
    ("nonsense", "--model: unknown model 'nonsense'; accepted: "),
    ("my_brdfs.py", "--model my_brdfs.py: a model of your own is named path.py:Name, Name the class or function"),
    ("{dir}:Diffuse", "--model {dir}:Diffuse: {dir}: is a directory, not a file"),
])
def test_a_user_model_that_cannot_be_used_is_refused_in_one_line(plane, tmp_path, capsys, spec, message):
    (tmp_path / "user_brdfs.py").write_text(MODEL_FILE)
    assert main(["compare", str(plane), "--model", spec.format(dir=tmp_path)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.splitlines()) == 1
    assert captured.err.startswith("microsim: error: " + message.format(dir=tmp_path)), captured.err


def test_directions_are_normalised_and_a_null_direction_is_refused():
    """A model normalises its directions (m([0, 0, 2], [0, 0, 1]) is m([0, 0, 1], [0, 0, 1])) and
    refuses a null one."""
    model = models.create("oren_nayar", albedo=0.8, roughness=0.3)
    wi = np.array([0.3, -0.2, 0.9])
    wo = np.array([-0.5, 0.1, 0.6])
    unit = model(wi / np.linalg.norm(wi), wo / np.linalg.norm(wo))
    assert model(2.0 * wi, 0.5 * wo) == pytest.approx(unit, rel=1e-14)
    assert model([0.0, 0.0, 2.0], [0.0, 0.0, 1.0]) == pytest.approx(model([0.0, 0.0, 1.0], [0.0, 0.0, 1.0]), rel=1e-14)
    for bad in ([0.0, 0.0, 0.0], [np.nan, 0.0, 1.0], [0.0, np.inf, 1.0]):
        with pytest.raises(ValueError, match="wo: a direction of length 0, NaN or infinity"):
            model(wi, bad)
