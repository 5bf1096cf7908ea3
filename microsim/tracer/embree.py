"""A small binding of Embree 4, the library that the embreex wheel ships, callable from numba.

The tracer needs a dozen Embree calls: a device; scenes of triangle meshes and of native
spheres (``RTC_GEOMETRY_TYPE_SPHERE_POINT``: one float4 x, y, z, r per sphere, intersected
exactly); commit; and ``rtcIntersect1`` / ``rtcOccluded1`` for one ray at a time. Scenes are
built from Python through ctypes. The two ray queries are called from numba kernels by symbol
name (``numba.types.ExternalFunction``), the library being loaded into the process for LLVM
(``llvmlite.binding.load_library_permanently``): a kernel that calls them can be cached, and it
runs without the GIL, so threads share one committed scene.

Ray and hit live in an ``RTCRayHit`` record (:data:`RAYHIT`, Embree 4.4 with instance arrays:
ray 48 bytes, hit 48 bytes, 16-byte aligned). Handles and addresses are passed as integers,
which the x86-64 and AArch64 calling conventions pass like pointers. The layout is checked in
each process before its first scene (:func:`load`) by tracing known rays at a known triangle and
sphere; if the library is missing or fails the check, :class:`EmbreeUnavailable` says why in one
line, and the runner falls back to embreex's own wavefront calls.
"""

from __future__ import annotations

import ctypes
import functools
import importlib.util
import os
import threading
from collections import namedtuple
from pathlib import Path

import numba
import numpy as np
from numba import types

#: RTCGeometryType, RTCBufferType and RTCFormat values (include/embree4/rtcore_*.h)
GEOMETRY_TRIANGLE, GEOMETRY_SPHERE_POINT, GEOMETRY_INSTANCE = 0, 50, 121
BUFFER_INDEX, BUFFER_VERTEX = 0, 1
FORMAT_UINT3, FORMAT_FLOAT3, FORMAT_FLOAT4, FORMAT_FLOAT3X4_COLUMN_MAJOR = 0x5003, 0x9003, 0x9004, 0x9234
#: geometry ids: the triangles, the spheres (in the top scene, or in the scene an instance holds:
#: the id is then the same, so that ``prim_offset[geomID]`` numbers both), the instance
TRIANGLES_ID, SPHERES_ID, INSTANCE_ID = 0, 1, 2
#: RTCSceneFlags: no optimization that reduces arithmetic accuracy, as embreex builds its scenes
#: (the two backends then find the same hits, to the bit); without it 13 % of hit distances on
#: a sphere mesh differ
SCENE_FLAG_ROBUST = 1 << 2
#: RTCBuildQuality values (rtcore_common.h), and the quality scenes are built at: Mitsuba 3's HIGH
#: answers no query faster on a robust triangle scene or on native spheres (docs/developer/performance.md,
#: "Raw queries: microsim's Embree scene against Mitsuba 3's")
BUILD_QUALITY_LOW, BUILD_QUALITY_MEDIUM, BUILD_QUALITY_HIGH = 0, 1, 2
BUILD_QUALITY = BUILD_QUALITY_MEDIUM
#: RTCDeviceProperty values (rtcore_device.h)
DEVICE_BACKFACE_CULLING, DEVICE_POINT_GEOMETRY = 65, 101
INVALID_ID = 0xFFFFFFFF
MASK_ALL = 0xFFFFFFFF
ALIGNMENT = 16
RAYHIT_BYTES = 96
#: environment variable whose value, if set, is the device's configuration string (rtcNewDevice:
#: e.g. ``max_isa=avx2`` traces with Embree's AVX2 kernels, as ``benchmarks/cross_isa.py`` does)
DEVICE_CONFIG_VARIABLE = "MICROSIM_EMBREE_CONFIG"

