"""Analysis, grouped by what each module is: :mod:`~geovs_drake.analysis.linear` (the
loop's linear model and what it predicts), :mod:`~geovs_drake.analysis.studies` (the
studies that run many loops) and :mod:`~geovs_drake.analysis.sweep` (the energy guarantee
at scale, on a Dask cluster)."""
