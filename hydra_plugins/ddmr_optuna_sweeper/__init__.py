"""ddmr's Optuna sweeper (``hydra/sweeper=ddmr_optuna``): Hydra-optuna-sweeper's grammar on Optuna >= 4."""