#: struct RTCRayHit (rtcore_ray.h): RTCRay, then RTCHit with instID and instPrimID of one level
RAYHIT = np.dtype({
    "names": ["org_x", "org_y", "org_z", "tnear", "dir_x", "dir_y", "dir_z", "time", "tfar", "mask", "id", "flags",
              "Ng_x", "Ng_y", "Ng_z", "u", "v", "primID", "geomID", "instID", "instPrimID"],
    "formats": ["f4"] * 9 + ["u4"] * 3 + ["f4"] * 5 + ["u4"] * 4,
    "offsets": [4 * k for k in range(12)] + [48 + 4 * k for k in range(9)],
    "itemsize": RAYHIT_BYTES,
})

rtc_intersect1 = types.ExternalFunction("rtcIntersect1", types.void(types.intp, types.intp, types.intp))
rtc_occluded1 = types.ExternalFunction("rtcOccluded1", types.void(types.intp, types.intp, types.intp))


#: what a kernel needs of a committed scene: its handle, the primitive offset of each geometry and
#: the (x, y) scale of the spheres' frame (float64 (2,); see :class:`Scene`)
SceneHandle = namedtuple("SceneHandle", ["handle", "prim_offset", "sphere_scale"])


class EmbreeUnavailable(RuntimeError):
    """The direct binding cannot be used here; the message is one line saying why."""


def library_path() -> Path:
    """libembree4 inside the installed embreex wheel (its ``embreex.libs`` directory)."""
    spec = importlib.util.find_spec("embreex")
    if spec is None or spec.origin is None:
        raise EmbreeUnavailable("embreex is not installed, so there is no Embree library to bind")
    site = Path(spec.origin).resolve().parent.parent
    found = sorted(site.glob("embreex.libs/libembree4*.so*")) + sorted(site.glob("embreex/.dylibs/libembree4*.dylib"))
    if not found:
        raise EmbreeUnavailable(f"no libembree4 shared library next to embreex in {site}")
    return found[0]


class _Library:
    """The ctypes functions that build scenes; one device per process, made on first use.

    Loading the library starts no thread. A device does not either, but the first commit starts
    Embree's TBB workers, which a forked process does not get back: the runner forks its workers
    before anything here is committed (:func:`available` checks the library without a device).
    """

    def __init__(self, path: Path):
        from llvmlite import binding

        lib = ctypes.CDLL(str(path))
        binding.load_library_permanently(str(path))  # so that kernels find rtcIntersect1 by name
        p, u, s = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t
        for name, restype, argtypes in (
            ("rtcNewDevice", p, [ctypes.c_char_p]), ("rtcGetDeviceError", ctypes.c_int, [p]),
            ("rtcGetDeviceProperty", ctypes.c_ssize_t, [p, ctypes.c_int]),
            ("rtcNewScene", p, [p]), ("rtcSetSceneFlags", None, [p, ctypes.c_int]),
            ("rtcSetSceneBuildQuality", None, [p, ctypes.c_int]), ("rtcSetGeometryBuildQuality", None, [p, ctypes.c_int]),
            ("rtcCommitScene", None, [p]), ("rtcReleaseScene", None, [p]),
            ("rtcNewGeometry", p, [p, ctypes.c_int]), ("rtcSetNewGeometryBuffer", p, [p, ctypes.c_int, u, ctypes.c_int, s, s]),
            ("rtcCommitGeometry", None, [p]), ("rtcAttachGeometryByID", None, [p, p, u]),
            ("rtcReleaseGeometry", None, [p]), ("rtcSetGeometryInstancedScene", None, [p, p]),
            ("rtcSetGeometryTransform", None, [p, u, ctypes.c_int, p]),
        ):
            function = getattr(lib, name)
            function.restype, function.argtypes = restype, argtypes
            setattr(self, name, function)
        self.path = path
        self._devices = {}  # process id -> device
        self._making = threading.Lock()  # threads building scenes at once make one device

    @property
    def device(self):
        pid = os.getpid()
        if pid not in self._devices:
            with self._making:
                if pid not in self._devices:
                    device = self.rtcNewDevice(os.environ.get(DEVICE_CONFIG_VARIABLE, "").encode() or None)
                    if not device:
                        raise EmbreeUnavailable(f"rtcNewDevice failed in {self.path.name}")
                    self._devices[pid] = device
        return self._devices[pid]

    def property(self, which: int) -> int:
        return self.rtcGetDeviceProperty(self.device, which)

    def check(self, result, what: str):
        """``result`` of a call, after making sure Embree reported no error and returned no NULL."""
        code = self.rtcGetDeviceError(self.device)
        if code or result is None or result == 0:
            raise RuntimeError(f"Embree error {code} while {what}")
        return result


