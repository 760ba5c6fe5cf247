"""The command line and the Hydra glue: the `ddmr` command and its subcommands, the run modes (run, sweep, tuning
study, calibration search), help and explain, one-line errors, the Hydra task function and callbacks. Storage,
configuration, the job, studies and reports live below it (README, Layout)."""
