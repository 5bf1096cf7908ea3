"""Analytic shapes behind the triangle meshes: exact surface points and shading normals.

Embree finds which triangle a ray hits; the triangle's shape then gives the exact surface
point (the hit projected onto the analytic surface) and the normal the material scatters about
there. Every shape is a row of ``Shapes``: a kind code and its float64 parameters, ``N_PARAMS``
of them (rows are as wide as the widest kind of the scene: ``SMOOTH_PARAMS`` where a scene has
smooth triangles). A code that :func:`surface_point` does not know is refused when ``Shapes`` is
built.

Kinds and parameters:

- ``SPHERE``: centre (3), radius used for the normal, radius onto which hit points are
  projected (the mesh's circumscribed radius, so that a projected point is never inside the
  sphere's own convex mesh).
- ``PLANE``: a point (3) and the unit normal (3). Base planes and V-groove facets.
- ``ELLIPSOID``: centre (3), inverse semi-axes (3) along x, y, z, projection scale (>= 1, the
  mesh's circumscribed scale). Micrograins are the upper halves of such ellipsoids.
- ``SMOOTH``: a triangle shaded by its vertex normals interpolated (Phong shading): a point of
  its plane (3), its unit geometric normal (3), and the interpolated normal's affine map of the
  point q on the plane, n(q) = n_0 + M (q - point): n_0 (3), then M (3 x 3, by rows). The map is
  the barycentric interpolation of the corners' normals, extended linearly beyond the triangle.
  The material scatters about the unit n(q) where it faces the arriving ray and lies within
  acos(MIN_SHADING_COSINE) of the geometric normal, about the geometric normal elsewhere
  (docs/conventions.md §5.6: what this keeps of energy and reciprocity).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

SPHERE = 0
PLANE = 1
ELLIPSOID = 2
SMOOTH = 3
#: shape name -> kind code
CODES = {"sphere": SPHERE, "plane": PLANE, "ellipsoid": ELLIPSOID, "smooth": SMOOTH}
N_PARAMS = 7
SMOOTH_PARAMS = 18
#: a smooth triangle's interpolated normal is used where its cosine to the geometric normal is at least this
MIN_SHADING_COSINE = 0.5


@dataclass
class Shapes:
    """Analytic data of every shape of a scene (one row per shape)."""

    code: np.ndarray  # (S,) int32 kind code
    params: np.ndarray  # (S, N_PARAMS or SMOOTH_PARAMS) float64
    material: np.ndarray  # (S,) int32 index into the scene's material table (set by SceneBuilder.add)
    size: np.ndarray  # (S,) float64 characteristic length, scales the ray offset

    def __post_init__(self):
        if len(self.code) and (self.code.min() < 0 or self.code.max() >= len(CODES)):  # the codes are 0 .. len - 1
            unknown = set(np.unique(self.code).tolist()) - set(CODES.values())
            raise ValueError(f"shape kind codes {sorted(unknown)} unknown; known: {CODES}")

    @classmethod
    def empty(cls) -> "Shapes":
        return cls(
            np.zeros(0, np.int32), np.zeros((0, N_PARAMS)), np.zeros(0, np.int32), np.zeros(0)
        )

    def __len__(self) -> int:
        return len(self.code)

    @staticmethod
    def concatenate(parts: list["Shapes"]) -> "Shapes":
        """The parts' rows in order, as wide as the widest (narrower rows padded with zeros)."""
        if len(parts) == 1:
            return parts[0]
        width = max(p.params.shape[1] for p in parts)
        return Shapes(
            np.concatenate([p.code for p in parts]).astype(np.int32),
            np.concatenate([np.pad(p.params, ((0, 0), (0, width - p.params.shape[1]))) if p.params.shape[1] < width
                            else p.params for p in parts]),
            np.concatenate([p.material for p in parts]).astype(np.int32),
            np.concatenate([p.size for p in parts]),
        )

    @staticmethod
    def spheres(centres, radius, project_radius) -> "Shapes":
        n = len(centres)
        params = np.zeros((n, N_PARAMS))
        params[:, 0:3] = centres
        params[:, 3] = radius
        params[:, 4] = project_radius
        return Shapes(np.full(n, SPHERE, np.int32), params, np.zeros(n, np.int32), np.full(n, radius))

    @staticmethod
    def planes(points, normals, size) -> "Shapes":
        """Planes through ``points`` (n, 3) facing ``normals`` (n, 3), made unit here."""
        params = _plane_rows(np.ascontiguousarray(points, np.float64), np.ascontiguousarray(normals, np.float64))
        return Shapes.planes_of_rows(params, size)

    @staticmethod
    def planes_of_rows(params, size) -> "Shapes":
        """Planes whose rows ``params`` (n, N_PARAMS) :func:`set_plane_row` wrote."""
        n = len(params)
        return Shapes(np.full(n, PLANE, np.int32), params, np.zeros(n, np.int32), np.full(n, size, float))

    @staticmethod
    def ellipsoids(centres, semi_axes, project_scale) -> "Shapes":
        n = len(centres)
        params = np.zeros((n, N_PARAMS))
        params[:, 0:3] = centres
        params[:, 3:6] = 1.0 / np.asarray(semi_axes, np.float64)
        params[:, 6] = project_scale
        return Shapes(np.full(n, ELLIPSOID, np.int32), params, np.zeros(n, np.int32), np.min(semi_axes, axis=1))

    @staticmethod
    def smooth_triangles(corners, corner_normals, size) -> "Shapes":
        """Triangles ``corners`` (n, 3, 3), counter-clockwise seen from outside, shaded by their
        corners' unit normals ``corner_normals`` (n, 3, 3) interpolated (module doc)."""
        corners = np.asarray(corners, np.float64)
        normals = np.asarray(corner_normals, np.float64)
        e1, e2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
        cross = np.cross(e1, e2)
        doubled = np.linalg.norm(cross, axis=1)[:, None]
        g = cross / doubled
        # barycentric gradients on the plane: b1 = (q - v0) . (e2 x g) / 2A, b2 = (q - v0) . (g x e1) / 2A
        grad1, grad2 = np.cross(e2, g) / doubled, np.cross(g, e1) / doubled
        n0 = normals[:, 0]
        m = (np.einsum("ni,nj->nij", normals[:, 1] - n0, grad1) + np.einsum("ni,nj->nij", normals[:, 2] - n0, grad2))
        n = len(corners)
        params = np.column_stack([corners[:, 0], g, n0, m.reshape(n, 9)])
        return Shapes(np.full(n, SMOOTH, np.int32), params, np.zeros(n, np.int32), np.full(n, size, float))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _plane_rows(points, normals):
    """Rows of PLANE shapes through ``points`` facing ``normals`` (:func:`set_plane_row`)."""
    params = np.zeros((len(points), N_PARAMS))
    for i in range(len(points)):
        set_plane_row(params[i], points[i, 0], points[i, 1], points[i, 2], normals[i, 0], normals[i, 1], normals[i, 2])
    return params


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def set_plane_row(row, px, py, pz, nx, ny, nz):
    """Write a PLANE shape's parameters into ``row`` (zeros): the point, then the normal over its
    length (bit for bit as ``normals / np.linalg.norm(normals, axis=1)[:, None]``)."""
    length = math.sqrt(nx * nx + ny * ny + nz * nz)
    row[0], row[1], row[2] = px, py, pz
    row[3], row[4], row[5] = nx / length, ny / length, nz / length


