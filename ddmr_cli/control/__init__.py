"""Wheel-speed controllers (one module per law) and the Kanayama outer loop (docs/model.md §3, §6)."""

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

__all__ = ["WheelController", "PID", "SMC", "AdaptiveSMC", "SuperTwisting", "ADRC", "OpenLoop", "NonlinearDisturbanceObserver", "RBFNetworkObserver",
           "Kanayama", "SWITCHING_FUNCTIONS"]
