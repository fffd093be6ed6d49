"""Generated kernels of the batch engine (:mod:`geovs_drake.batch._codegen`)."""
