"""microsim's BRDFs in Mitsuba 3 (the optional extra ``render``): a BSDF plugin, ``microsim``, and
the side-by-side renders of ``microsim render``.

The plugin wraps any microsim model: a table's tabulated BRDF (:class:`microsim.models.tabulated.TabulatedBRDF`,
``{"type": "microsim", "filename": "table.h5"}``) or an analytic model (``{"type": "microsim",
"model": "lambert_sphere", "albedo": 0.8}``), or, from Python, a model made already
(:func:`bsdf`). Mitsuba's conventions: directions in the local shading frame, both pointing away
from the surface; ``eval`` returns f |cos theta_o|, ``pdf`` the density of ``sample``'s
directions per steradian, ``sample`` f |cos theta_o| / pdf as its weight. The tabulated BRDF
samples by its cells (:meth:`TabulatedBRDF.sample`); an analytic model, cosine-weighted.
The BRDF is grey (one value for the three channels) and one-sided (0 under the surface).

In the JIT variants (``llvm_ad_rgb``) the methods take whole wavefronts of rays, evaluated with
numpy (Dr.Jit's symbolic loops and calls are turned off so that Python runs on concrete
arrays); in the scalar ones, one ray at a time, correct but slow. :func:`variant` picks the first
of VARIANTS that the installed Mitsuba has.
"""

from __future__ import annotations

import numpy as np

#: the variants :func:`variant` tries, in order
VARIANTS = ("llvm_ad_rgb", "scalar_rgb")
#: the Mitsuba BSDF class of each variant (the classes derive from the variant's mi.BSDF)
_CLASSES: dict = {}


def load():
    """The ``mitsuba`` module with a variant set (:func:`variant`); ImportError naming the extra."""
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError:
        raise ImportError("Mitsuba 3 is not installed: install the extra render: "
                          "pip install -e '.[render]' in microsim's clone") from None
    if mi.variant() is None:
        mi.set_variant(next(v for v in VARIANTS if v in mi.variants()))
    if dr.is_jit_v(mi.Float):  # a Python BSDF needs concrete arrays: evaluate wavefront by wavefront
        dr.set_flag(dr.JitFlag.SymbolicLoops, False)
        dr.set_flag(dr.JitFlag.SymbolicCalls, False)
    return mi


def variant() -> str:
    """The Mitsuba variant in use (set by :func:`load` if none was)."""
    return load().variant()


def register() -> None:
    """Register the BSDF plugin ``microsim`` (module doc) with Mitsuba."""
    mi = load()
    mi.register_bsdf("microsim", lambda props: _bsdf_class(mi)(props, _model_of(props)))


def bsdf(model):
    """A Mitsuba BSDF of the microsim ``model`` (any object with ``__call__(wi, wo)``; a
    :class:`~microsim.models.tabulated.TabulatedBRDF` brings its own ``sample`` and ``pdf``)."""
    mi = load()
    return _bsdf_class(mi)(mi.Properties("microsim"), model)


class ModelRaised(Exception):
    """A render ended because the model a BSDF wraps raised ``error`` (Mitsuba itself reports it
    only as "(see above)")."""

    def __init__(self, model, error: Exception):
        self.model, self.error = model, error
        super().__init__(f"evaluating {model!r} raised {type(error).__name__}: {' '.join(str(error).split())}")


def raised(bsdf, err: Exception) -> Exception:
    """What a render that ended in ``err`` raised in truth: :class:`ModelRaised` of the first
    exception ``bsdf``'s methods raised (the model's own), else ``err``."""
    kept = getattr(bsdf, "error", None)
    return ModelRaised(bsdf.model, kept) if kept is not None else err


def _model_of(props):
    """The model of the plugin's properties: ``filename`` (a table), or ``model`` and its parameters."""
    from microsim import models
    from microsim.models.tabulated import TabulatedBRDF

    if "filename" in props:
        tabulated = TabulatedBRDF(str(props["filename"]))
        tabulated.require_full_brdf()
        return tabulated
    if "model" not in props:
        raise ValueError("BSDF microsim: give filename (a table) or model (a registered model's name)")
    return models.create(str(props["model"]), **{key: props[key] for key in props.keys() if key != "model"})


