"""Wheel-speed controllers behind one protocol (:class:`WheelController`)."""

from ddmr_cli.control.base import SWITCHING_FUNCTIONS, WheelController
from ddmr_cli.control.observers import NonlinearDisturbanceObserver, RBFNetworkObserver
from ddmr_cli.control.open_loop import OpenLoop
from ddmr_cli.control.pid import PID
from ddmr_cli.control.smc import SMC

__all__ = ["WheelController", "PID", "SMC", "OpenLoop", "NonlinearDisturbanceObserver",
           "RBFNetworkObserver", "SWITCHING_FUNCTIONS"]