class Scene:
    """A committed Embree scene of a triangle mesh and/or native spheres, owned by this object.

    Primitives are numbered across geometries: triangles first (0 .. F-1), then spheres
    (F .. F+K-1); ``prim_offset[geomID]`` turns Embree's (geomID, primID) into that number. A
    scene of triangles alone is built robust, as embreex builds its scenes, so that the two
    backends find the same hits (see SCENE_FLAG_ROBUST); with spheres it is not (faster, and the
    same sphere hits: docs/developer/performance.md, 'The direct backend').

    ``quality`` is the BVH's build quality; ``robust`` (None: robust for triangles alone) sets
    RTC_SCENE_FLAG_ROBUST, without which a ray through a shared edge may pass between two
    triangles (benchmarks/raw_queries.py builds a scene as Mitsuba 3 does, HIGH and not robust).

    ``sphere_scale`` = (sx, sy) other than (1, 1): the spheres are given in the frame where x is
    scaled by sx and y by sy, and stand for the ellipsoids that frame maps onto them. They go
    into a scene of their own, which the top scene holds as an instance with the transform
    diag(1/sx, 1/sy, 1) back to the world. Embree moves each ray into the instance's frame, so
    the hit distance t is that of the world ray, and it reports the geometric normal in that
    frame; :func:`hit_of` maps it back (normals go by the inverse transpose, diag(sx, sy, 1)).
    """

    handle = 0
    _spheres_scene = 0

    def __init__(self, vertices=None, faces=None, spheres=None, lib=None, sphere_scale=(1.0, 1.0),
                 quality: int = BUILD_QUALITY, robust: bool | None = None):
        lib = load() if lib is None else lib
        self._lib = lib
        self.handle = lib.check(lib.rtcNewScene(lib.device), "creating a scene")
        has_spheres = spheres is not None and len(spheres) > 0
        self.quality, self.robust = quality, not has_spheres if robust is None else robust
        if self.robust:
            lib.rtcSetSceneFlags(self.handle, SCENE_FLAG_ROBUST)
        lib.rtcSetSceneBuildQuality(self.handle, quality)
        offsets, count = {}, 0
        if faces is not None and len(faces):
            self._attach(self.handle, TRIANGLES_ID, GEOMETRY_TRIANGLE,
                         [(BUFFER_VERTEX, FORMAT_FLOAT3, np.asarray(vertices, np.float32)),
                          (BUFFER_INDEX, FORMAT_UINT3, np.asarray(faces, np.uint32))])
            offsets[TRIANGLES_ID], count = count, count + len(faces)
        self.sphere_scale = np.array(sphere_scale, np.float64)
        if has_spheres:
            buffers = [(BUFFER_VERTEX, FORMAT_FLOAT4, np.asarray(spheres, np.float32))]
            if tuple(sphere_scale) == (1.0, 1.0):
                self._attach(self.handle, SPHERES_ID, GEOMETRY_SPHERE_POINT, buffers)
            else:
                self._spheres_scene = lib.check(lib.rtcNewScene(lib.device), "creating a scene")
                lib.rtcSetSceneBuildQuality(self._spheres_scene, quality)
                self._attach(self._spheres_scene, SPHERES_ID, GEOMETRY_SPHERE_POINT, buffers)
                lib.rtcCommitScene(self._spheres_scene)
                self._attach_instance(self._spheres_scene, sphere_scale)
            offsets[SPHERES_ID], count = count, count + len(spheres)
        lib.rtcCommitScene(self.handle)
        lib.check(self.handle, "committing the scene")
        self.prim_offset = np.zeros(max(offsets, default=0) + 1, dtype=np.int64)  # by the ids Embree gave
        for geometry, offset in offsets.items():
            self.prim_offset[geometry] = offset
        self.n_prims = count

    def _attach(self, scene, geometry_id: int, geometry_type: int, buffers) -> None:
        """Attach to ``scene``, as ``geometry_id``, one geometry of ``buffers`` (type, format, data)."""
        lib = self._lib
        geometry = lib.check(lib.rtcNewGeometry(lib.device, geometry_type), "creating a geometry")
        lib.rtcSetGeometryBuildQuality(geometry, self.quality)
        for buffer_type, fmt, data in buffers:
            data = np.ascontiguousarray(data)
            address = lib.rtcSetNewGeometryBuffer(geometry, buffer_type, 0, fmt, data.strides[0], len(data))
            ctypes.memmove(lib.check(address, f"allocating a buffer of {len(data)} items"), data.ctypes.data,
                           data.nbytes)
        lib.rtcCommitGeometry(geometry)
        lib.rtcAttachGeometryByID(scene, geometry, geometry_id)
        lib.rtcReleaseGeometry(geometry)
        lib.check(scene, "building a geometry")

    def _attach_instance(self, scene, sphere_scale) -> None:
        """The committed ``scene`` as an instance of the top scene, mapped by diag(1/sx, 1/sy, 1)."""
        lib = self._lib
        geometry = lib.check(lib.rtcNewGeometry(lib.device, GEOMETRY_INSTANCE), "creating an instance")
        lib.rtcSetGeometryInstancedScene(geometry, scene)
        transform = np.zeros((4, 3), np.float32)  # column-major 3 x 4: the images of x, y, z, then the shift
        transform[0, 0], transform[1, 1], transform[2, 2] = 1.0 / sphere_scale[0], 1.0 / sphere_scale[1], 1.0
        lib.rtcSetGeometryTransform(geometry, 0, FORMAT_FLOAT3X4_COLUMN_MAJOR, transform.ctypes.data)
        lib.rtcCommitGeometry(geometry)
        lib.rtcAttachGeometryByID(self.handle, geometry, INSTANCE_ID)
        lib.rtcReleaseGeometry(geometry)
        lib.check(self.handle, "building an instance")

    def arrays(self) -> SceneHandle:
        return SceneHandle(self.handle, self.prim_offset, self.sphere_scale)

    def close(self) -> None:
        """Release the scene; no kernel may be tracing it (the backends own theirs until done)."""
        if self.handle:
            self._lib.rtcReleaseScene(self.handle)
            self.handle = 0
        if self._spheres_scene:
            self._lib.rtcReleaseScene(self._spheres_scene)
            self._spheres_scene = 0

    def _open_handle(self) -> int:
        if not self.handle:
            raise ValueError("this Embree scene is closed")
        return self.handle

    def __del__(self):
        self.close()

    def intersect(self, origins, directions, tfar, out=None):
        """Closest hits of rays (n, 3) float32 up to ``tfar``: (prim, t, Ng); prim -1 where none.
        ``out``, the (prim, t, Ng) of an earlier call on as many rays, is filled again instead of
        new arrays: a replay timed that way times Embree, not the first writes to fresh pages
        (docs/developer/performance.md, 'The direct backend')."""
        origins = np.ascontiguousarray(origins, np.float32)
        directions = np.ascontiguousarray(directions, np.float32)
        tfar = np.ascontiguousarray(tfar, np.float32)
        n = len(origins)
        if out is None:
            out = np.empty(n, np.int64), np.empty(n, np.float32), np.empty((n, 3), np.float32)
        prim, t, normal = out
        if not (prim.shape == (n,) and t.shape == (n,) and normal.shape == (n, 3)):
            raise ValueError(f"intersect: out holds hits of {len(prim)} rays, not {n}")
        self._open_handle()
        _intersect_all(self.arrays(), origins, directions, tfar, ray_hits(1), (prim, t, normal))
        return prim, t, normal

    def occluded(self, origins, directions, tfar) -> np.ndarray:
        """Whether anything lies on each ray (n, 3) float32 between 0 and ``tfar`` (shadow rays)."""
        origins = np.ascontiguousarray(origins, np.float32)
        directions = np.ascontiguousarray(directions, np.float32)
        tfar = np.ascontiguousarray(tfar, np.float32)
        blocked = np.empty(len(origins), np.bool_)
        _occluded_all(self._open_handle(), origins, directions, tfar, ray_hits(1), blocked)
        return blocked


