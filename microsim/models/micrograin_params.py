"""The parameters shared by ``micrograin`` and ``micrograin_smith``: :class:`MicrograinParams`.

Parameters mirror the run config of a micrograin scene (conventions §4), so that
``microsim compare --param`` takes the names of the scene's TOML: ``material`` is the grains'
``[material] kind`` and takes that kind's keys, no others; ``base`` is the ``[base] kind`` and
``base_albedo`` its ``albedo``:

- ``lambert``: ``albedo`` = K_d of the grain surface; F = 0, T = 1, no specular term.
- ``conductor``: ``eta`` and ``k`` (k >= 0), the complex index; opaque, so no diffuse term; F is
  the exact conductor reflectance, as in the tracer (also for k = 0).
- ``mirror``: the perfect conductor, F = 1 at every angle (a flag in the kernel); no keys, no
  diffuse term.
- ``interfaced_lambert``: ``albedo`` (K_d of the body) and ``eta`` (a dielectric; k is 0 or left
  out): the diffuse term with T and the specular term with the dielectric F.
- base ``absorber`` (f^B = 0, no ``base_albedo``) or ``lambert`` (f^B = base_albedo / pi).

Old names stay as aliases: ``bulk`` for ``base``, ``bulk_albedo`` for ``base_albedo`` (giving a
name and its alias is an error). Without ``material`` the old grain description holds, the
material following from ``eta`` and ``k`` (defaults 1 and 0): ``eta = 1, k = 0`` lambert,
``eta != 1, k = 0`` a dielectric coat over Lambertian grains (interfaced_lambert), ``k > 0`` a
conductor (``albedo`` left out or 0). Old and new names give identical values; the old forms
keep their old leniency (``albedo = 0`` with a conductor, ``bulk_albedo = 0`` with an absorbing
base), the new ones are as strict as a config.
"""

from __future__ import annotations

import math

from microsim.models.base import BRDFModel, Param
from microsim.tracer.materials import CONDUCTOR, INTERFACED_LAMBERT, LAMBERT, MIRROR

TAU0_RANGE = (1e-4, 0.9999)
BETA_RANGE = (1e-3, 1e3)

_BETA = Param("beta", "grain height / lateral semi-axis, isotropic (sets beta_x = beta_y)", None, *BETA_RANGE)

#: Grain material -> the keys it takes besides ``material``: those of its ``[material]`` table
#: (conventions §4). The kind codes are the tracer's (:mod:`microsim.tracer.materials`).
GRAIN_KEYS = {"lambert": ("albedo",), "conductor": ("eta", "k"), "mirror": (), "interfaced_lambert": ("albedo", "eta")}
GRAIN_CODES = {"lambert": LAMBERT, "conductor": CONDUCTOR, "mirror": MIRROR, "interfaced_lambert": INTERFACED_LAMBERT}
#: Values of the grain keys a material does not take, after resolution (no interface: eta 1, k 0;
#: no Lambertian surface: albedo 0; mirror grains have no finite index: None).
GRAIN_FILL = {
    "lambert": {"eta": 1.0, "k": 0.0},
    "conductor": {"albedo": 0.0},
    "mirror": {"albedo": 0.0, "eta": None, "k": None},
    "interfaced_lambert": {"k": 0.0},
}
BASES = ("absorber", "lambert")
#: Old parameter name -> the name that mirrors the config.
ALIASES = {"bulk": "base", "bulk_albedo": "base_albedo"}


