"""The Hydra edge: config schemas, composition and validation, the `ddmr` command, jobs, sweeps and output files."""
