"""Wheel-speed controllers behind one protocol (:class:`WheelController`)."""

from .base import SWITCHING_FUNCTIONS, WheelController
from .observers import NonlinearDisturbanceObserver, RBFNetworkObserver
from .open_loop import OpenLoop
from .pid import PID
from .smc import SMC

__all__ = ["WheelController", "PID", "SMC", "OpenLoop", "NonlinearDisturbanceObserver",
           "RBFNetworkObserver", "SWITCHING_FUNCTIONS"]
