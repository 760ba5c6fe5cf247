"""Wheel-speed controllers (one module per law) and the Kanayama outer loop (docs/model.md §3, §6).

The names below are imported on first use (PEP 562), so that importing one module of this package (the
channel kinds of :mod:`.base`, which the report reads) does not import every controller and numba with them.
"""

from typing import TYPE_CHECKING

from ddmr_cli.exports import lazy_exports

#: public name -> module of this package that defines it
_EXPORTS = {
    "AdaptiveSMC": "adaptive_smc", "ADRC": "adrc", "WheelController": "base", "NonlinearDisturbanceObserver": "ndo",
    "OpenLoop": "open_loop", "Kanayama": "outer_loop", "PID": "pid", "RBFNetworkObserver": "rbf", "SMC": "smc",
    "SWITCHING_FUNCTIONS": "smc", "SuperTwisting": "sta",
}


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)


if TYPE_CHECKING:  # pragma: no cover
    from ddmr_cli.control.adaptive_smc import AdaptiveSMC
    from ddmr_cli.control.adrc import ADRC
    from ddmr_cli.control.base import WheelController
    from ddmr_cli.control.ndo import NonlinearDisturbanceObserver
    from ddmr_cli.control.open_loop import OpenLoop
    from ddmr_cli.control.outer_loop import Kanayama
    from ddmr_cli.control.pid import PID
    from ddmr_cli.control.rbf import RBFNetworkObserver
    from ddmr_cli.control.smc import SMC, SWITCHING_FUNCTIONS
    from ddmr_cli.control.sta import SuperTwisting

__all__ = list(_EXPORTS)
