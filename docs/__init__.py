"""The model documentation (docs/model.md), shipped with the package as ``ddmr_cli.docs`` so that ``ddmr explain``
and the report can cite its sections from any install (pyproject.toml: package-dir, package-data)."""