@numba.njit(cache=True, error_model="numpy", _nrt=False, inline="always")
def surface_point(code, prm, h, d):
    """Project the hit h = (x, y, z) of a ray travelling along d onto the analytic shape; return
    the point and the unit normal the material scatters about there."""
    x, y, z = h
    if code == SPHERE:
        vx, vy, vz = x - prm[0], y - prm[1], z - prm[2]
        inv = 1.0 / math.sqrt(vx * vx + vy * vy + vz * vz)
        nx, ny, nz = vx * inv, vy * inv, vz * inv
        r = prm[4]
        return (prm[0] + r * nx, prm[1] + r * ny, prm[2] + r * nz), (nx, ny, nz)
    if code == PLANE:
        nx, ny, nz = prm[3], prm[4], prm[5]
        d = (x - prm[0]) * nx + (y - prm[1]) * ny + (z - prm[2]) * nz
        return (x - d * nx, y - d * ny, z - d * nz), (nx, ny, nz)
    if code == ELLIPSOID:
        # radial projection in the frame where the ellipsoid is the unit sphere: u = (h - c) / a
        # is moved to the radius s; the point is c + s (h - c), the normal that of the gradient
        # u / a, whose direction needs no s (two independent square roots, no division by a)
        vx, vy, vz = x - prm[0], y - prm[1], z - prm[2]
        ux, uy, uz = vx * prm[3], vy * prm[4], vz * prm[5]
        gx, gy, gz = ux * prm[3], uy * prm[4], uz * prm[5]
        s = prm[6] / math.sqrt(ux * ux + uy * uy + uz * uz)
        inv = 1.0 / math.sqrt(gx * gx + gy * gy + gz * gz)
        return (prm[0] + s * vx, prm[1] + s * vy, prm[2] + s * vz), (gx * inv, gy * inv, gz * inv)
    if code == SMOOTH:
        gx, gy, gz = prm[3], prm[4], prm[5]
        dist = (x - prm[0]) * gx + (y - prm[1]) * gy + (z - prm[2]) * gz
        qx, qy, qz = x - dist * gx, y - dist * gy, z - dist * gz
        rx, ry, rz = qx - prm[0], qy - prm[1], qz - prm[2]
        nx = prm[6] + prm[9] * rx + prm[10] * ry + prm[11] * rz
        ny = prm[7] + prm[12] * rx + prm[13] * ry + prm[14] * rz
        nz = prm[8] + prm[15] * rx + prm[16] * ry + prm[17] * rz
        inv = 1.0 / math.sqrt(nx * nx + ny * ny + nz * nz)
        nx, ny, nz = nx * inv, ny * inv, nz * inv
        if nx * gx + ny * gy + nz * gz >= MIN_SHADING_COSINE and nx * d[0] + ny * d[1] + nz * d[2] < 0.0:
            return (qx, qy, qz), (nx, ny, nz)
        return (qx, qy, qz), (gx, gy, gz)
    raise ValueError("surface_point: unknown shape kind code")
