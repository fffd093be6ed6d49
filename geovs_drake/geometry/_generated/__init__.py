"""Code generated from the scalar-style sources; see :mod:`geovs_drake.geometry._codegen`."""