def _bsdf_class(mi):
    """The BSDF class for the current variant (made once per variant)."""
    if mi.variant() not in _CLASSES:
        _CLASSES[mi.variant()] = _make_class(mi)
    return _CLASSES[mi.variant()]


def _make_class(mi):
    import drjit as dr

    jit = dr.is_jit_v(mi.Float)

    def rows(value) -> np.ndarray:
        """A Mitsuba vector (or a scalar one) as numpy rows (n, k)."""
        array = np.asarray(value, dtype=np.float64)
        if not jit:
            return array.reshape(1, -1)
        return array.reshape(-1, 1) if array.ndim == 1 else array.T  # a Float (n,); a vector (k, n)

    def together(*arrays) -> list[np.ndarray]:
        """Rows of as many arrays as the longest (Mitsuba broadcasts an array of width 1)."""
        n = max(len(a) for a in arrays)
        return [np.broadcast_to(a, (n, a.shape[1])) for a in arrays]

    def floats(values: np.ndarray):
        return mi.Float(values) if jit else float(values[0])

    def vectors(values: np.ndarray):
        return mi.Vector3f(*values.T) if jit else mi.Vector3f(*values[0])

    def keeping_errors(method):
        """``method``, whose first exception is kept in ``self.error`` before it goes on into
        Mitsuba, which reports it only as "(see above)": the caller of the render raises it
        (:func:`raised`)."""

        def kept(self, *args, **kwargs):
            try:
                return method(self, *args, **kwargs)
            except Exception as err:
                if self.error is None:
                    self.error = err
                raise

        return kept

    class MicrosimBSDF(mi.BSDF):
        """A microsim model as a Mitsuba BSDF (module doc)."""

        def __init__(self, props, model):
            mi.BSDF.__init__(self, props)
            self.model = model
            self.error = None  # the first exception a method raised (keeping_errors)
            self.sampled = hasattr(model, "sample") and hasattr(model, "pdf")
            self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]

        def _f(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
            """f |cos theta_o|, 0 unless both directions lie above the surface."""
            above = (wi[:, 2] > 0) & (wo[:, 2] > 0)
            out = np.zeros(len(wi))
            if above.any():
                out[above] = self.model(wi[above], wo[above]) * wo[above, 2]
            return out

        def _pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
            if self.sampled:
                return self.model.pdf(wi, wo)
            return np.where((wi[:, 2] > 0) & (wo[:, 2] > 0), wo[:, 2] / np.pi, 0.0)

        @keeping_errors
        def eval(self, ctx, si, wo, active=True):
            return mi.Color3f(floats(self._f(*together(rows(si.wi), rows(wo)))))

        @keeping_errors
        def pdf(self, ctx, si, wo, active=True):
            return floats(self._pdf(*together(rows(si.wi), rows(wo))))

        @keeping_errors
        def eval_pdf(self, ctx, si, wo, active=True):
            wi, wo = together(rows(si.wi), rows(wo))
            return mi.Color3f(floats(self._f(wi, wo))), floats(self._pdf(wi, wo))

        @keeping_errors
        def sample(self, ctx, si, sample1, sample2, active=True):
            wi, u1, u2 = together(rows(si.wi), rows(sample1), rows(sample2))
            u1, n = u1[:, 0], len(wi)
            if self.sampled:
                wo, pdf = self.model.sample(wi, u1, u2)
            else:  # cosine-weighted hemisphere
                r, phi = np.sqrt(u2[:, 0]), 2 * np.pi * u2[:, 1]
                wo = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1 - u2[:, 0], 0))], 1)
                pdf = np.where(wi[:, 2] > 0, wo[:, 2] / np.pi, 0.0)
            ok = (pdf > 0) & (wi[:, 2] > 0) & (wo[:, 2] > 0)
            weight = np.zeros(n)
            weight[ok] = self._f(wi[ok], wo[ok]) / pdf[ok]
            sampled = mi.BSDFSample3f()
            sampled.wo = vectors(wo)
            sampled.pdf = floats(np.where(ok, pdf, 0.0))
            sampled.eta = 1.0
            sampled.sampled_type = +mi.BSDFFlags.DiffuseReflection
            sampled.sampled_component = 0
            return sampled, mi.Color3f(floats(weight))

        def to_string(self):
            return f"MicrosimBSDF[{self.model!r}]"

    return MicrosimBSDF
