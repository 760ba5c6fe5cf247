"""The engine: seeded noise, the compiled step loop, metric accumulation and results (docs/model.md 4, 7)."""
