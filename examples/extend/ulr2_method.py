"""A rendering method for vibr: Unstructured Lumigraph Rendering blending the two best views
per pixel, not four (docs/how-to/extend/add-a-method.md)."""

from vibr.render.methods import Method, register_method

register_method(Method("ulr2", "ULR blending the 2 best views per pixel", solve=False, reweight=False,
                       overrides=dict(gamma=0.0, n_outer=0, ulr_k=2)))
