"""The sensitivity study of the paper's claims (docs/model.md §11): the parameter box (:mod:`.space`), the designs
(:mod:`.design`), the claim statistics (:mod:`.claims`), the Hydra job and callback (:mod:`.task`) and the
analyses (:mod:`.analysis`). ``ddmr sensitivity`` (:mod:`ddmr_cli.cli.sensitivity`) runs every stage."""
