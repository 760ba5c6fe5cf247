"""``python -m ddmr_cli.config``: a helper that composes sets of group choices into ddmr's cache while a sweep's
validation composes others (:mod:`ddmr_cli.config.compose_parallel`)."""

import sys

from ddmr_cli.config import compose_config
from ddmr_cli.config.compose_parallel import helper

if __name__ == "__main__":
    sys.exit(helper(lambda config_name, groups: compose_config(groups, config_name, return_hydra_config=True)))