class MicrograinParams(BRDFModel):
    """Parameters shared by ``micrograin`` and ``micrograin_smith`` (not a registered model).

    A model class adds its own choice of GAF, ``class Model(MicrograinParams, gaf=Param("gaf", ...))``,
    after the shared parameters.

    Grain and base parameters follow the scene config (module docstring). After resolution
    ``values`` holds every key: a grain key the material does not take holds the value that
    means "none" (``GRAIN_FILL``), ``base_albedo`` is 0 for an absorbing base, and the old
    names ``bulk``, ``bulk_albedo`` repeat ``base``, ``base_albedo``.

    tau0 in [1e-4, 0.9999]: at tau0 = 0 the model is its bulk and 0/0 appears in
    lambda / tau0; at tau0 = 1 lambda = -ln(1 - tau0) is infinite (no pores, grains touching
    everywhere at their tips). Up to 0.9999 (lambda = 9.2) the height density
    exp(-lambda (1 - h^2)) stays resolved by the fixed Gauss rules. beta in [1e-3, 1e3] keeps
    beta_x beta_y and the NDF peak 1 / beta^2 far from under/overflow: flatter grains are a plane,
    taller ones hide everything but their tips at any incidence.
    """

    params = (
        Param("tau0", "filling factor: fraction of the base covered by grains (Eq. 8)", None, *TAU0_RANGE),
        _BETA,
        Param("beta_x", "grain height / lateral semi-axis along x", None, *BETA_RANGE),
        Param("beta_y", "grain height / lateral semi-axis along y", None, *BETA_RANGE),
        Param("material", "grains, as [material] kind (left out: from eta and k, the old form)", None,
              choices=tuple(GRAIN_KEYS), optional=True),
        Param("albedo", "K_d of the Lambertian grain surface: lambert, interfaced_lambert need it, others refuse it",
              None, 0.0, 1.0, optional=True),
        Param("eta", "real part of the grains' index ratio: conductor, interfaced_lambert need it", None, 0.0,
              math.inf, lo_open=True, optional=True),
        Param("k", "imaginary part of the grains' index: conductor needs it (interfaced_lambert: 0 or left out)",
              None, 0.0, math.inf, optional=True),
        Param("base", "plane under the grains, as [base] kind", "absorber", choices=BASES),
        Param("base_albedo", "albedo of the Lambertian base: base = lambert needs it, absorber refuses it", None,
              0.0, 1.0, optional=True),
        Param("bulk", "old name of base (an alias)", None, choices=BASES, optional=True),
        Param("bulk_albedo", "old name of base_albedo (an alias)", None, 0.0, 1.0, optional=True),
    )

    def __init_subclass__(cls, gaf: Param, **kwargs):
        super().__init_subclass__(**kwargs)
        cls.params = MicrograinParams.params + (gaf,)

    def resolve(self, values: dict) -> dict:
        has_beta = "beta" in values
        has_xy = [key for key in ("beta_x", "beta_y") if key in values]
        if has_beta and has_xy:
            raise ValueError(f"give either beta or beta_x + beta_y, not both (got beta and {', '.join(has_xy)})")
        if has_beta:
            values["beta_x"] = values["beta_y"] = values["beta"]
        elif len(has_xy) == 2:
            same = values["beta_x"] == values["beta_y"]
            values["beta"] = values["beta_x"] if same else None
        else:
            raise ValueError(f"model {self.name!r} needs beta, or beta_x and beta_y, in {_BETA.describe()}")
        _resolve_base(values)
        _resolve_grains(values)
        return values

    def setup(self) -> None:
        self.material_code = GRAIN_CODES[self.material]
        # T of Eq. 21-22 on the diffuse term for a coat only; a specular term for every interface
        self.has_interface = self.material == "interfaced_lambert"
        self.has_specular = self.material != "lambert"
        self.base_brdf = self.base_albedo / math.pi
        # the index handed to the kernels (mirror grains: any number, F = 1 does not read it)
        self.index = (1.0, 0.0) if self.material == "mirror" else (self.eta, self.k)


def _resolve_base(values: dict) -> None:
    """``base``, ``base_albedo`` from them or their old names; the old names then repeat them."""
    typed = {}
    for old, new in ALIASES.items():
        typed[new] = new
        if old in values:
            if new in values:
                raise ValueError(f"give {new} or its old name {old}, not both")
            values[new] = values.pop(old)
            typed[new] = old
    base = values.setdefault("base", "absorber")
    albedo_key = typed["base_albedo"]
    if base == "lambert":
        if "base_albedo" not in values:
            name = "bulk_albedo" if typed["base"] == "bulk" else "base_albedo"
            raise ValueError(f"{typed['base']} = 'lambert' needs {name} in [0, 1]")
    elif "base_albedo" in values and (albedo_key == "base_albedo" or values["base_albedo"] != 0.0):
        raise ValueError(f"{albedo_key} applies only to {typed['base']} = 'lambert' (an absorber has no albedo)")
    else:
        values["base_albedo"] = 0.0
    values["bulk"] = values["base"]
    values["bulk_albedo"] = values["base_albedo"]


def _resolve_grains(values: dict) -> None:
    """``material`` and the keys it takes, given or derived from the old form (eta, k, albedo)."""
    material = values.get("material")
    if material is None:
        if values.get("k", 0.0) > 0.0:
            if values.pop("albedo", 0.0) != 0.0:
                raise ValueError("albedo must be left out (or 0) with k > 0: conductor grains are opaque")
            values.setdefault("eta", 1.0)
            material = "conductor"
        else:
            material = "lambert" if values.get("eta", 1.0) == 1.0 else "interfaced_lambert"
            if material == "lambert":
                values.pop("eta", None)
            values.pop("k", None)
        values["material"] = material
    else:
        if material == "interfaced_lambert" and values.get("k") == 0.0:
            del values["k"]  # a dielectric: k = 0 is accepted, as no k
        takes = GRAIN_KEYS[material]
        for key in ("albedo", "eta", "k"):
            if key in values and key not in takes:
                raise ValueError(f"{key} does not apply to material = {material!r} "
                                 f"(its keys: {', '.join(takes) or 'none'})")
    for key in GRAIN_KEYS[material]:
        if key not in values:
            domain = next(p for p in MicrograinParams.params if p.name == key).describe()
            raise ValueError(f"material = {material!r} needs {key} in {domain}")
    values.update(GRAIN_FILL[material])
