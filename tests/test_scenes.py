"""The scene contract: generators name their integrator, SceneBuilder assembles parts and bases."""

from typing import ClassVar, Literal

import numpy as np
import pytest

from microsim import geometry
from microsim.tracer import integrators, materials
from microsim.tracer.materials import Absorber, Lambert
from microsim.tracer.scene import BASE_MARGIN, SceneBuilder
from microsim.tracer.shapes import PLANE, SPHERE, Shapes


def test_every_scene_kind_names_an_integrator_that_exists():
    for kind, generator in geometry.SCENES.items():
        tracer = integrators.get(generator.INTEGRATOR)
        assert callable(tracer.compile) and callable(tracer.trace), kind


def test_builder_keeps_part_order_and_lays_a_base_plane_over_the_tile():
    builder = SceneBuilder(tile=10.0)
    sphere = Shapes.spheres(np.array([[5.0, 5.0, -2.0]]), 1.0, 1.0)
    vertices = np.array([[4.0, 5.0, -2.0], [6.0, 5.0, -2.0], [5.0, 6.0, -2.0]])
    builder.add(vertices, np.array([[0, 1, 2]]), np.array([0]), sphere, Lambert(kind="lambert", albedo=0.3))
    builder.add_base_plane(-4.0, Absorber(kind="absorber"))
    scene = builder.build(1.0, -5.0, {"kind": "test"})
    assert scene.shapes.code.tolist() == [SPHERE, PLANE]
    assert scene.shapes.material.tolist() == [0, 1]
    assert scene.materials.code.tolist() == [Lambert.code, Absorber.code]
    assert scene.face_shape.tolist() == [0, 1, 1] and scene.faces[1:].min() == 3
    base = scene.vertices[3:]
    assert np.all(base[:, 2] == -4.0)
    assert base[:, :2].min() == pytest.approx(-BASE_MARGIN * 10.0) and base[:, :2].max() == pytest.approx(10.1)
    a, b, c = scene.vertices[scene.faces[1]]
    assert np.cross(b - a, c - a)[2] > 0  # the base faces +z
    assert scene.info == {"kind": "test", "triangles": 3}


def define_material_kind(name: str) -> type:
    """A material kind named ``name`` that absorbs everything, defined now."""
    class Kind(materials.Material):
        kind: Literal[name]
        example: ClassVar[dict] = {}

        @staticmethod
        def sample(prm, states, i, d, n):
            return d, 0.0, 0.0

    return Kind


def test_a_material_kind_is_refused_when_defined_twice_or_after_the_kernels_are_built():
    """A kind's code is its place in the registry; a name defined twice, or a kind defined once
    the kernels' switch over the kinds is built (a module the package does not import before
    it), is refused and leaves the registry as it was."""
    before = dict(materials.MATERIALS)
    with pytest.raises(TypeError, match="defined twice"):
        define_material_kind("lambert")
    with pytest.raises(TypeError, match="before the kernels' switch over the kinds is built"):
        define_material_kind("velvet")
    assert [kind.code for kind in materials.MATERIALS.values()] == list(range(len(materials.MATERIALS)))
    assert materials.MATERIALS == before
