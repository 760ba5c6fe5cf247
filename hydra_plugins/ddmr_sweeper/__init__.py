"""ddmr's Hydra sweeper: Hydra's basic sweeper composing a sweep's jobs once per set of group choices."""