def ray_hits(n: int) -> np.ndarray:
    """n RTCRayHit records, 16-byte aligned as Embree requires, each a query of every geometry
    from tnear = 0 (fields Embree leaves as they are)."""
    raw = np.zeros(n * RAYHIT.itemsize + ALIGNMENT, np.uint8)
    start = -raw.ctypes.data % ALIGNMENT
    records = raw[start:start + n * RAYHIT.itemsize].view(RAYHIT)
    records["mask"] = MASK_ALL
    return records


def ray_views(records: np.ndarray):
    """(origin (n, 3), direction (n, 3), tfar (n,)) float32 views into RTCRayHit records: a
    segment written there is the query itself, with no copy."""
    floats = records.view(np.float32).reshape(len(records), RAYHIT_BYTES // 4)
    return floats[:, 0:3], floats[:, 4:7], floats[:, 8]


@numba.njit(cache=True, error_model="numpy", inline="always")
def set_ray(record, o, d, tfar):
    """A fresh query in an RTCRayHit record of :func:`ray_hits`: origin o, direction d, segment (0, tfar)."""
    record.org_x, record.org_y, record.org_z = o
    record.dir_x, record.dir_y, record.dir_z = d
    record.tfar = tfar
    clear_hit(record)


@numba.njit(cache=True, error_model="numpy", inline="always")
def clear_hit(record):
    """Mark the record's hit empty, as Embree wants it before a query."""
    record.geomID = INVALID_ID
    record.primID = INVALID_ID
    record.instID = INVALID_ID


@numba.njit(cache=True, error_model="numpy", inline="always")
def closest_hit(handle, records, k):
    """Trace the query in ``records[k]`` on the scene of ``handle`` (a :data:`SceneHandle`):
    (primitive number or -1, t, geometric normal in float32)."""
    trace(handle.handle, records, k)
    return hit_of(handle, records, k)


@numba.njit(cache=True, error_model="numpy", inline="always")
def trace(handle, records, k):
    """Trace the query in ``records[k]``; the hit is left in the record (:func:`hit_of`)."""
    rtc_intersect1(handle, records.ctypes.data + k * RAYHIT_BYTES, 0)


@numba.njit(cache=True, error_model="numpy", inline="always")
def hit_of(handle, records, k):
    """The hit Embree left in ``records[k]``: (primitive number or -1, t, geometric normal in
    float32, in the world frame: a normal from inside the instance is mapped back, see :class:`Scene`)."""
    record = records[k]
    ng = (record.Ng_x, record.Ng_y, record.Ng_z)
    if record.geomID == INVALID_ID:
        return -1, record.tfar, ng
    if record.instID != INVALID_ID:
        ng = (np.float32(record.Ng_x * handle.sphere_scale[0]), np.float32(record.Ng_y * handle.sphere_scale[1]),
              record.Ng_z)
    return handle.prim_offset[record.geomID] + record.primID, record.tfar, ng


@numba.njit(cache=True, error_model="numpy")
def _intersect_all(handle, origins, directions, tfar, records, hits):
    prim, t, normal = hits
    for i in range(len(origins)):
        set_ray(records[0], (origins[i, 0], origins[i, 1], origins[i, 2]),
                (directions[i, 0], directions[i, 1], directions[i, 2]), tfar[i])
        p, distance, ng = closest_hit(handle, records, 0)
        prim[i] = p
        t[i] = distance
        normal[i, 0], normal[i, 1], normal[i, 2] = ng


@numba.njit(cache=True, error_model="numpy")
def _occluded_all(handle, origins, directions, tfar, records, blocked):
    for i in range(len(origins)):
        set_ray(records[0], (origins[i, 0], origins[i, 1], origins[i, 2]),
                (directions[i, 0], directions[i, 1], directions[i, 2]), tfar[i])
        blocked[i] = is_occluded(handle, records, 0)


@numba.njit(cache=True, error_model="numpy", inline="always")
def is_occluded(handle, records, k):
    """Trace the shadow query in ``records[k]`` (an RTCRay: the first 48 bytes); Embree sets its
    tfar to -inf when anything blocks it."""
    rtc_occluded1(handle, records.ctypes.data + k * RAYHIT_BYTES, 0)
    return records[k].tfar < 0.0


@functools.lru_cache(maxsize=None)
def _open() -> _Library:
    try:
        return _Library(library_path())
    except (OSError, AttributeError, RuntimeError) as err:
        message = " ".join(str(err).split())
        raise EmbreeUnavailable(f"cannot load the Embree library: {message}") from None


def available() -> _Library:
    """The library, loaded and its functions found, without a device or a thread (raises
    EmbreeUnavailable): what a process that forks workers may check."""
    return _open()


_checked = set()  # process ids whose library passed the layout check


def load() -> _Library:
    """The library, checked in this process (raises EmbreeUnavailable): see :func:`_check_layout`."""
    lib = _open()
    if os.getpid() not in _checked:
        try:
            _check_layout(lib)
        except RuntimeError as err:
            raise EmbreeUnavailable(f"the Embree library fails its check: {err}") from None
        _checked.add(os.getpid())
    return lib


def _check_layout(lib: _Library) -> None:
    """Refuse the binding unless the library and RTCRayHit are as this module assumes.

    The device must trace points and not cull back faces (a ray inside a solid must see the face
    it leaves by); known rays at a known triangle and sphere must come back with the right
    primitive, distance and normal, from outside and from behind.
    """
    if lib.property(DEVICE_BACKFACE_CULLING) != 0 or lib.property(DEVICE_POINT_GEOMETRY) != 1:
        raise EmbreeUnavailable(f"{lib.path.name} culls back faces or has no point geometry")
    scene = Scene(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]], spheres=[[5.0, 0.0, 0.0, 1.0]],
                  lib=lib)
    prim, t, normal = scene.intersect([[0.25, 0.25, 2.0], [5.0, 0.0, 3.0], [9.0, 9.0, 9.0], [0.25, 0.25, -2.0],
                                       [5.0, 0.0, 0.0]],
                                      [[0, 0, -1], [0, 0, -1], [0, 0, 1], [0, 0, 1], [0, 0, 1]],
                                      [10.0, 10.0, 10.0, 10.0, 10.0])
    scene.close()
    expected = ([0, 1, -1, 0, 1], [2.0, 2.0, 10.0, 2.0, 1.0])
    if prim.tolist() != expected[0] or not np.allclose(t, expected[1], rtol=1e-6):
        raise EmbreeUnavailable(f"RTCRayHit layout check failed: primitives {prim.tolist()}, distances {t.tolist()}")
    if normal[0, 2] <= 0 or normal[1, 2] <= 0 or normal[3, 2] <= 0 or normal[4, 2] <= 0 \
            or abs(normal[0, 0]) + abs(normal[1, 0]) > 1e-6:
        raise EmbreeUnavailable(f"RTCRayHit layout check failed: normals {normal.tolist()}")
