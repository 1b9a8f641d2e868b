"""The sweep engine: YAML sweeps expanded into cells, fanned out over workers, stored as Parquet."""
