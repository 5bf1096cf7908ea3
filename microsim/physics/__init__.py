"""The physics that tracers and models share, in one home: Fresnel reflectance (:mod:`.fresnel`),
microfacet distributions (:mod:`.distributions`), phase functions (:mod:`.phase`), the Boolean
model's relations (:mod:`.boolean_model`), direction sampling (:mod:`.sampling`) and the
counter-keyed random streams (:mod:`.rng`). Each is imported by the tracer's kernels and by the
analytic models alike, so the two can never mean different things by one name. Nothing here
imports the tracer, the models or the scene generators.
"""
