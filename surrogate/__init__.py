"""itr_surrogate (the repository folder ``surrogate/``): high-throughput campaigns on Dask,
Parquet results, the paper's tables as package data, and surrogates (prototypical
functions, baselines, the certified reduced basis)."""
